"""Parse-and-compile of spec expressions with their source location attached to any error."""
from __future__ import annotations

from typing import Callable, Mapping

import casadi as ca

from ..errors import ExprError, Location
from ..spec.expr import evaluate, parse_value, relocate
from .expr_casadi import to_casadi

Locate = Callable[[tuple], Location]


class ExprCompiler:
    """Compiles the expressions of one spec part, naming file:line:col and key on failure."""

    def __init__(self, locate: Locate, owner: str):
        self.locate = locate
        self.owner = owner

    def _fail(self, err: ExprError, path: tuple) -> ExprError:
        key = f"{self.owner}: " + ".".join(str(p) for p in path)
        return relocate(err, self.locate(path, offset=getattr(err, "offset", 0) or 0), key, shift=False)

    def sx(self, value, path: tuple, env: Mapping[str, object]) -> ca.SX:
        """One expression as a CasADi SX over the symbols in env."""
        try:
            return to_casadi(parse_value(value), env)
        except ExprError as e:
            raise self._fail(e, path) from None

    def vector(self, values, path: tuple, env: Mapping[str, object]) -> ca.SX:
        return ca.vertcat(*[self.sx(v, path + (i,), env) for i, v in enumerate(values)]) if values else ca.SX(0, 1)

    def number(self, value, path: tuple, env: Mapping[str, float]) -> float:
        """A constant expression (period, domain, let) evaluated to a float."""
        try:
            return float(evaluate(parse_value(value), env))
        except ExprError as e:
            raise self._fail(e, path) from None
