"""Registry of region-of-attraction verifiers, loaded through the `mpgspec.roa` entry-point group.

A verifier has `name`, `description`, `is_installed()` and `estimate(problem, options) -> RoAResult`
(the RoAVerifier contract of certify/problem.py); third parties add theirs with an entry point of their package. A
verifier may list the keys of `roa.options` it reads in an `options` attribute; the spec's options
are then checked against it (unknown keys are spec errors). The built-in verifiers' keys are listed
here; `sos` and `lyapunov` also type their values (certify/options.py).
"""
from __future__ import annotations

from functools import lru_cache

from ..plugins import load_plugins
from .options import OPTION_MODELS
from .problem import RoAVerifier

GROUP = "mpgspec.roa"
_BUILTIN = {"lyapunov": "verifiers.lyapunov:verifier", "sos": "verifiers.sos:verifier",
            "floquet": "verifiers.floquet:verifier", "sampling": "verifiers.sampling:verifier"}

_SEARCH = ("r0", "r_max", "rtol", "confirm_rounds", "confirm_shrink", "samples", "seed", "conv", "dt")
BUILTIN_OPTIONS: dict[str, frozenset[str]] = {
    **{name: frozenset(model.model_fields) for name, model in OPTION_MODELS.items()},
    "sampling": frozenset(_SEARCH + ("horizon",)),
    "floquet": frozenset(_SEARCH + ("t0", "steps", "tol", "orbit_tol", "periods", "steps_per_period", "neutral", "window", "window_samples")),
}
"""Keys of `roa.options` each built-in verifier reads (verifiers/*.py)."""


@lru_cache(maxsize=None)
def roa_methods() -> dict[str, RoAVerifier]:
    """Installed RoA verifiers by name (entry points override the built-in table)."""
    return load_plugins(GROUP, _BUILTIN)


def option_model(name: str):
    """The pydantic model of the built-in verifier `name`'s options, when it has one (not a plug-in's)."""
    verifier = roa_methods().get(name)
    builtin = _BUILTIN.get(name, "").partition(":")[0]
    if verifier is not None and builtin and type(verifier).__module__ == builtin:
        return OPTION_MODELS.get(name)
    return None


def accepted_options(name: str) -> frozenset[str] | None:
    """Option keys the installed verifier `name` accepts, or None when it does not say (any key)."""
    verifier = roa_methods().get(name)
    if verifier is None:
        return None
    declared = getattr(verifier, "options", None)
    if declared is not None:
        return frozenset(declared)
    builtin = _BUILTIN.get(name, "").partition(":")[0]
    if builtin and type(verifier).__module__ == builtin:  # the built-in, not a plug-in of the same name
        return BUILTIN_OPTIONS.get(name)
    return None
