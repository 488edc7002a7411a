"""Guards: where a closed loop stops being smooth, as functions that change sign there.

RK4 and its error estimates assume a smooth right-hand side. A law that switches (`if_else`, a
comparison, `sign`), a kink (`abs`, `min`/`max`, `clip`, input saturation) or a jump (`floor`,
`ceil`, `fmod`) breaks that assumption between samples. Each such point of the closed loop's
expression graph is a guard g(x, t, s, x_sw) whose sign changes exactly where the loop switches
branch: the difference of a comparison's sides (an `if_else` switches where its condition's
comparison does; a comparison with an infinite constant, a finiteness test, never switches), the argument of `sign`/`abs`, the difference of
`min`/`max`'s arguments (input saturation: u_raw minus its bound), sin(pi a) for `floor(a)`.
The oracle (oracle/integrator.py) integrates piece by piece between the guards' crossings.

Guards are collected from an SX closed loop, a robot's too (a walk's loop of 17,650 nodes is searched
in about half a second): a loop that calls a compiled Function (an optimisation-based law) is not
expanded, and its guards are reported as not exposed, with the reason.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

_DIFF = {ca.OP_LT: "<", ca.OP_LE: "<=", ca.OP_EQ: "==", ca.OP_NE: "!=", ca.OP_FMIN: "min", ca.OP_FMAX: "max"}
_ARG = {ca.OP_SIGN: "sign", ca.OP_FABS: "abs"}
_PERIODIC = {ca.OP_FLOOR: "floor", ca.OP_CEIL: "ceil"}
_RATIO = {ca.OP_FMOD: "fmod", ca.OP_REMAINDER: "remainder"}
_OPS = {*_DIFF, *_ARG, *_PERIODIC, *_RATIO, ca.OP_COPYSIGN}
_LOGIC = (ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_AND, ca.OP_OR, ca.OP_NOT)
MAX_NODES = 100_000
"""Loops larger than this many SX nodes are not searched (the search takes about 30 us a node)."""
MAX_GUARDS = 128
"""More distinct guards than this in one loop are not located one by one (the loop is reported as
not exposed, and `mpgspec verify` warns): each is evaluated at every RK4 stage. A trot has about 70
(its torque limits, gait phases, swing profile, ramps and contact flags)."""


@dataclass
class Guards:
    """The guards of one closed loop.

    fn: (x, t, s, x_sw) -> g (one row per guard), None when none are exposed; names: what each
    guard is (the operation and its expression, shortened); exposed: the loop's expression graph
    could be searched; why: the reason when it could not.
    """

    fn: ca.Function | None = None
    names: list[str] = field(default_factory=list)
    exposed: bool = True
    why: str = ""

    def __len__(self) -> int:
        return len(self.names)

    def record(self) -> dict:
        """The report's record: the guards by name, or why none could be exposed."""
        return {"exposed": self.exposed, "guards": list(self.names), **({"why": self.why} if self.why else {})}


def collect(f: ca.Function, inputs: int = 4, labels: tuple[ca.Function, list[str]] | None = None) -> Guards:
    """The guards of f's outputs as functions of its first `inputs` inputs (x, t, s, x_sw). labels:
    a Function of the same inputs giving known guard expressions (input saturation's) and their
    names, which replace the printed expression of a guard equal to one of them."""
    if not f.is_a("SXFunction"):
        return Guards(exposed=False, why="the loop calls a compiled function (an optimisation-based law): its "
                                         "switching points are not exposed")
    if f.n_nodes() > MAX_NODES:
        return Guards(exposed=False, why=f"a loop of {f.n_nodes()} nodes (more than {MAX_NODES}): its "
                                         "switching points are not searched")
    a = f.sx_in()
    tape = f.instructions_sx()  # every operation of f, in terms of its inputs a
    found = []
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        if op in _OPS:
            e = tape[k]
            deps = [e.dep(i) for i in range(e.n_dep())]
            g = _guard(op, deps)
            if g is not None and not g.is_constant():
                found.append((g, op, deps))
    live = ca.vertcat(*a[:inputs])
    gs = _distinct([c for c in found if ca.depends_on(c[0], live) and not _is_logic(c[0])], a[:inputs])
    if len(gs) > MAX_GUARDS:
        return Guards(exposed=False, why=f"{len(gs)} switching points (more than {MAX_GUARDS})")
    if not gs:
        return Guards()
    known, lexprs, lnames = {}, [], []
    if labels is not None and labels[0].is_a("SXFunction"):
        lv = ca.vertcat(*labels[0].call(a[:inputs]))
        lexprs, lnames = [lv[i] for i in range(lv.numel())], labels[1]
        for i, key in enumerate(_probe(lexprs, a[:inputs])):
            known.setdefault(key, []).append(i)
    named = [(g, _label(g, key, known, lexprs, lnames) or _name(op, deps)) for (g, op, deps), key in gs]
    named.sort(key=lambda p: p[1])
    fn = ca.Function("guards", a[:inputs], [ca.vertcat(*[g for g, _ in named])], ["x", "t", "s", "x_sw"][:inputs],
                     ["g"])
    return Guards(fn, [name for _, name in named])


