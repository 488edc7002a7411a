"""Switches checked from the boundary of E_A, at the nominal parameters.

Algorithm 1 verifies A -> B from x_A*(t_A) only, but the executor leaves A as soon as the state is in
E_A (and the lookup table allows the switch at that clock), so a switch is made from anywhere in E_A.
Here every row of an edge that the executor may switch through (a verified t_A, at its best t_B) is
also checked from seeded samples of E_A(t_A)'s boundary (starts.boundary_starts: on the contact
manifold of A's feet for a robot), with B's oracle and the settings of the grid. A row is taken by the
executor only when every sample is safe (an inconclusive one is not); an edge left with no such row is
not executable (plan.planner.plan_graph). A transient source hands over from the end of its own flow,
not from E_A: its rows are not checked. Sampled, so the evidence is empirical.
"""
from __future__ import annotations

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..graph.transition import MotionPrimitiveGraph, input_bounds, switch_clocks
from ..oracle.executors import Executor, InProcess, split
from ..settings import OracleSettings
from ..spec.models import PrimitiveClass
from .starts import boundary_starts

SEED = 0
"""Seed of the samples (sample k of a source has the same direction for every target and row)."""

RIGID_BODY_SAMPLES = 8
"""Samples per row when the project does not say (oracle.from_roa), for rigid bodies; other systems: none."""


def from_roa_samples(spec) -> dict[str, int]:
    """Samples of E_A's boundary per row, by source primitive, for a project (ProjectSpec): the primitive's
    roa.boundary_samples, else the project's oracle.from_roa, else RIGID_BODY_SAMPLES for a rigid body and 0
    (no check) for other systems."""
    n = spec.project.oracle.from_roa
    if n is None:
        n = RIGID_BODY_SAMPLES if getattr(spec.system, "kind", None) == "rigid_body" else 0
    out = {}
    for inst in spec.primitives:
        own = inst.spec.roa.boundary_samples
        out[inst.name] = int(n if own is None else own)
    return out


def samples_of(samples: int | dict[str, int], source: str) -> int:
    """Samples a row out of `source` is checked from (one count for every source, or a count by source)."""
    return int(samples.get(source, 0)) if isinstance(samples, dict) else int(samples)


def _rows(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], rule: str, reserve: float | None,
          keep: dict[str, float] | None = None):
    """(a, b, i, t_A, t_B, taken) of every verified row from a non-transient source; taken: whether the
    sequence's switching rule, reserve and keep take it (switch_clocks on the grid before this check)."""
    for (a, b), tr in g.transitions.items():
        if g.edge(a, b) is None or prims[a].cls is PrimitiveClass.TRANSIENT:
            continue
        taken = switch_clocks(tr, rule, reserve, input_bounds(prims[b].system), keep)
        for i, t_b in enumerate(tr.best_t_B):
            if t_b is not None:
                yield a, b, i, float(tr.t_A[i]), float(t_b), taken[i] is not None


FRACTIONS = (1.0, 0.5, 0.25)
"""Shares of r_A a row is checked at, in turn, until every sample of that sphere is safe."""


def check_from_roa(g: MotionPrimitiveGraph, prims: dict[str, CompiledPrimitive], settings: OracleSettings,
                   samples: int | dict[str, int], executor: Executor | None = None, progress=None, rule: str = "first",
                   reserve: float | None = None, keep: dict[str, float] | None = None) -> int:
    """Fill each edge's row_from_roa (per t_A: [share of r_A, safe samples, samples drawn on E_A's
    boundary], None where the row is not checked) and from_roa_worst (the worst sample on E_A's
    boundary that was not safe); returns the oracle calls made. `samples`: per row, or by source primitive.

    A row is checked at r_A; when a sample there is not safe, at each smaller share of FRACTIONS in
    turn. Its share is the first at which every sample is safe (0 when none is: the row is refused),
    and the executor switches through the row only within that share of r_A from x_A*(t_A). A verified
    row the sequence's `rule`, `reserve` and `keep` never take (graph.transition.switch_clocks) is not checked and
    is refused: [0, 0, 0]."""
    executor = executor or InProcess()
    for tr in g.transitions.values():
        tr.row_from_roa = [None] * len(tr.t_A) if g.edge(tr.source, tr.target) is not None else []
        tr.from_roa_worst = None
    todo = []
    for a, b, i, t_a, t_b, taken in _rows(g, prims, rule, reserve, keep):
        if taken:
            todo.append((a, b, i, t_a, t_b))
        else:
            g.transitions[(a, b)].row_from_roa[i] = [0.0, 0, 0]
    calls = 0
    for level, share in enumerate(FRACTIONS):
        if not todo:
            break
        evidence = _run(g, prims, settings, samples, share, todo, executor, progress)
        calls += sum(len(ev) for ev in evidence.values())
        left = []
        for row in todo:
            a, b, i, _t_a, t_b = row
            ev = evidence.get(row, [])
            safe = sum(e.status == "safe" for e in ev)
            tr = g.transitions[(a, b)]
            if not ev:  # no sample of E_A's sphere could be drawn (E empty, or W weighs nothing): not checked
                tr.row_from_roa[i] = None
                continue
            if level == 0:
                tr.row_from_roa[i] = [1.0, safe, len(ev)]
                for k, e in enumerate(ev):
                    if e.status != "safe" and _worse(e, tr.from_roa_worst):
                        tr.from_roa_worst = {"t_A": float(tr.t_A[i]), "t_B": t_b, "sample": k, "status": e.status,
                                             "violated": e.violated, "margin": e.margin, "reason": e.reason.value}
            if safe == len(ev):
                tr.row_from_roa[i][0] = share
            else:
                tr.row_from_roa[i][0] = 0.0
                left.append(row)
        todo = left
    return calls


def _run(g, prims, settings, samples: int, share: float, rows: list, executor, progress) -> dict:
    """Evidence of B's oracle from the samples of each row's sphere at share x r_A, by row."""
    points: dict[str, list] = {}
    for row in rows:
        a, b, _i, t_a, t_b = row
        src = prims[a] if share == 1.0 else prims[a].with_radius(share * float(prims[a].radius))
        for s in boundary_starts(src, t_a, samples_of(samples, a), SEED):
            points.setdefault(b, []).append((s.x, t_b, row))
    if not points:
        return {}
    nx = next(iter(prims.values())).system.nx
    batches = {b: (np.array([p[0] for p in pts]).reshape(-1, nx), np.array([p[1] for p in pts], float))
               for b, pts in points.items()}
    tasks = split(batches, executor.workers)
    results: dict[str, list] = {b: [] for b in batches}
    for task, ev in zip(tasks, executor.run(prims, settings, tasks, progress)):
        results[task.target].extend(ev)
    out: dict = {}
    for b, pts in points.items():
        for (_x, _t_b, row), e in zip(pts, results[b]):
            out.setdefault(row, []).append(e)
    return out


def _worse(e, worst: dict | None) -> bool:
    """An unsafe sample before an inconclusive one, then the lower margin."""
    if worst is None:
        return True
    rank = {"unsafe": 0, "inconclusive": 1}
    a, b = rank.get(e.status, 2), rank.get(worst["status"], 2)
    m = e.margin if e.margin is not None else np.inf
    return a < b or (a == b and m < (worst["margin"] if worst["margin"] is not None else np.inf))
