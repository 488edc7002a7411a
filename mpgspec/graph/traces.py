"""Dense rollouts the report shows: every verified switch, and the closest attempt of each pair without an edge.

They belong to the graph stage, so the report only formats data and its content does not depend on
how (or where) the oracle calls ran.
"""
from __future__ import annotations

import hashlib

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..oracle.joint import Map
from ..oracle.tasks import Failed
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


def _traces(g, prims, settings, cells: list[tuple[str, str, int, int]], memo):
    """The entries of the chosen (A, B, i, j) cells as a stage (mpgspec.oracle.joint): dense series of
    B's closed loop from x_A*(t_A[i]) at clock t_B[j]. Series traced before with the same closed
    loop, start, horizon and settings come from the memo (a run with nothing changed simulates
    nothing); the trace chunks of the rest are compiled side by side first, then traced as one map.
    An error is the trace's content, never remembered."""
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
    todo = [k for k, known in enumerate(series) if known is None]
    prebuild(list({id(prims[cells[k][1]]): prims[cells[k][1]] for k in todo}.values()), settings)
    items = []
    for k in todo:
        a, b, i, j = cells[k]
        tr = g.transitions[(a, b)]
        items.append((b, prims[a].x_star(float(tr.t_A[i])), float(tr.t_B[j]), horizons[k]))
    done = yield Map(_traced, items, "traces", (prims, settings), cost=[h for *_, h in items])
    for k, known in zip(todo, done):
        if isinstance(known, Failed):  # the worker died: as a raising trace
            known = {"error": known.error[:300]}
        elif keys[k] is not None and "failed" not in known and "error" not in known:
            memo.put(keys[k], known)
        series[k] = known
    out = []
    for (a, b, i, j), known in zip(cells, series):
        tr = g.transitions[(a, b)]
        e = tr.evidence[i][j]
        out.append({"from": a, "to": b, "t_A": float(tr.t_A[i]), "t_B": float(tr.t_B[j]), "reason": e.reason.value,
                    "violated": e.violated, "t_stop": _f(e.t_stop), "series": known})
    return out


def _traced(shared: tuple, item: tuple) -> dict:
    """One dense series (a map item): shared = (prims, settings), item = (B, x0, t_B, horizon)."""
    prims, settings = shared
    b, x0, t_b, horizon = item
    try:
        return trace(prims[b], x0, t_b, horizon, settings)
    except Exception as err:  # noqa: BLE001 - the trace's content
        return {"error": str(err)[:300]}


def traces_stage(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], settings: OracleSettings,
                 pairs: list[tuple[str, str]], memo=None):
    """(edge traces, failure traces) as a stage: h and the E margin over time of every edge's
    verified switch and of each pair without an edge from its closest attempt (memo:
    mpgspec.oracle.cache.Memo, to keep traces between runs), traced in one map."""
    edges, failures = _edge_cells(g), _failure_cells(g, pairs)
    out = yield from _traces(g, prims, settings, edges + failures, memo)
    return out[:len(edges)], out[len(edges):]


def _failure_cells(g: MotionPrimitiveGraph, pairs: list[tuple[str, str]]) -> list[tuple[str, str, int, int]]:
    """For pairs without an edge: the start point whose flow came closest to E."""
    cells = []
    for a, b in pairs:
        tr = g.transitions.get((a, b))
        if tr is None or tr.cls is not TransitionClass.NONE:
            continue
        grid = [(i, j) for i in range(len(tr.t_A)) for j in range(len(tr.t_B))]
        i, j = max(grid, key=lambda c: (tr.evidence[c[0]][c[1]].t_stop,
                                        tr.evidence[c[0]][c[1]].best_roa_margin or -np.inf))
        cells.append((a, b, i, j))
    return cells


def _edge_cells(g: MotionPrimitiveGraph) -> list[tuple[str, str, int, int]]:
    """For every edge: the verified switch from the first available t_A."""
    cells = []
    for (a, b), tr in g.transitions.items():
        if tr.cls is TransitionClass.NONE:
            continue
        i = next(k for k, t_b in enumerate(tr.best_t_B) if t_b is not None)
        cells.append((a, b, i, int(np.argmin(np.abs(tr.t_B - tr.best_t_B[i])))))
    return cells
