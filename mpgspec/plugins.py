"""Plug-in loading shared by the registries: built-in targets, overridden by entry points."""
from __future__ import annotations

from importlib.metadata import entry_points


def load_plugins(group: str, builtin: dict[str, str]) -> dict[str, object]:
    """Installed plug-ins of an entry-point group by name; unimportable or uninstalled ones are skipped."""
    found = dict(builtin)
    for ep in entry_points(group=group):
        found[ep.name] = ep.value
    out = {}
    for name, target in found.items():
        mod, _, attr = target.partition(":")
        try:
            plugin = getattr(__import__(mod, fromlist=[attr]), attr)
        except ImportError:
            continue
        if plugin.is_installed():
            out[name] = plugin
    return out
