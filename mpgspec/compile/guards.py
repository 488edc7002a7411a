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
_LOGIC = (ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_AND, ca.OP_OR, ca.OP_NOT)
MAX_NODES = 100_000
"""Loops larger than this many SX nodes are not searched (the search takes about 30 us a node)."""
MAX_GUARDS = 64
"""More distinct guards than this in one loop are not located one by one (the loop is reported as
not exposed): each is evaluated at every RK4 stage."""


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
    outs = [o for o in f.call(a) if o.numel()]
    roots = ca.vertcat(*[ca.vec(o) for o in outs]) if outs else ca.SX(0, 1)
    found: list[tuple[ca.SX, str]] = []
    seen: set[int] = set()
    stack = [roots[i] for i in range(roots.numel())]
    while stack:
        e = stack.pop()
        key = e.element_hash()
        if key in seen or e.is_leaf():
            continue
        seen.add(key)
        deps = [e.dep(i) for i in range(e.n_dep())]
        stack.extend(deps)
        g = _guard(e.op(), deps)
        if g is not None and not g[0].is_constant():
            found.append(g)
    live = ca.vertcat(*a[:inputs])
    gs = _distinct([(g, name) for g, name in found if ca.depends_on(g, live) and not _is_logic(g)], a[:inputs])
    if len(gs) > MAX_GUARDS:
        return Guards(exposed=False, why=f"{len(gs)} switching points (more than {MAX_GUARDS})")
    if not gs:
        return Guards()
    if labels is not None and labels[0].is_a("SXFunction"):
        known = ca.vertcat(*labels[0].call(a[:inputs]))
        gs = [(g, next((labels[1][i] for i in range(known.numel()) if ca.is_equal(g, known[i], 64)), name))
              for g, name in gs]
    gs.sort(key=lambda p: p[1])
    fn = ca.Function("guards", a[:inputs], [ca.vertcat(*[g for g, _ in gs])], ["x", "t", "s", "x_sw"][:inputs], ["g"])
    return Guards(fn, [name for _, name in gs])


def _distinct(gs: list, args: list) -> list:
    """gs without repeats: the same test written twice is one guard. Two guards are the same when
    they print alike and take the same value at a fixed pseudo-random point (printing rounds
    constants: t < 0.2537 and t < 0.2537000003 print alike and are two guards)."""
    if not gs:
        return gs
    rng = np.random.default_rng(0)
    point = [rng.uniform(0.1, 0.9, a.shape) for a in args]
    with np.errstate(all="ignore"):
        values = np.asarray(ca.Function("probe", args, [ca.vertcat(*[g for g, _ in gs])])(*point), float).ravel()
    out: dict[tuple[str, str], tuple] = {}
    for (g, name), v in zip(gs, values):
        out.setdefault((str(g), repr(float(v))), (g, name))
    return list(out.values())


def _guard(op: int, deps: list) -> tuple[ca.SX, str] | None:
    """(g, name) for a non-smooth operation, else None."""
    if op in _DIFF:
        if any(d.is_constant() and not np.isfinite(float(d)) for d in deps):  # a finiteness test: never switches
            return None
        g = deps[1] - deps[0] if op in (ca.OP_LT, ca.OP_LE) else deps[0] - deps[1]
        return g, f"{_DIFF[op]}: {_short(deps[0])} vs {_short(deps[1])}"
    if op in _ARG:
        return deps[0], f"{_ARG[op]}: {_short(deps[0])}"
    if op == ca.OP_COPYSIGN:
        return deps[1], f"copysign: {_short(deps[1])}"
    if op in _PERIODIC:
        return ca.sin(ca.pi * deps[0]), f"{_PERIODIC[op]}: {_short(deps[0])}"
    if op in _RATIO:
        return ca.sin(ca.pi * deps[0] / deps[1]), f"{_RATIO[op]}: {_short(deps[0])} / {_short(deps[1])}"
    return None


def _is_logic(g: ca.SX) -> bool:
    """A guard that is itself a condition (the argument of if_else is a comparison, whose own
    guard is the difference of its sides)."""
    return g.is_scalar() and not g.is_leaf() and g.op() in _LOGIC


def _short(e: ca.SX, n: int = 60) -> str:
    s = str(e)
    return s if len(s) <= n else s[:n - 3] + "..."
