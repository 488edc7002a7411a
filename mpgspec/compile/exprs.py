"""Parse-and-compile of spec expressions with their source location attached to any error."""
from __future__ import annotations

import math
from typing import Callable, Mapping

import casadi as ca

from ..errors import ExprError, Location
from ..spec.expr import check_number, evaluate, expr_error, parse_value, relocate
from .expr_casadi import to_casadi

Locate = Callable[[tuple], Location]


class ExprCompiler:
    """Compiles the expressions of one spec part, naming file:line:col and key on failure.

    Every expression here stands where a number is expected (a dynamics entry, a control law, a
    setpoint, a safety function, a constant): one whose value is a comparison or and/or/not is
    rejected (MPG206), and a constant that evaluates to NaN is rejected (MPG205).
    """

    def __init__(self, locate: Locate, owner: str):
        self.locate = locate
        self.owner = owner

    def _fail(self, err: ExprError, path: tuple) -> ExprError:
        key = f"{self.owner}: " + ".".join(str(p) for p in path)
        return relocate(err, self.locate(path, offset=getattr(err, "offset", 0) or 0), key, shift=False)

    def parse(self, value, path: tuple):
        """The number-valued expression of a spec value (located ExprError otherwise)."""
        try:
            expr = parse_value(value)
            check_number(expr)
            return expr
        except ExprError as e:
            raise self._fail(e, path) from None

    def sx(self, value, path: tuple, env: Mapping[str, object]) -> ca.SX:
        """One expression as a CasADi SX over the symbols in env."""
        expr = self.parse(value, path)
        try:
            return to_casadi(expr, env)
        except ExprError as e:
            raise self._fail(e, path) from None

    def vector(self, values, path: tuple, env: Mapping[str, object]) -> ca.SX:
        return ca.vertcat(*[self.sx(v, path + (i,), env) for i, v in enumerate(values)]) if values else ca.SX(0, 1)

    def number(self, value, path: tuple, env: Mapping[str, float], *, finite: bool = False) -> float:
        """A constant expression (period, domain, let) evaluated to a float; never NaN, and with
        `finite` never infinite either."""
        expr = self.parse(value, path)
        try:
            v = float(evaluate(expr, env))
        except ExprError as e:
            raise self._fail(e, path) from None
        if math.isnan(v) or (finite and math.isinf(v)):
            err = expr_error("MPG205", "cannot evaluate expression", 0, "",
                             expected="a finite real value" if finite else "a real value (not NaN)",
                             found=f"{v}")
            raise self._fail(err, path)
        return v
