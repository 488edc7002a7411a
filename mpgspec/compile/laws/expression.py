"""The expression law: u = k(x, t) written out in the spec, one expression per input."""
from __future__ import annotations

import casadi as ca

from ...errors import SpecError
from ...spec.controllers import ExpressionController
from .base import ControlContext


def expression_law(c: ExpressionController, ctx: ControlContext) -> ca.SX:
    if len(c.u) != ctx.sys.nu:
        raise SpecError("one expression per input is needed", location=ctx.ec.locate(("controller", "u")),
                        key=f"{ctx.ec.owner}: controller.u", expected=f"{ctx.sys.nu}", found=f"{len(c.u)}",
                        code="MPG106")
    return ctx.ec.vector(c.u, ("controller", "u"), ctx.env)
