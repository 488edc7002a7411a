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


def _start_points(prims, gA, gB, b):
    """Algorithm 1 lines 3-8 for one target B: x_A*(t_A) for every other A, paired with every t_B."""
    x0s, t0s, index = [], [], []
    for a in prims:
        if a == b:
            continue
        for i, ta in enumerate(gA[a]):
            xa = prims[a].x_star(float(ta))
            for j, tb in enumerate(gB[b]):
                x0s.append(xa)
                t0s.append(tb)
                index.append((a, i, j))
    nx = next(iter(prims.values())).system.nx
    return np.array(x0s).reshape(-1, nx), np.array(t0s, float), index


def _evaluate_serial(prims, settings, b, x0s, t0s, oracles) -> list[OracleEvidence]:
    try:
        if b not in oracles:
            oracles[b] = SafetyOracle(prims[b], settings)
        return oracles[b].evaluate(x0s, t0s)
    except Exception as err:  # a compile or backend failure is this batch's evidence
        return [OracleEvidence(0, Reason.ERROR, 0.0, message=str(err)[:500])] * len(t0s)


def build_graph(prims: dict[str, CompiledPrimitive], settings: OracleSettings, n_A: int = 12, n_B: int = 12,
                progress: Progress | None = None, oracles: dict[str, SafetyOracle] | None = None,
                workers: int = 1, factory: Callable[[], dict] | None = None) -> MotionPrimitiveGraph:
    """Run the oracle of every target B on the setpoints of every other primitive A.

    All (A, t_A, t_B) start points of one target B go to its oracle in one batch; with workers > 1
    and a factory that rebuilds the primitives, targets run in parallel processes. A failing
    oracle call becomes that call's evidence (reason 'error') and the build goes on.
    """
    gA, gB = grids(prims, n_A, n_B)
    oracles = oracles if oracles is not None else {}
    transitions: dict[tuple[str, str], Transition] = {}
    names = list(prims)
    points = {b: _start_points(prims, gA, gB, b) for b in names}
    if workers > 1 and factory is not None:
        from ..oracle.parallel import run_jobs

        if progress:
            progress(f"oracle on {workers} processes", 0, len(names))
        results = dict(zip(names, run_jobs([(b, points[b][0], points[b][1]) for b in names], factory, settings,
                                           workers)))
    else:
        results = {}
        for k, b in enumerate(names):
            if progress:
                progress(f"oracle {b}", k, len(names))
            results[b] = _evaluate_serial(prims, settings, b, points[b][0], points[b][1], oracles)
    for b in names:
        sources = [a for a in names if a != b]
        index, ev = points[b][2], results[b]
        for a in sources:
            cells = [[None] * len(gB[b]) for _ in gA[a]]
            transitions[(a, b)] = Transition(a, b, gA[a], gB[b], cells)
        for (a, i, j), e in zip(index, ev):
            transitions[(a, b)].evidence[i][j] = e
        for a in sources:
            transitions[(a, b)].classify()
    if progress:
        progress("oracle", len(names), len(names))
    nodes = {n: {"cls": p.cls.value, "period": p.period, "domain": p.domain, "next": p.next}
             for n, p in prims.items()}
    return MotionPrimitiveGraph(nodes, transitions)
