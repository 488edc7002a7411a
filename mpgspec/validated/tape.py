"""A CasADi SX Function read back as its operation sequence, evaluated in any ball algebra.

Values may be arb balls, arb_series (truncated Taylor series) or jets of either (jet.py): the
smooth operations are written once for all of them. The non-smooth ones (abs, min, max,
comparisons, if_else, floor, sign, fmod) take a *decision*: evaluated on balls, each records which
branch holds over the whole ball (or None when the ball straddles the switch) and returns a sound
hull either way; evaluated on series, each replays the decision taken over the step's whole
domain, so a Taylor expansion is only ever taken on one smooth branch. An operation whose decision
is None yields UNDECIDED, which a consumer of series treats as "this step crosses a kink".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
from flint import arb

from . import jet as J

UNDECIDED = None
"""The value of an operation whose branch is not fixed over the evaluated domain (series mode)."""

ZERO_ONE = arb("0.5 +/- 0.5")
"""The ball of an undecided comparison: [0, 1]."""

_SMOOTH1 = {ca.OP_NEG: J.neg, ca.OP_SQ: J.sq, ca.OP_TWICE: J.twice, ca.OP_SQRT: J.sqrt, ca.OP_SIN: J.sin,
            ca.OP_COS: J.cos, ca.OP_TAN: J.tan, ca.OP_EXP: J.exp, ca.OP_LOG: J.log, ca.OP_INV: J.inv,
            ca.OP_ATAN: J.atan, ca.OP_ASSIGN: lambda a: a}
_SMOOTH2 = {ca.OP_ADD: lambda a, b: a + b, ca.OP_SUB: lambda a, b: a - b, ca.OP_MUL: lambda a, b: a * b,
            ca.OP_DIV: lambda a, b: a / b, ca.OP_POW: J.pow, ca.OP_CONSTPOW: J.pow}
_KINK = {ca.OP_FABS, ca.OP_FMIN, ca.OP_FMAX, ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_NOT, ca.OP_AND,
         ca.OP_OR, ca.OP_IF_ELSE_ZERO, ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN, ca.OP_FMOD}
_NAMES = {getattr(ca, n): n[3:].lower() for n in dir(ca) if n.startswith("OP_")}


class TapeError(ValueError):
    """A Function the tape cannot read: not SX, or an operation without a sound ball rule."""


@dataclass(frozen=True)
class Tape:
    """The instructions of an SX Function: (op, outputs, inputs, constant) in execution order."""

    name: str
    ops: tuple
    n_work: int
    in_sizes: tuple
    out_sizes: tuple
    psd_sqrt: bool = False  # square roots of forms known to be >= 0 (E's norm): clip the ball at 0

    def of_psd(self) -> "Tape":
        """The same tape with square roots taken of the nonnegative part of their ball: for norms,
        whose argument is >= 0 wherever defined, so a ball's spurious negative part is no NaN."""
        return Tape(self.name, self.ops, self.n_work, self.in_sizes, self.out_sizes, True)

    @classmethod
    def of(cls, fn: ca.Function) -> "Tape":
        if not fn.is_a("SXFunction"):
            raise TapeError(f"{fn.name()} is not an expression graph (SX) but {fn.class_name()}: it calls "
                            f"compiled code whose operations cannot be enclosed")
        ops = []
        for k in range(fn.n_instructions()):
            op = fn.instruction_id(k)
            if op not in (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST) and op not in _SMOOTH1 and op not in _SMOOTH2 \
                    and op not in _KINK:
                raise TapeError(f"{fn.name()} uses the operation {_NAMES.get(op, op)!r}, which has no ball rule")
            const = arb(fn.instruction_constant(k)) if op == ca.OP_CONST else None
            ops.append((op, tuple(fn.instruction_output(k)), tuple(fn.instruction_input(k)), const))
        return cls(fn.name(), tuple(ops), fn.sz_w(), tuple(fn.nnz_in(i) for i in range(fn.n_in())),
                   tuple(fn.nnz_out(i) for i in range(fn.n_out())))

    def __call__(self, inputs, decisions: dict | None = None, clarke: bool = False):
        """Outputs (lists of values) at `inputs` (one list of values per Function input).

        Without `decisions`, non-smooth operations act on balls and the decision each took is
        returned as the second result (dict by instruction index; None where undecided); with
        `decisions`, they replay them (series and jets) and the second result is None.
        """
        w = [None] * self.n_work
        outs = [[None] * n for n in self.out_sizes]
        record = decisions is None
        taken = {} if record else None
        for k, (op, o, i, c) in enumerate(self.ops):
            if op == ca.OP_CONST:
                w[o[0]] = c
            elif op == ca.OP_INPUT:
                w[o[0]] = inputs[i[0]][i[1]]
            elif op == ca.OP_OUTPUT:
                outs[o[0]][o[1]] = w[i[0]]
            elif op in _SMOOTH2:
                a, b = w[i[0]], w[i[1]]
                w[o[0]] = UNDECIDED if a is UNDECIDED or b is UNDECIDED else _SMOOTH2[op](a, b)
            elif op in _SMOOTH1:
                a = w[i[0]]
                if op == ca.OP_SQRT and self.psd_sqrt and isinstance(a, arb) and not a >= 0:
                    a = a.nonnegative_part()
                w[o[0]] = UNDECIDED if a is UNDECIDED else _SMOOTH1[op](a)
            elif record:
                w[o[0]], taken[k] = _decide(op, [w[j] for j in i])
            else:
                args = [w[j] for j in i]
                d = decisions.get(k)
                w[o[0]] = _clarke(op, args) if clarke and d is None else _replay(op, args, d)
        return outs, taken


