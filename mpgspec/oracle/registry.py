"""Registry of oracle backends, loaded through the `mpgspec.verifiers` entry-point group.

A backend implements OracleBackend (backend.py): `name`, `description`, declared `capabilities`,
`is_installed()` and `runner(primitive, settings)`, whose runner has `evaluate(x0s, t0s,
horizons)`. Third parties add theirs by declaring an entry point in their own package; a loaded
backend that does not implement the contract is refused with an error naming its entry point.
The spec's `oracle.method` names the backend a project runs on.
"""
from __future__ import annotations

from functools import lru_cache

from ..errors import UsageError
from ..plugins import load_plugins
from .backend import OracleBackend, check_backend

GROUP = "mpgspec.verifiers"
_BUILTIN = {"rk4": "verifiers.rk4:backend", "scipy": "verifiers.scipy_ref:backend",
            "validated": "verifiers.validated:backend"}


@lru_cache(maxsize=None)
def backends() -> dict[str, OracleBackend]:
    """All installed backends by name (entry points override the built-in table)."""
    return load_plugins(GROUP, _BUILTIN, check_backend)


def get_backend(name: str) -> OracleBackend:
    """The backend called `name`, or a UsageError listing those available."""
    bs = backends()
    if name not in bs:
        raise UsageError(f"unknown oracle method {name!r}; available: {', '.join(sorted(bs))}")
    return bs[name]
