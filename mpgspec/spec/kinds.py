"""Controller kinds as the spec layer sees them: the entry points of the group
`mpgspec.controllers` (installed, or added in-process) and the `controller:` union of their spec
models. Loading a kind's object must not import CasADi (compile/laws/kind.py)."""
from __future__ import annotations

from functools import lru_cache
from importlib.metadata import EntryPoint
from typing import Annotated, Union

from pydantic import Field

from .. import plugins
from ..plugins import group_entry_points

GROUP = "mpgspec.controllers"


def controller_entry_points() -> dict[str, EntryPoint]:
    """The group's entry points by name: the installed ones, then those added in-process."""
    return group_entry_points(GROUP)


def add_entry_point(ep: EntryPoint) -> None:
    """Register a controller kind in this process, as an installed entry point would."""
    plugins.add_entry_point(ep, GROUP)
    loaded_kinds.cache_clear()


def remove_entry_point(name: str) -> None:
    """Forget a kind added in-process (installed kinds stay)."""
    plugins.remove_entry_point(GROUP, name)
    loaded_kinds.cache_clear()


@lru_cache(maxsize=1)
def loaded_kinds() -> dict[str, object]:
    """Every registered kind's object by its entry-point name."""
    found = controller_entry_points()
    if not found:
        raise ImportError(f"no controller kinds are registered under the entry points {GROUP!r}: install mpgspec "
                          "(pip install -e .) so that its metadata declares them")
    return {name: ep.load() for name, ep in found.items()}


def controller_models() -> tuple[type, ...]:
    """The spec models of the registered kinds, by their `position` (then their name)."""
    kinds = sorted(loaded_kinds().items(), key=lambda item: (getattr(item[1], "position", 100), item[0]))
    return tuple(kind.spec_model for _, kind in kinds)


def controller_union():
    """`controller:` of a primitive: one of the registered spec models, told apart by `type`."""
    return Annotated[Union[controller_models()], Field(discriminator="type")]
