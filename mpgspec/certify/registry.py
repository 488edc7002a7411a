"""Registry of region-of-attraction verifiers, loaded through the `mpgspec.roa` entry-point group.

A verifier has `name`, `description`, `is_installed()` and `estimate(problem, options) -> RoAResult`
(see verifiers/roa_common.py); third parties add theirs with an entry point of their package.
"""
from __future__ import annotations

from functools import lru_cache
from importlib.metadata import entry_points

GROUP = "mpgspec.roa"
_BUILTIN = {"lyapunov": "verifiers.lyapunov:verifier", "sos": "verifiers.sos:verifier",
            "floquet": "verifiers.floquet:verifier", "sampling": "verifiers.sampling:verifier"}


def _load(target: str):
    mod, _, attr = target.partition(":")
    return getattr(__import__(mod, fromlist=[attr]), attr)


@lru_cache(maxsize=None)
def roa_verifiers() -> dict[str, object]:
    """Installed RoA verifiers by name (entry points override the built-in table)."""
    found = dict(_BUILTIN)
    for ep in entry_points(group=GROUP):
        found[ep.name] = ep.value
    out = {}
    for name, target in found.items():
        try:
            v = _load(target)
        except ImportError:
            continue
        if v.is_installed():
            out[name] = v
    return out
