"""The ControllerKind contract: what a controller type brings to a primitive.

A kind is registered by entry point (group `mpgspec.controllers`, compile/laws/registry.py). Its
object must be importable without CasADi, because the spec layer reads its `spec_model` to build
the `controller:` union; the law and the setup are named as "module:function" and imported only
when a primitive is compiled.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from importlib import import_module
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:  # the spec layer imports this module without CasADi
    from ..contacts import Schedule


@dataclass
class Setup:
    """What a kind's setup hands the compiler before the law is built.

    `contacts`: the contact plan, when the kind sets the contact mode by the clock (as the trot
    does; it runs on the primitive's clock and period); `info`: entries for the compiled
    primitive's info, which the law can read back through ControlContext.info.
    """

    contacts: Schedule | None = None
    info: dict[str, Any] = field(default_factory=dict)


def _resolve(target: str) -> Callable:
    module, _, attr = target.partition(":")
    return getattr(import_module(module), attr)


@dataclass(frozen=True)
class ControllerKind:
    """A controller type: its spec model (a pydantic model whose `type` literal is the name of the
    kind's entry point), its law `law(spec, ctx) -> u_raw` and an optional
    `setup(inst, sys, ec, consts) -> Setup`.

    `law` and `setup` are "module:function" references, imported on first use; `position` orders
    the kinds in the `controller:` union (and so in the JSON schema).
    """

    spec_model: type
    law: str
    setup: str | None = None
    position: int = 100

    def build_law(self, spec, ctx):
        """u_raw = k(x, t, s, x_sw) of a primitive: an SX expression or a CasADi Function."""
        return _resolve(self.law)(spec, ctx)

    def run_setup(self, inst, sys, ec, consts: dict) -> Setup:
        """The kind's setup for one primitive node (nothing to set up: an empty Setup)."""
        return _resolve(self.setup)(inst, sys, ec, consts) if self.setup is not None else Setup()
