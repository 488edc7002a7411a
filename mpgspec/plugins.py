"""Plug-in loading shared by the registries: built-in targets, overridden by entry points."""
from __future__ import annotations

from importlib.metadata import EntryPoint, entry_points
from typing import Callable

Check = Callable[[str, str, object], None]
"""(name, target, plug-in) -> None, raising when the plug-in does not implement its contract."""


def load_plugins(group: str, builtin: dict[str, str], check: Check | None = None) -> dict[str, object]:
    """Installed plug-ins of an entry-point group by name; unimportable or uninstalled ones are skipped.

    With `check`, every importable plug-in is checked against its contract before it is asked
    whether it is installed; a plug-in that fails the check stops the loading with check's error.
    """
    found = dict(builtin)
    for ep in entry_points(group=group):
        found[ep.name] = ep.value
    out = {}
    for name, target in found.items():
        mod, _, attr = target.partition(":")
        try:
            plugin = getattr(__import__(mod, fromlist=[attr]), attr)
        except ImportError as err:  # an optional dependency is missing, or the plug-in itself is broken
            _UNLOADED.setdefault(group, {})[name] = f"{type(err).__name__}: {err}"
            continue
        if check is not None:
            check(name, target, plugin)
        if plugin.is_installed():
            out[name] = plugin
    return out


_UNLOADED: dict[str, dict[str, str]] = {}
"""Plug-ins declared but not importable, by group and name, with the import error."""


def unloaded(group: str) -> dict[str, str]:
    """The plug-ins of `group` that load_plugins skipped because importing them failed, with why."""
    return dict(_UNLOADED.get(group, {}))


_ADDED: dict[str, dict[str, EntryPoint]] = {}
"""Entry points added in this process, by group and name (as an installed package would declare them)."""


def add_entry_point(ep: EntryPoint, group: str) -> None:
    """Declare an entry point of `group` in this process."""
    if ep.group != group:
        raise ValueError(f"entry point {ep.name!r} belongs to the group {ep.group!r}, not {group!r}")
    _ADDED.setdefault(group, {})[ep.name] = ep


def remove_entry_point(group: str, name: str) -> None:
    """Forget an entry point added in this process (installed ones stay)."""
    _ADDED.get(group, {}).pop(name, None)


def group_entry_points(group: str) -> dict[str, EntryPoint]:
    """The group's entry points by name: the installed ones, then those added in this process."""
    found = {ep.name: ep for ep in entry_points(group=group)}
    found.update(_ADDED.get(group, {}))
    return found
