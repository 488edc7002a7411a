"""Certified windows: a transition proved for every t_A of an interval, not only at grid points.

Algorithm 1 samples t_A on a grid; between two grid points nothing is known. With the validated
oracle, the start states x_A*([t_i, t_i+1]) of a grid interval are enclosed as one set (a segment
along the setpoint's tangent, with the mean-value remainder: a thin Lohner set, not a box) and
B's closed loop is enclosed from all of them at once, switched in at the t_B the grid verified at
either end. A failing interval is bisected (up to DEPTH times). The transition records the
maximal runs of proved intervals as `certified["windows"]`; a fixed source has one t_A, proved
by its certified grid cell.
"""
from __future__ import annotations

import time

import numpy as np
from flint import arb, arb_mat

from ..compile.primitive import CompiledPrimitive
from ..settings import OracleSettings
from ..spec.models import PrimitiveClass
from ..validated.flow import Options, loop_of, run
from ..validated.jet import Jet
from ..validated.lohner import LohnerSet
from ..validated.tape import Tape
from .transition import Transition, TransitionClass

DEPTH = 3
"""Bisections of a grid interval of t_A before it is left unproved (at most 2^DEPTH sets)."""


def segment(x_star: Tape, ta: float, tb: float) -> tuple[LohnerSet, list]:
    """The set {x_A*(t) : ta < t < tb} as a Lohner set along the tangent at the midpoint (the
    mean-value form x*(tm) + x*'([ta, tb]) (t - tm)), and the ball vector of its hull (the law's
    switch-in state x_sw). The ends are the grid's own cells; inside, the setpoint's branches are
    those of the open interval (decided 1e-6 of its width inside), so a clock switch at an end is no jump."""
    tm, w = (ta + tb) / 2, (tb - ta) / 2
    inner = _ball(ta + 1e-6 * w, tb - 1e-6 * w)
    _, decisions = x_star([[inner]])
    T = _ball(ta, tb)
    (over, *_), _ = x_star([[T]], decisions)
    (jets, *_), _ = x_star([Jet.seed([T], arb(0))], decisions)
    if any(v is None for v in (*over, *jets)):  # a branch switches inside: the box of the range
        (over, *_), _ = x_star([[T]])
        return LohnerSet.box([float(v.mid()) for v in over], [float(v.rad()) for v in over]), list(over)
    (mid, *_), _ = x_star([[arb(tm)]], decisions)
    d = [j.d[0] if isinstance(j, Jet) else arb(0) for j in jets]
    n = len(mid)
    m = [arb(float(v.mid())) for v in mid]
    B = _basis(np.array([float(v.mid()) for v in d]))
    Binv = arb_mat(B.tolist()).inv()
    span = arb(0, w)
    r = Binv * arb_mat([[mid[i] - m[i] + d[i] * span] for i in range(n)])
    start = LohnerSet(m, B, Binv, r)
    return start, start.hull()


def _ball(a: float, b: float) -> arb:
    return arb(a).union(arb(b))


def _basis(v: np.ndarray) -> np.ndarray:
    """An orthonormal basis whose first column is along v (the identity for v = 0)."""
    n = len(v)
    if not np.any(v):
        return np.eye(n)
    Q, _ = np.linalg.qr(np.column_stack([v, np.eye(n)])[:, :n] if n > 1 else v.reshape(1, 1))
    return Q


def prove(a: CompiledPrimitive, b: CompiledPrimitive, ta: float, tb: float, t_B: float, horizon: float,
          opts: Options, depth: int = 0) -> tuple[bool, int, float]:
    """(proved, sets run, widest set) for every t_A in [ta, tb] switched into B at t_B."""
    start, x_sw = segment(Tape.of(a.setpoint), ta, tb)
    enc = run(loop_of(b), start, t_B, horizon, x_sw, opts)
    if enc.status == "safe":
        return True, 1, start.width()
    if depth >= DEPTH or enc.status == "unsafe":
        return False, 1, start.width()
    m = (ta + tb) / 2
    ok1, n1, w1 = prove(a, b, ta, m, t_B, horizon, opts, depth + 1)
    if not ok1:
        return False, 1 + n1, w1
    ok2, n2, w2 = prove(a, b, m, tb, t_B, horizon, opts, depth + 1)
    return ok2, 1 + n1 + n2, max(w1, w2)


def intervals(a: CompiledPrimitive, tr: Transition) -> list[tuple[float, float, list[float]]]:
    """The grid intervals [t_i, t_i+1] of t_A whose ends are certified cells, each with the
    candidate t_B (the ends' own); a periodic source's last interval wraps to t_0 + T."""
    t, bt = list(map(float, tr.t_A)), tr.best_t_B
    out = []
    n = len(t)
    pairs = [(i, i + 1) for i in range(n - 1)]
    if a.cls is PrimitiveClass.PERIODIC and n:
        pairs.append((n - 1, 0))
    for i, j in pairs:
        if not (_cell_certified(tr, i) and _cell_certified(tr, j)):
            continue
        end = t[j] if j > i else t[j] + float(a.period)
        out.append((t[i], end, list(dict.fromkeys([bt[i], bt[j]]))))
    return out


def certify_windows(graph, prims: dict[str, CompiledPrimitive], settings: OracleSettings, executor,
                    progress=None) -> None:
    """Set `certified` on every transition with an edge, the edges side by side on the executor."""
    todo = [tr for tr in graph.transitions.values() if tr.cls != TransitionClass.NONE]
    out = executor.map(certify, [(tr.source, tr.target, tr) for tr in todo], progress, "certified windows",
                       shared=(prims, settings))
    for tr, rec in zip(todo, out):
        tr.certified = rec if isinstance(rec, dict) else {}


def certify(shared, item) -> dict:
    """The certified record of one transition: windows (t_A intervals proved for every t_A), the
    sets run, the Taylor order, the widest start set and the seconds it took."""
    prims, settings = shared
    a_name, b_name, tr = item
    a, b = prims[a_name], prims[b_name]
    opts = Options()
    clock = time.perf_counter()
    proved, sets, width = [], 0, 0.0
    if a.cls is PrimitiveClass.FIXED:
        proved = [(float(tr.t_A[0]), float(tr.t_A[0]))] if _cell_certified(tr, 0) else []
    else:
        for ta, tb, cands in intervals(a, tr):
            for t_B in cands:
                horizon = float(b.horizons(settings.horizon, [t_B])[0])
                ok, n, w = prove(a, b, ta, tb, t_B, horizon, opts)
                sets, width = sets + n, max(width, w)
                if ok:
                    proved.append((ta, tb))
                    break
    return {"windows": [list(w) for w in _runs(proved)], "boxes": sets, "order": opts.order,
            "width": width, "time_s": time.perf_counter() - clock}


def _cell_certified(tr: Transition, i: int) -> bool:
    t_b = tr.best_t_B[i]
    if t_b is None:
        return False
    j = int(np.argmin(np.abs(tr.t_B - t_b)))
    e = tr.evidence[i][j]
    return e.verdict == 1 and e.method == "certified"


def _runs(iv: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Adjacent intervals joined."""
    out: list[list[float]] = []
    for a, b in sorted(iv):
        if out and abs(out[-1][1] - a) < 1e-12:
            out[-1][1] = b
        else:
            out.append([a, b])
    return [tuple(x) for x in out]
