"""Registry of oracle backends, loaded through the `mpgspec.verifiers` entry-point group.

A backend is an object with `name`, `description`, `is_installed()` and
`runner(primitive, settings)`; the runner has `evaluate(x0s, t0s, horizons)`. Third parties add
theirs by declaring an entry point in their own package.
"""
from __future__ import annotations

from functools import lru_cache
from importlib.metadata import entry_points

from ..errors import UsageError

GROUP = "mpgspec.verifiers"
_BUILTIN = {"rk4": "verifiers.rk4:backend", "scipy": "verifiers.scipy_ref:backend",
            "cvodes": "verifiers.cvodes:backend"}


def _load(target: str):
    mod, _, attr = target.partition(":")
    module = __import__(mod, fromlist=[attr])
    return getattr(module, attr)


@lru_cache(maxsize=None)
def backends() -> dict[str, object]:
    """All installed backends by name (entry points override the built-in table)."""
    found = {name: target for name, target in _BUILTIN.items()}
    for ep in entry_points(group=GROUP):
        found[ep.name] = ep.value
    out = {}
    for name, target in found.items():
        try:
            b = _load(target)
        except ImportError:
            continue
        if b.is_installed():
            out[name] = b
    return out


def get_backend(name: str):
    """The backend called `name`, or a UsageError listing those available."""
    bs = backends()
    if name not in bs:
        raise UsageError(f"unknown oracle method {name!r}; available: {', '.join(sorted(bs))}")
    return bs[name]
