"""Compile parsed spec expressions and tabulated samples to CasADi SX/MX expressions.

Only the whitelisted AST from mpgspec.spec.expr is translated, so a spec can never reach
arbitrary Python. Numbers are lifted to the symbolic type of the environment (SX by default,
MX when any environment value is MX) so SX and MX graphs never mix.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import reduce

import casadi as ca
import numpy as np

from mpgspec.errors import ExprError
from mpgspec.spec.expr import (
    CONSTANTS,
    FUNCTIONS,
    Binary,
    Call,
    Expr,
    Name,
    Num,
    Unary,
    expr_error,
    fold,
    parse_value,
    unknown_name_error,
)

Sym = ca.SX | ca.MX

_UNARY: dict[str, Callable] = {
    "sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "asin": ca.asin, "acos": ca.acos,
    "atan": ca.atan, "sinh": ca.sinh, "cosh": ca.cosh, "tanh": ca.tanh, "exp": ca.exp,
    "log": ca.log, "log10": ca.log10, "sqrt": ca.sqrt, "abs": ca.fabs, "sign": ca.sign,
    "floor": ca.floor, "ceil": ca.ceil, "sq": lambda x: x * x,
}
_ARITH: dict[str, Callable] = {
    "+": lambda a, b: a + b, "-": lambda a, b: a - b, "*": lambda a, b: a * b,
    "/": lambda a, b: a / b, "^": ca.power,
}
_COMPARE: dict[str, Callable] = {"<": ca.lt, "<=": ca.le, ">": ca.gt, ">=": ca.ge, "==": ca.eq, "!=": ca.ne}
_LOGIC: dict[str, Callable] = {"and": ca.logic_and, "or": ca.logic_or}
_FUNC2: dict[str, Callable] = {"atan2": ca.atan2, "fmod": ca.fmod, "hypot": ca.hypot}

# NaN must reach the oracle's judge: CasADi's fmin/fmax return the other operand for a NaN, its
# comparisons answer 0 and its if_else takes a NaN condition as true. The forms below keep NaN.
# (x != x is no NaN test for CasADi: it simplifies it to 0; x <= inf is false only for NaN.)


def isnan(x: Sym) -> Sym:
    """1 where x is NaN, else 0 (elementwise), in a form CasADi does not simplify away."""
    return ca.logic_not(x <= ca.inf)


def nan_if(cond: Sym, value: Sym) -> Sym:
    """value, or NaN where cond holds."""
    return ca.if_else(cond, np.nan, value)


def _any_nan(*xs: Sym) -> Sym:
    return reduce(ca.logic_or, (isnan(x) for x in xs))


def nan_min(a: Sym, b: Sym) -> Sym:
    """min(a, b), NaN when either is NaN."""
    return ca.if_else(a <= b, a, ca.if_else(b < a, b, a + b))


def nan_max(a: Sym, b: Sym) -> Sym:
    """max(a, b), NaN when either is NaN."""
    return ca.if_else(a >= b, a, ca.if_else(b > a, b, a + b))


def _kind(env: Mapping[str, object]) -> type:
    kinds = {type(v) for v in env.values() if isinstance(v, (ca.SX, ca.MX))}
    if len(kinds) > 1:
        raise TypeError("environment mixes casadi.SX and casadi.MX values")
    return kinds.pop() if kinds else ca.SX


def to_casadi(expr: Expr, env: Mapping[str, object]) -> Sym:
    """CasADi expression for expr; env maps names to SX/MX/float values.

    pi, e and inf resolve to constants unless env defines them. Comparisons and logic yield 0/1,
    or NaN when an operand is NaN; min, max, clip, sat, norm_inf and the conditions of if_else and
    piecewise pass NaN on as well. Raises ExprError MPG204 (offset, found, hint set) for a name
    missing from env.
    """
    kind = _kind(env)
    return _Compiler(env, kind).compile(expr)


def compile_vector(exprs: Sequence[Expr | str | float], env: Mapping[str, object]) -> Sym:
    """Column vector (vertcat) of compiled expressions; strings and numbers are parsed first."""
    kind = _kind(env)
    compiler = _Compiler(env, kind)
    items = [compiler.compile(e if isinstance(e, (Num, Name, Unary, Binary, Call))
                              else parse_value(e)) for e in exprs]
    return ca.vertcat(*items) if items else kind(0, 1)


class _Compiler:
    def __init__(self, env: Mapping[str, object], kind: type):
        self.kind = kind
        self.env = {k: self.lift(v) for k, v in env.items()}

    def lift(self, value: object) -> Sym:
        return value if isinstance(value, (ca.SX, ca.MX)) else self.kind(value)

    def compile(self, expr: Expr) -> Sym:
        """Children first, without recursion (chains of thousands of terms are fine)."""
        return fold(expr, self.node)

    def node(self, expr: Expr, args: list) -> Sym:
        if isinstance(expr, Num):
            return self.kind(expr.value)
        if isinstance(expr, Name):
            if expr.id in self.env:
                return self.env[expr.id]
            if expr.id in CONSTANTS:
                return self.kind(CONSTANTS[expr.id])
            raise unknown_name_error(expr.id, expr.pos, [*self.env, *CONSTANTS])
        if isinstance(expr, Unary):
            (operand,) = args
            return -operand if expr.op == "-" else nan_if(isnan(operand), ca.logic_not(operand))
        if isinstance(expr, Binary):
            a, b = args
            if expr.op in _ARITH:
                return _ARITH[expr.op](a, b)
            op = _COMPARE.get(expr.op) or _LOGIC[expr.op]
            return nan_if(_any_nan(a, b), op(a, b))
        return self.call(expr, args)

    def call(self, expr: Call, args: list) -> Sym:
        if expr.func not in FUNCTIONS:
            raise expr_error("MPG202", f"unknown function '{expr.func}'", expr.pos, "",
                             expected="a whitelisted function", found=repr(expr.func))
        f = expr.func
        if f in _UNARY:
            return _UNARY[f](*args)
        if f in _FUNC2:
            return _FUNC2[f](*args)
        if f == "min":
            return reduce(nan_min, args)
        if f == "max":
            return reduce(nan_max, args)
        if f in ("clip", "sat"):
            x, lo, hi = args
            return nan_min(nan_max(x, lo), hi)
        if f in ("if_else", "piecewise"):
            *pairs, result = args
            for cond, value in reversed(list(zip(pairs[::2], pairs[1::2]))):
                result = nan_if(isnan(cond), ca.if_else(cond, value, result))
            return result
        stacked = ca.vertcat(*args)
        if f == "norm_2":
            return ca.sqrt(ca.sumsqr(stacked))
        if f == "norm_1":
            return ca.sum1(ca.fabs(stacked))
        if f == "norm_inf":
            mags = ca.fabs(stacked)
            return nan_if(isnan(ca.sum1(mags)), ca.mmax(mags))
        raise ExprError(f"function '{f}' has no CasADi translation", code="MPG202")


# ---------------------------------------------------------------------------------------------
# Tabulated samples


def _samples(ts: Sequence[float], ys: Sequence) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(ts, dtype=float)
    y = np.asarray(ys, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"need at least 2 sample times, got {t.size}")
    if y.shape[0] != t.size or y.ndim > 2:
        raise ValueError(f"samples shape {y.shape} does not match {t.size} sample times")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise ValueError("sample times and values must be finite")
    if np.any(np.diff(t) <= 0):
        raise ValueError("sample times must be strictly increasing")
    return t, y


def _select(tc: Sym, knots: np.ndarray, pieces: list[Sym], lo: int, hi: int) -> Sym:
    """Balanced if_else tree picking pieces[i] on [knots[i], knots[i+1])."""
    if lo == hi:
        return pieces[lo]
    mid = (lo + hi) // 2
    return ca.if_else(tc < float(knots[mid + 1]), _select(tc, knots, pieces, lo, mid),
                      _select(tc, knots, pieces, mid + 1, hi))


def _clamp(t: Sym | float, knots: np.ndarray) -> Sym:
    return ca.fmin(ca.fmax(t, float(knots[0])), float(knots[-1]))


def interp_linear(t: Sym | float, ts: Sequence[float], ys: Sequence) -> Sym:
    """Piecewise-linear interpolant of (ts, ys) at t, held constant outside [ts[0], ts[-1]].

    ys of shape (n,) gives a scalar, shape (n, m) a column of m values (one if_else tree over
    columns of pieces: the same operations per entry as m scalar interpolants, built m times faster).
    Raises ValueError for fewer than 2 samples, non-increasing times or non-finite values.
    """
    knots, y = _samples(ts, ys)
    tc = _clamp(t, knots)
    rows = y.reshape(len(knots), -1)
    slopes = np.diff(rows, axis=0) / np.diff(knots)[:, None]
    pieces = [ca.DM(rows[i]) + ca.DM(slopes[i]) * (tc - float(knots[i])) for i in range(len(knots) - 1)]
    out = _select(tc, knots, pieces, 0, len(pieces) - 1)
    return out[0] if y.ndim == 1 else out


def interp_cubic(t: Sym | float, ts: Sequence[float], ys: Sequence,
                 bc_type: str = "not-a-knot") -> Sym:
    """Cubic spline of (ts, ys) at t (scipy CubicSpline coefficients), clamped outside the range.

    bc_type is passed to scipy ('not-a-knot', 'natural', 'clamped'); shapes as interp_linear.
    """
    from scipy.interpolate import CubicSpline  # imported when used: scipy's start-up is a process's slowest

    knots, y = _samples(ts, ys)
    tc = _clamp(t, knots)
    spline = CubicSpline(knots, y, bc_type=bc_type, axis=0)
    coeffs = spline.c.reshape(4, len(knots) - 1, -1)
    pieces = []
    for i in range(len(knots) - 1):
        c3, c2, c1, c0 = (ca.DM(coeffs[k, i]) for k in range(4))
        dt = tc - float(knots[i])
        pieces.append(((c3 * dt + c2) * dt + c1) * dt + c0)
    out = _select(tc, knots, pieces, 0, len(pieces) - 1)
    return out[0] if y.ndim == 1 else out
