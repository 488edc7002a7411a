"""Algorithm 1, BuildMotionPrimitiveGraph: the oracle over (t_A, t_B) grids for all ordered pairs."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..oracle.evidence import OracleEvidence
from ..oracle.executors import Executor, InProcess, split
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


def _scales(p: CompiledPrimitive, t_B: np.ndarray) -> np.ndarray:
    """Each safety function's value at the setpoint x*(t_B), switched in there (one row per t_B):
    how far from its boundary the primitive keeps it at rest, the unit of the margin weight."""
    return np.array([np.asarray(p.h(p.x_star(float(t)), float(t), 0.0, p.x_star(float(t))), float).ravel()
                     for t in t_B]).reshape(len(t_B), len(p.h_names))


def build_graph(prims: dict[str, CompiledPrimitive], settings: OracleSettings, n_A: int = 12, n_B: int = 12,
                progress: Progress | None = None, executor: Executor | None = None,
                recheck: frozenset = frozenset()) -> MotionPrimitiveGraph:
    """Run the oracle of every target B on the setpoints of every other primitive A.

    The start points of all targets are split into tasks for the executor (in-process unless
    given); a failing oracle call becomes that call's evidence (reason 'error') and the build goes
    on. The result does not depend on the executor.
    """
    executor = executor or InProcess()
    gA, gB = grids(prims, n_A, n_B)
    names = list(prims)
    points = {b: _start_points(prims, gA, gB, b) for b in names}
    flags = {b: np.array([(a, b) in recheck for a, _i, _j in points[b][2]], bool) for b in names}
    tasks = split({b: (*points[b][:2], flags[b]) for b in names}, executor.workers)
    results: dict[str, list[OracleEvidence]] = {b: [] for b in names}
    for task, ev in zip(tasks, executor.run(prims, settings, tasks, progress)):
        results[task.target].extend(ev)
    transitions: dict[tuple[str, str], Transition] = {}
    for b in names:
        sources = [a for a in names if a != b]
        for a in sources:
            cells = [[None] * len(gB[b]) for _ in gA[a]]
            transitions[(a, b)] = Transition(a, b, gA[a], gB[b], cells)
        for (a, i, j), e in zip(points[b][2], results[b]):
            transitions[(a, b)].evidence[i][j] = e
        scales = None
        for a in sources:
            tr = transitions[(a, b)]
            tr.classify()
            if tr.weights:
                scales = _scales(prims[b], gB[b]) if scales is None else scales
                m = tr.measure_margins(prims[b].h_names, scales)
                if m is not None:
                    tr.weights["margin"] = m
    if progress:
        progress("oracle", len(tasks), len(tasks))
    nodes = {n: {"cls": p.cls.value, "period": p.period, "domain": p.domain, "next": p.next}
             for n, p in prims.items()}
    return MotionPrimitiveGraph(nodes, transitions)
