"""The graph executor run on the simulator's own state: when to switch is decided from MuJoCo's
state, not taken from mpgspec's run.

mpgspec's graph run (execute/sequence.py) switches towards the goal once its flow has entered E of
the active primitive, at the next clock t_A the oracle verified (within half a step), to the
verified t_B; a transient hands over to its `next` at the end of its domain. ExecutorPlan holds
what that needs as plain data (the lookup table, each edge's t_A grid and best t_B, the goal
commands), and StateExecutor applies the same rules to the state the simulator reports at each
control update, with E's margin evaluated there. A run can then stall where the simulator's state
never enters E, or switch at other times than mpgspec's run: both are findings.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...compile.contacts import grid_clock
from ...compile.primitive import CompiledPrimitive
from ...graph.transition import executor_clocks, input_bounds, switch_shares
from ...spec.models import PrimitiveClass


@dataclass(frozen=True)
class ExecutorPlan:
    """What the graph executor reads: start primitive, goal commands (t, goal), the lookup table
    (primitive -> goal -> next primitive) and each edge's (t_A grid, the t_B the sequence's switching
    rule takes per t_A)."""

    start: str
    commands: tuple[tuple[float, str], ...]
    table: dict = field(hash=False)
    edges: dict = field(hash=False)  # (from, to) -> (t_A list, switch-in clock list, None where none, share of r_A
    # the executor switches within per t_A: robust/from_roa.py)

    @classmethod
    def of(cls, graph, table: dict, seq, prims: dict[str, CompiledPrimitive]) -> "ExecutorPlan":
        """From a verified graph (MotionPrimitiveGraph or ReportGraph), its lookup table, the
        sequence (its switching rule) and the primitives (for the transients' hand-overs)."""
        pairs = {(a, b) for a, row in table.items() for b in row.values() if b and b != a}
        pairs |= {(n, p.next) for n, p in prims.items() if p.cls is PrimitiveClass.TRANSIENT and p.next}
        edges = {}
        for a, b in sorted(pairs):
            tr = graph.edge(a, b)
            if tr is not None:
                clocks = executor_clocks(tr, prims[a].cls is PrimitiveClass.TRANSIENT, seq.switch,
                                         getattr(seq, "reserve", None), input_bounds(prims[b].system),
                                         getattr(seq, "keep", None))
                edges[(a, b)] = ([float(v) for v in tr.t_A], [None if v is None else float(v) for v in clocks],
                                 switch_shares(tr))
        return cls(seq.start, tuple((float(c.t), c.goal) for c in seq.commands), table, edges)

    def key(self) -> list:
        """The plan as sorted plain data (for a content hash)."""
        return [self.start, list(self.commands), sorted((a, sorted(r.items())) for a, r in self.table.items()),
                sorted([list(k), v] for k, v in self.edges.items())]

    def switch_clock(self, a: str, b: str, t_A: float, tol: float) -> float | None:
        """The verified t_B of edge a -> b for a clock within tol of one of its grid times, else None."""
        j = self._row(a, b, t_A, tol)
        return None if j is None else self.edges[(a, b)][1][j]

    def admits(self, a: str, b: str, t_A: float, tol: float, margin: float, radius: float) -> bool:
        """Whether the state, whose RoA margin r_A - ||x - x_A*(t_A)||_W is `margin`, lies within the share
        of r_A the switch a -> b was checked from at that grid time (within E_A, for a share of 1: a state
        that entered E_A and left it again does not switch)."""
        j = self._row(a, b, t_A, tol)
        shares = self.edges[(a, b)][2] if j is not None else []
        share = float(shares[j]) if j is not None and j < len(shares) else 1.0
        return share > 0 and margin >= (1.0 - share) * float(radius)

    def _row(self, a: str, b: str, t_A: float, tol: float) -> int | None:
        e = self.edges.get((a, b))
        if e is None or not e[0]:
            return None
        tA = np.asarray(e[0], float)
        j = int(np.argmin(np.abs(tA - t_A)))
        return j if abs(tA[j] - t_A) <= tol + 1e-12 else None


class StateExecutor:
    """The graph run's switching rules applied to a simulator's state at its control updates."""

    def __init__(self, plan: ExecutorPlan, prims: dict[str, CompiledPrimitive], rate: float):
        self.plan, self.prims, self.dt = plan, prims, 1.0 / rate
        self.cur, self.goal, self.cmd_i, self.converged = plan.start, plan.start, 0, False
        self.unverified: str = ""
        self.best: dict[str, float] = {}  # per primitive, the largest E margin seen while waiting to enter E
        self.arrivals: list[tuple[float, str]] = [(0.0, plan.start)]  # (t, primitive) of every switch in

    def decide(self, t: float, x: np.ndarray, clock: float) -> dict | None:
        """The switch to make at time t from state x at the active primitive's clock, or None."""
        plan, p = self.plan, self.prims[self.cur]
        while self.cmd_i < len(plan.commands) and plan.commands[self.cmd_i][0] <= t + 1e-12:
            self.goal = plan.commands[self.cmd_i][1]
            self.cmd_i += 1
        if p.cls is PrimitiveClass.TRANSIENT:
            if p.next is None or clock < p.domain[1] - 1e-6:
                return None
            t_B = plan.switch_clock(self.cur, p.next, p.domain[1], 1e-9)
            if t_B is None:
                self.unverified = self.unverified or f"unverified hand-over {self.cur} -> {p.next} at t = {t:.3f} s"
            return self._switch(t, p.next, t_B if t_B is not None else self.prims[p.next].start_clock())
        if self.goal == self.cur:
            return None
        m = None
        if not self.converged:
            m = self._margin(p, x, clock)
            self.best[self.cur] = max(self.best.get(self.cur, -np.inf), m)
            self.converged = m > 0
        if not self.converged:
            return None
        nxt = plan.table.get(self.cur, {}).get(self.goal)
        if not nxt or nxt == self.cur:
            return None
        c = 0.0 if p.cls is PrimitiveClass.FIXED else grid_clock(clock, p.period)
        t_B = plan.switch_clock(self.cur, nxt, c, self.dt / 2)
        if t_B is None:
            return None
        if not plan.admits(self.cur, nxt, c, self.dt / 2, self._margin(p, x, clock) if m is None else m,
                          p.radius_at(clock)):
            return None
        return self._switch(t, nxt, t_B)

    @staticmethod
    def _margin(p: CompiledPrimitive, x, clock: float) -> float:
        return float(np.asarray(p.roa_margin(x, clock), float).ravel()[0])

    def _switch(self, t: float, to: str, t_B: float) -> dict:
        self.cur, self.converged = to, False
        self.arrivals.append((t, to))
        return {"t": t, "to": to, "clock": float(t_B)}

    def goals(self, reference: list[dict] | None = None) -> list[dict]:
        """Per goal command: when the run first got there while it was commanded (None: never), and
        when mpgspec's run did (from its switches, `reference`)."""
        out, cmds = [], self.plan.commands
        for i, (t0, goal) in enumerate(cmds):
            t1 = cmds[i + 1][0] if i + 1 < len(cmds) else np.inf
            out.append({"t": t0, "goal": goal, "arrived": _arrival(self.arrivals, goal, t0, t1),
                        "arrived_mpgspec": _arrival([(s["t"], s["to"]) for s in reference], goal, t0, t1)
                        if reference is not None else None})
        return out


def _arrival(arrivals: list[tuple[float, str]], goal: str, t0: float, t1: float) -> float | None:
    """When a run whose switches in are `arrivals` was first in `goal` during [t0, t1)."""
    here = None
    for t, name in arrivals:  # the primitive active at t0 counts from t0
        if t <= t0 + 1e-12:
            here = name
    if here == goal:
        return float(t0)
    for t, name in arrivals:
        if t0 < t < t1 and name == goal:
            return float(t)
    return None