def _probe(exprs: list, args: list) -> list:
    """Each expression's values at two fixed pseudo-random points of the arguments: a cheap first
    test of equality (ca.is_equal then decides)."""
    if not exprs:
        return []
    rng = np.random.default_rng(0)
    with np.errstate(all="ignore"):
        F = ca.Function("probe", args, [ca.vertcat(*[ca.vec(e) for e in exprs])])
        v = [np.asarray(F(*[rng.uniform(0.1, 0.9, x.shape) for x in args]), float).ravel() for _ in range(2)]
    return [(repr(float(v[0][i])), repr(float(v[1][i]))) for i in range(len(exprs))]


def _distinct(found: list, args: list) -> list:
    """[(guard, its probe key)] without repeats: the same test written twice is one guard (equal
    at the probe points and as expressions; printing rounds constants: t < 0.2537 and
    t < 0.2537000003 print alike and are two guards)."""
    buckets: dict = {}
    for c, key in zip(found, _probe([g for g, _op, _deps in found], args)):
        same = buckets.setdefault(key, [])
        if not any(ca.is_equal(c[0], d[0], 64) for d in same):
            same.append(c)
    return [(c, key) for key, cs in buckets.items() for c in cs]


def _label(g, key, known: dict, exprs: list, names: list) -> str | None:
    """The known name of guard g (a label expression equal to it), else None."""
    return next((names[i] for i in known.get(key, ()) if ca.is_equal(g, exprs[i], 64)), None)


def _guard(op: int, deps: list):
    """g for a non-smooth operation (it changes sign where the operation switches), else None."""
    if op in _DIFF:
        if any(d.is_constant() and not np.isfinite(float(d)) for d in deps):  # a finiteness test: never switches
            return None
        return deps[1] - deps[0] if op in (ca.OP_LT, ca.OP_LE) else deps[0] - deps[1]
    if op in _ARG:
        return deps[0]
    if op == ca.OP_COPYSIGN:
        return deps[1]
    if op in _PERIODIC:
        return ca.sin(ca.pi * deps[0])
    if op in _RATIO:
        return ca.sin(ca.pi * deps[0] / deps[1])
    return None


def _name(op: int, deps: list) -> str:
    """What a guard is: its operation and operands, shortened."""
    if op in _DIFF:
        return f"{_DIFF[op]}: {_short(deps[0])} vs {_short(deps[1])}"
    if op in _ARG:
        return f"{_ARG[op]}: {_short(deps[0])}"
    if op == ca.OP_COPYSIGN:
        return f"copysign: {_short(deps[1])}"
    if op in _PERIODIC:
        return f"{_PERIODIC[op]}: {_short(deps[0])}"
    return f"{_RATIO[op]}: {_short(deps[0])} / {_short(deps[1])}"


def _is_logic(g: ca.SX) -> bool:
    """A guard that is itself a condition (the argument of if_else is a comparison, whose own
    guard is the difference of its sides)."""
    return g.is_scalar() and not g.is_leaf() and g.op() in _LOGIC


def _short(e: ca.SX, n: int = 60) -> str:
    s = str(e)
    return s if len(s) <= n else s[:n - 3] + "..."
