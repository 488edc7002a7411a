"""Algorithm 1, BuildMotionPrimitiveGraph: the oracle over (t_A, t_B) grids for all ordered pairs."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..oracle.evidence import OracleEvidence, Reason
from ..oracle.oracle import SafetyOracle
from ..settings import OracleSettings
from .transition import MotionPrimitiveGraph, Transition

Progress = Callable[[str, int, int], None]


def grids(prims: dict[str, CompiledPrimitive], n_A: int, n_B: int) -> tuple[dict, dict]:
    """t_A and t_B samples per primitive, by class (fixed: one point; periodic: one period; transient: domain)."""
    gA = {n: p.clock_grid(p.grid_A or n_A, "A") for n, p in prims.items()}
    gB = {n: p.clock_grid(p.grid_B or n_B, "B") for n, p in prims.items()}
    return gA, gB


def build_graph(prims: dict[str, CompiledPrimitive], settings: OracleSettings, n_A: int = 12, n_B: int = 12,
                progress: Progress | None = None,
                oracles: dict[str, SafetyOracle] | None = None) -> MotionPrimitiveGraph:
    """Run the oracle of every target B on the setpoints of every other primitive A.

    All (A, t_A, t_B) start points of one target B go to its oracle in one batch. A failing
    oracle call becomes that call's evidence (reason 'error') and the build goes on.
    """
    gA, gB = grids(prims, n_A, n_B)
    oracles = oracles if oracles is not None else {}
    transitions: dict[tuple[str, str], Transition] = {}
    names = list(prims)
    for k, b in enumerate(names):
        if progress:
            progress(f"oracle {b}", k, len(names))
        try:
            oracle = oracles.get(b) or SafetyOracle(prims[b], settings)
            oracles[b] = oracle
        except Exception as err:  # compile failure of one target
            oracle, fail = None, str(err)
        sources = [a for a in names if a != b]
        x0s, t0s, index = [], [], []
        for a in sources:
            for i, ta in enumerate(gA[a]):
                xa = prims[a].x_star(float(ta))
                for j, tb in enumerate(gB[b]):
                    x0s.append(xa)
                    t0s.append(tb)
                    index.append((a, i, j))
        if oracle is not None and x0s:
            try:
                ev = oracle.evaluate(np.array(x0s), np.array(t0s))
            except Exception as err:
                ev = [OracleEvidence(0, Reason.ERROR, 0.0, message=str(err)[:500])] * len(x0s)
        else:
            ev = [OracleEvidence(0, Reason.ERROR, 0.0, message=fail)] * len(x0s)
        for a in sources:
            cells = [[None] * len(gB[b]) for _ in gA[a]]
            transitions[(a, b)] = Transition(a, b, gA[a], gB[b], cells)
        for (a, i, j), e in zip(index, ev):
            transitions[(a, b)].evidence[i][j] = e
        for a in sources:
            transitions[(a, b)].classify(prims[a].t_range[1])
    if progress:
        progress("oracle", len(names), len(names))
    nodes = {n: {"cls": p.cls.value, "period": p.period, "domain": p.domain, "next": p.next}
             for n, p in prims.items()}
    return MotionPrimitiveGraph(nodes, transitions)
