"""Simulate a timed sequence of goal primitives in two modes.

naive: switch to each goal at once, with the goal's clock at its start.
graph: follow the lookup table; leave a primitive only after its flow entered its E, and only at
a grid time t_A where the oracle verified the transition, switching in at the verified t_B.
Transients hand over to their `next` at the end of their domain in both modes. Safety (every h of
the active primitive) is monitored throughout.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..graph.transition import MotionPrimitiveGraph
from ..oracle.integrator import build_chunk, initial_state
from ..settings import OracleSettings
from ..spec.models import PrimitiveClass, Sequence


@dataclass
class SequenceRun:
    """Result of one mode: switches made, safety violations and a decimated trajectory."""

    mode: str
    safe: bool = True
    switches: list[dict] = field(default_factory=list)
    violations: list[dict] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    x: list[list[float]] = field(default_factory=list)
    min_h: list[float] = field(default_factory=list)
    active: list[str] = field(default_factory=list)
    final_primitive: str = ""
    failed: str = ""

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def _start_clock(p: CompiledPrimitive) -> float:
    return p.domain[0] if p.cls is PrimitiveClass.TRANSIENT else 0.0


def simulate_sequence(prims: dict[str, CompiledPrimitive], graph: MotionPrimitiveGraph | None,
                      table: dict | None, seq: Sequence, settings: OracleSettings, mode: str,
                      max_points: int = 1500) -> SequenceRun:
    """Run the sequence from the start primitive's setpoint; returns what happened.

    A run that cannot go on (a state that is no longer finite, a numerical failure) stops there
    and is unsafe, with the reason in `failed`; it never raises.
    """
    run = SequenceRun(mode)
    try:
        _simulate(run, prims, graph, table, seq, settings, mode, max_points)
    except (ArithmeticError, ValueError, RuntimeError, KeyError, IndexError) as err:
        run.safe = False
        run.failed = run.failed or f"the simulation stopped: {type(err).__name__}: {str(err)[:200]}"
    return run


def _simulate(run: SequenceRun, prims: dict[str, CompiledPrimitive], graph: MotionPrimitiveGraph | None,
              table: dict | None, seq: Sequence, settings: OracleSettings, mode: str, max_points: int) -> None:
    dt, tol = settings.dt, settings.h_tolerance
    cur = seq.start
    clock = _start_clock(prims[cur])
    x = prims[cur].x_star(clock)
    z = initial_state(prims[cur], x, clock)
    converged = False
    goal, cmd_i = cur, 0
    nsteps = int(round(seq.duration / dt))
    stride = max(1, nsteps // max_points)
    k = 0
    run.switches.append({"t": 0.0, "to": cur, "clock": clock, "reason": "start"})
    run.final_primitive = cur
    if not np.isfinite(x).all():
        run.safe = False
        run.failed = f"the setpoint of {cur} is not finite at its start clock {clock:g}"
        return

    def switch(to: str, t_B: float | None, why: str, x_now: np.ndarray, t_now: float):
        nonlocal cur, z, converged
        t_B = _start_clock(prims[to]) if t_B is None else t_B
        run.switches.append({"t": t_now, "from": cur, "to": to, "clock": float(t_B), "reason": why})
        cur, converged = to, False
        run.final_primitive = cur
        z = initial_state(prims[to], x_now, t_B)

    while k < nsteps:
        p = prims[cur]
        ch = build_chunk(p, dt, 64, settings.jit, settings.jit_flags, with_state=True, boundaries=False)
        zf, out = ch.run(z[:, None])
        r, nx = ch.rows, p.system.nx
        nh = r.nh
        H, M, X = out[r.h, 0], out[r.margin, 0], out[r.x, 0]
        event = None
        for i in range(ch.K):
            if k + i >= nsteps:
                event = (i, "end", None)
                break
            t_now = (k + i) * dt
            xi = X[:, i]
            clk = z[nx] + i * dt
            if not np.isfinite(xi).all():
                run.safe = False
                run.failed = f"non-finite state at t = {t_now:.3f} s in {cur}"
                event = (i, "end", None)
                break
            hv = H[:, i]
            if nh and ((hv < -tol) | ~np.isfinite(hv)).any():
                run.safe = False
                if len(run.violations) < 50:
                    j = int(np.argmin(np.where(np.isfinite(hv), hv, -np.inf)))
                    v = float(hv[j]) if np.isfinite(hv[j]) else None
                    run.violations.append({"t": t_now, "primitive": cur, "h": p.h_names[j], "value": v})
            if (k + i) % stride == 0:
                run.t.append(t_now)
                run.x.append([float(v) for v in xi])
                act = hv[hv < INACTIVE / 2]
                low = float(act.min()) if act.size else None
                run.min_h.append(low if low is not None and np.isfinite(low) else None)
                run.active.append(cur)
            if M[i] > 0:
                converged = True
            while cmd_i < len(seq.commands) and seq.commands[cmd_i].t <= t_now + 1e-12:
                goal = seq.commands[cmd_i].goal
                cmd_i += 1
                if mode == "naive" and goal != cur:
                    event = (i, "naive", goal)
            if event:
                break
            if p.cls is PrimitiveClass.TRANSIENT and clk >= p.domain[1] - 1e-9:
                tr = graph.edge(cur, p.next) if graph is not None else None
                t_B = tr.switch_clock(p.domain[1]) if tr is not None else None
                if mode == "graph" and t_B is None:  # the primitive ends regardless; nothing vouches for it
                    run.safe = False
                    run.failed = run.failed or f"unverified hand-over {cur} -> {p.next} at t = {t_now:.3f} s"
                event = (i, "transient_end", (p.next, t_B if mode == "graph" else None))
                break
            if mode == "graph" and goal != cur and converged and p.cls is not PrimitiveClass.TRANSIENT:
                nxt = table[cur].get(goal)
                tr = graph.edge(cur, nxt) if nxt and nxt != cur else None
                if tr is not None:
                    c = clk - p.period * np.floor(clk / p.period + 1e-9) if p.period else clk
                    if p.cls is PrimitiveClass.FIXED:
                        c = 0.0
                    j = int(np.argmin(np.abs(tr.t_A - c)))
                    if abs(tr.t_A[j] - c) <= dt / 2 + 1e-12 and tr.best_t_B[j] is not None:
                        event = (i, "graph", (nxt, tr.best_t_B[j]))
                        break
        if event is None:
            z = zf[:, 0]
            k += ch.K
            continue
        i, kind, arg = event
        t_now = (k + i) * dt
        k += i
        if kind == "end":
            break
        xi = X[:, i]
        if kind == "naive":
            switch(arg, None, "commanded", xi, t_now)
        elif kind == "transient_end":
            switch(arg[0], arg[1], "end of domain", xi, t_now)
        else:
            switch(arg[0], arg[1], f"towards {goal}", xi, t_now)
    run.final_primitive = cur
