"""Dense rollouts the report shows: every verified switch, and the closest attempt of each pair without an edge.

They belong to the graph stage, so the report only formats data and its content does not depend on
how (or where) the oracle calls ran.
"""
from __future__ import annotations

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


def _trace_entry(g, prims, settings, a: str, b: str, i: int, j: int) -> dict:
    """Dense series of B's closed loop from x_A*(t_A[i]) at clock t_B[j], a little past the decision."""
    tr = g.transitions[(a, b)]
    e = tr.evidence[i][j]
    horizon = float(prims[b].horizons(settings.horizon, tr.t_B[j])[0])  # the oracle's own horizon rule
    horizon = min(horizon, max(e.t_stop * 1.2 + 0.2, 0.5))
    try:
        series = trace(prims[b], prims[a].x_star(float(tr.t_A[i])), float(tr.t_B[j]), horizon, settings)
    except Exception as err:
        series = {"error": str(err)[:300]}
    return {"from": a, "to": b, "t_A": float(tr.t_A[i]), "t_B": float(tr.t_B[j]), "reason": e.reason.value,
            "violated": e.violated, "t_stop": _f(e.t_stop), "series": series}


def failure_traces(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], settings: OracleSettings,
                   pairs: list[tuple[str, str]]) -> list[dict]:
    """For pairs without an edge: h over time from the start point whose flow came closest to E."""
    out = []
    prebuild([prims[b] for a, b in pairs if (a, b) in g.transitions
              and g.transitions[(a, b)].cls is TransitionClass.NONE], settings)
    for a, b in pairs:
        tr = g.transitions.get((a, b))
        if tr is None or tr.cls is not TransitionClass.NONE:
            continue
        cells = [(i, j) for i in range(len(tr.t_A)) for j in range(len(tr.t_B))]
        i, j = max(cells, key=lambda c: (tr.evidence[c[0]][c[1]].t_stop,
                                         tr.evidence[c[0]][c[1]].best_roa_margin or -np.inf))
        out.append(_trace_entry(g, prims, settings, a, b, i, j))
    return out


def edge_traces(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], settings: OracleSettings) -> list[dict]:
    """For every edge: h and the E margin over time of the verified switch from the first available t_A."""
    out = []
    prebuild([prims[b] for (a, b), tr in g.transitions.items() if tr.cls is not TransitionClass.NONE], settings)
    for (a, b), tr in g.transitions.items():
        if tr.cls is TransitionClass.NONE:
            continue
        i = next(k for k, t_b in enumerate(tr.best_t_B) if t_b is not None)
        j = int(np.argmin(np.abs(tr.t_B - tr.best_t_B[i])))
        out.append(_trace_entry(g, prims, settings, a, b, i, j))
    return out
