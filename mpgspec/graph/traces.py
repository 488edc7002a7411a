"""Dense rollouts the report shows: every verified switch, and the closest attempt of each pair without an edge.

They belong to the graph stage, so the report only formats data and its content does not depend on
how (or where) the oracle calls ran.
"""
from __future__ import annotations

import hashlib

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..oracle.trace import prebuild, trace
from ..settings import OracleSettings
from .transition import MotionPrimitiveGraph, TransitionClass


def _f(v):
    if v is None:
        return None
    v = float(v)
    return v if np.isfinite(v) else None


TRACE_RECORD = 2
"""Layout of a memoised trace (part of its key)."""


def _horizon(prims, settings, tr, b: str, i: int, j: int) -> float:
    """The oracle's own horizon rule, cut to a little past the decision."""
    horizon = float(prims[b].horizons(settings.horizon, tr.t_B[j])[0])
    return min(horizon, max(tr.evidence[i][j].t_stop * 1.2 + 0.2, 0.5))


def _traces(g, prims, settings, cells: list[tuple[str, str, int, int]], memo) -> list[dict]:
    """The entries of the chosen (A, B, i, j) cells: dense series of B's closed loop from x_A*(t_A[i])
    at clock t_B[j]. Series traced before with the same closed loop, start, horizon and settings
    come from the memo (a run with nothing changed simulates nothing); the trace chunks of the rest
    are compiled side by side first. An error is the trace's content, never remembered."""
    keys, series, horizons = [], [], []
    for a, b, i, j in cells:
        tr = g.transitions[(a, b)]
        horizons.append(_horizon(prims, settings, tr, b, i, j))
        x0 = prims[a].x_star(float(tr.t_A[i]))
        key = memo.key("trace", TRACE_RECORD, prims[b].digest(),
                       hashlib.sha256(np.ascontiguousarray(x0, float).tobytes()).hexdigest(),
                       repr(float(tr.t_B[j])), repr(horizons[-1]), repr(settings)) if memo is not None else None
        keys.append(key)
        series.append(memo.get(key) if key is not None else None)
    prebuild(list({id(prims[c[1]]): prims[c[1]] for c, s in zip(cells, series) if s is None}.values()), settings)
    out = []
    for (a, b, i, j), key, known, horizon in zip(cells, keys, series, horizons):
        tr = g.transitions[(a, b)]
        if known is None:
            try:
                known = trace(prims[b], prims[a].x_star(float(tr.t_A[i])), float(tr.t_B[j]), horizon, settings)
                if key is not None and "failed" not in known:
                    memo.put(key, known)
            except Exception as err:
                known = {"error": str(err)[:300]}
        e = tr.evidence[i][j]
        out.append({"from": a, "to": b, "t_A": float(tr.t_A[i]), "t_B": float(tr.t_B[j]), "reason": e.reason.value,
                    "violated": e.violated, "t_stop": _f(e.t_stop), "series": known})
    return out


def failure_traces(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], settings: OracleSettings,
                   pairs: list[tuple[str, str]], memo=None) -> list[dict]:
    """For pairs without an edge: h over time from the start point whose flow came closest to E
    (memo: mpgspec.oracle.cache.Memo, to keep traces between runs)."""
    cells = []
    for a, b in pairs:
        tr = g.transitions.get((a, b))
        if tr is None or tr.cls is not TransitionClass.NONE:
            continue
        grid = [(i, j) for i in range(len(tr.t_A)) for j in range(len(tr.t_B))]
        i, j = max(grid, key=lambda c: (tr.evidence[c[0]][c[1]].t_stop,
                                        tr.evidence[c[0]][c[1]].best_roa_margin or -np.inf))
        cells.append((a, b, i, j))
    return _traces(g, prims, settings, cells, memo)


def edge_traces(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], settings: OracleSettings,
                memo=None) -> list[dict]:
    """For every edge: h and the E margin over time of the verified switch from the first available t_A
    (memo as in failure_traces)."""
    cells = []
    for (a, b), tr in g.transitions.items():
        if tr.cls is TransitionClass.NONE:
            continue
        i = next(k for k, t_b in enumerate(tr.best_t_B) if t_b is not None)
        cells.append((a, b, i, int(np.argmin(np.abs(tr.t_B - tr.best_t_B[i])))))
    return _traces(g, prims, settings, cells, memo)
