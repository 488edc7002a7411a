"""Controller kinds by name: the entry points of the group `mpgspec.controllers`.

A package adds a kind by declaring one in its metadata:

    [project.entry-points."mpgspec.controllers"]
    my_law = "my_package.kinds:MY_LAW"      # a ControllerKind (compile/laws/kind.py)

`register` does the same in this process (an EntryPoint object, as an installed package would
declare it) and rebuilds the spec models' `controller:` union so that specs may name the kind.
"""
from __future__ import annotations

from importlib.metadata import EntryPoint

from ...errors import SpecError
from ...spec.kinds import GROUP, add_entry_point, loaded_kinds, remove_entry_point
from ...spec.models import refresh_controllers
from .kind import ControllerKind


def controller_kinds() -> dict[str, ControllerKind]:
    """Every registered controller kind by its name."""
    return dict(loaded_kinds())


def controller_kind(spec, ec) -> ControllerKind:
    """The kind of a primitive's `controller:` block (its `type`)."""
    kinds = loaded_kinds()
    if spec.type not in kinds:
        raise SpecError("no controller kind of this type is registered", location=ec.locate(("controller", "type")),
                        key=f"{ec.owner}: controller.type", expected="one of " + ", ".join(sorted(kinds)),
                        found=repr(spec.type), code="MPG108")
    return kinds[spec.type]


def register(entry_point: EntryPoint | str, value: str | None = None) -> None:
    """Register a controller kind in this process through the entry-point mechanism: an EntryPoint
    of the group `mpgspec.controllers`, or its name and "module:attribute" value."""
    if not isinstance(entry_point, EntryPoint):
        entry_point = EntryPoint(name=entry_point, value=value, group=GROUP)
    add_entry_point(entry_point)
    refresh_controllers()


def unregister(name: str) -> None:
    """Undo `register` for the kind `name` (installed kinds stay registered)."""
    remove_entry_point(name)
    refresh_controllers()
