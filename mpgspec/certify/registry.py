"""Registry of region-of-attraction verifiers, loaded through the `mpgspec.roa` entry-point group.

A verifier has `name`, `description`, `is_installed()` and `estimate(problem, options) -> RoAResult`
(see verifiers/roa_common.py); third parties add theirs with an entry point of their package.
"""
from __future__ import annotations

from functools import lru_cache

from ..plugins import load_plugins

GROUP = "mpgspec.roa"
_BUILTIN = {"lyapunov": "verifiers.lyapunov:verifier", "sos": "verifiers.sos:verifier",
            "floquet": "verifiers.floquet:verifier", "sampling": "verifiers.sampling:verifier"}


@lru_cache(maxsize=None)
def roa_verifiers() -> dict[str, object]:
    """Installed RoA verifiers by name (entry points override the built-in table)."""
    return load_plugins(GROUP, _BUILTIN)