def _decide(op, args):
    """(hull value, decision) of a non-smooth operation on balls."""
    a = args[0]
    if op == ca.OP_FABS:
        d = 1 if a >= 0 else -1 if a <= 0 else None
        return abs(a), d
    if op in (ca.OP_FMIN, ca.OP_FMAX):
        b = args[1]
        lo_a = a <= b if op == ca.OP_FMIN else a >= b
        lo_b = b <= a if op == ca.OP_FMIN else b >= a
        d = 0 if lo_a else 1 if lo_b else None
        return (a.min(b) if op == ca.OP_FMIN else a.max(b)), d
    if op in (ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE):
        b = args[1]
        yes = {ca.OP_LT: a < b, ca.OP_LE: a <= b, ca.OP_EQ: a == b, ca.OP_NE: a != b}[op]
        no = {ca.OP_LT: a >= b, ca.OP_LE: a > b, ca.OP_EQ: a != b, ca.OP_NE: a == b}[op]
        return _truth(1 if yes else 0 if no else None)
    if op == ca.OP_NOT:
        v = _bool(a)
        return _truth(None if v is None else 1 - v)
    if op in (ca.OP_AND, ca.OP_OR):
        u, v = _bool(a), _bool(args[1])
        if op == ca.OP_AND:
            r = 0 if 0 in (u, v) else 1 if (u, v) == (1, 1) else None
        else:
            r = 1 if 1 in (u, v) else 0 if (u, v) == (0, 0) else None
        return _truth(r)
    if op == ca.OP_IF_ELSE_ZERO:
        c, b = _bool(a), args[1]
        return (b if c == 1 else arb(0) if c == 0 else b.union(0)), c
    if op in (ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN):
        return _step_fn(op, a)
    if op == ca.OP_FMOD:  # a - b trunc(a / b), CasADi's fmod
        b = args[1]
        q = a / b
        tr = _step_fn(ca.OP_FLOOR if q >= 0 else ca.OP_CEIL, q) if (q >= 0 or q <= 0) else (q, None)
        n = tr[1]
        return (a - b * (arb(n) if n is not None else _trunc_hull(q))), n
    raise TapeError(f"no ball rule for {_NAMES.get(op, op)}")  # pragma: no cover - _KINK lists the rest


def _replay(op, args, d):
    """A non-smooth operation on series (or jets) along the branch decided over the step's domain;
    on balls, an undecided one is their hull."""
    if d is None:
        if all(isinstance(a, arb) for a in args):
            return _decide(op, args)[0]
        return UNDECIDED
    if op == ca.OP_FABS:
        return UNDECIDED if args[0] is UNDECIDED else (args[0] if d == 1 else J.neg(args[0]))
    if op in (ca.OP_FMIN, ca.OP_FMAX):
        return args[d]
    if op == ca.OP_IF_ELSE_ZERO:
        return args[1] if d == 1 else arb(0)
    if op == ca.OP_FMOD:
        return UNDECIDED if UNDECIDED in args else args[0] - args[1] * d
    return arb(d)  # comparisons, logic, floor, ceil, sign: constant on the domain


def _clarke(op, args):
    """An undecided abs / min / max of jets over balls: hull value, convex hull of the gradients."""
    if UNDECIDED in args or not all(isinstance(a, (J.Jet, arb)) for a in args):
        return UNDECIDED
    if not any(isinstance(a, J.Jet) for a in args):
        return _decide(op, args)[0]
    if op == ca.OP_FABS:
        a = args[0]
        return J.Jet(abs(a.v), [ZERO_ONE * 2 * g - g for g in a.d])
    if op in (ca.OP_FMIN, ca.OP_FMAX):
        a, b = (x if isinstance(x, J.Jet) else J.Jet(x, None) for x in args)
        n = len((a.d or b.d))
        da, db = a.d or [arb(0)] * n, b.d or [arb(0)] * n
        v = a.v.min(b.v) if op == ca.OP_FMIN else a.v.max(b.v)
        return J.Jet(v, [y + ZERO_ONE * (x - y) for x, y in zip(da, db)])
    if op in (ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_NOT, ca.OP_AND, ca.OP_OR):
        return _decide(op, [a.v if isinstance(a, J.Jet) else a for a in args])[0]
    return UNDECIDED


def _truth(v):
    return (ZERO_ONE if v is None else arb(v)), v


def _bool(a) -> int | None:
    """1 / 0 when the ball is certainly nonzero / zero; None otherwise."""
    if a.is_zero():
        return 0
    if not a.contains(0):
        return 1
    return None


def _step_fn(op, a):
    """(hull, decision) of floor, ceil or sign of a ball: the decision is the integer when it is
    the same at every point of the ball."""
    if op == ca.OP_SIGN:
        d = 1 if a > 0 else -1 if a < 0 else 0 if a.is_zero() else None
        return (arb(d) if d is not None else arb("0 +/- 1")), d
    n = math.floor(float(a.mid())) if op == ca.OP_FLOOR else math.ceil(float(a.mid()))
    ok = (a >= n and a < n + 1) if op == ca.OP_FLOOR else (a > n - 1 and a <= n)
    if ok:
        return arb(n), n
    lo, hi = math.floor(float(a.lower())) - 1, math.ceil(float(a.upper())) + 1
    return arb(lo).union(arb(hi)), None


def _trunc_hull(q: arb) -> arb:
    lo, hi = math.floor(float(q.lower())) - 1, math.ceil(float(q.upper())) + 1
    return arb(lo).union(arb(hi))
