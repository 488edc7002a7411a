"""Simulate a timed sequence of goal primitives in two modes.

naive: switch to each goal at once, with the goal's clock at its start.
graph: follow the lookup table; leave a primitive only after its flow entered its E, and only at
a grid time t_A where the oracle verified the transition, switching in at the verified t_B.
Transients hand over to their `next` at the end of their domain in both modes. Safety (every h of
the active primitive) is monitored throughout. For floating-base rigid bodies each run also records
its CoM height and trunk roll / pitch / yaw per sample and the robot's stick figure at the start,
each switch, the first violation and the end (Fig. 6 of the paper).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..compile.contacts import grid_clock
from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..graph.transition import MotionPrimitiveGraph
from ..oracle.integrator import build_chunk, initial_state
from ..settings import OracleSettings
from ..spec.models import PrimitiveClass, Sequence


@dataclass
class SequenceRun:
    """Result of one mode: switches made, safety violations and a decimated trajectory.

    body: com_z (m) and roll, pitch, yaw (rad, Z-Y-X Euler angles of the base, yaw unwrapped) at the
    samples of t; poses: stick figures in world coordinates (see body_points), each with its time,
    primitive and event (POSE_EVENTS). Both are empty for systems without a floating base.
    violations holds the most violated function at the first MAX_RECORDED violating samples (and the
    first of each function, and the first after each switch); violation_totals counts every violating
    sample: per primitive and safety function, the first and last time, the number of samples and
    the least value.
    """

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
    body: dict[str, list[float]] = field(default_factory=dict)
    poses: list[dict] = field(default_factory=list)
    violation_totals: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


POSE_EVENTS = ("start", "switch", "first_violation", "end")
MAX_RECORDED = 50
"""Violating samples whose most violated function a run records (beyond the first after each switch
and each function's first violation)."""
TRUNK_HEIGHT = 0.3
"""Half-height of the drawn trunk as a fraction of its half-length (hip to hip)."""


def body_points(system, box: bool = False) -> tuple[ca.Function, list[int]] | None:
    """x -> (CoM, trunk outline, leg points) of a floating-base rigid body, and the number of points
    of each leg; None for other systems.

    The trunk outline is the rectangle in the base's x-z plane spanning the legs' first joints (four
    corners, world frame), or with `box` the box spanning them in x and y (eight corners: the four
    of the rectangle at the least y, then at the largest); each leg is the world position of every
    joint from the base down to its contact frame, then the contact frame (for the A1: hip, thigh,
    knee, foot).
    """
    if not system.is_rigid_body or "base_qw" not in system.state_names:
        return None
    model = system.model
    tree = system.dyn.state(system.x[:model.nq])
    legs, first, side = [], [], []
    for f in model.contact_frames:
        chain = [j for j in reversed(tree.support(model.frame(f).joint)) if model.joints[j].kind != "free"]
        legs.append([tree.world[j].p for j in chain] + [tree.frame_position(f)])
        if chain and model.joints[chain[0]].parent == 0:
            first.append(float(model.joints[chain[0]].translation[0]))
            side.append(float(model.joints[chain[0]].translation[1]))
    lo, hi = (min(first), max(first)) if first else (-0.1, 0.1)
    dz = TRUNK_HEIGHT * max(hi - lo, 1e-3) / 2
    base = tree.world[0]
    corners = np.array([[lo, hi, hi, lo], [0.0] * 4, [-dz, -dz, dz, dz]])
    if box:
        dy = max(max(side, default=0.0) - min(side, default=0.0), 2 * dz) / 2
        corners = np.hstack([corners + [[0], [-dy], [0]], corners + [[0], [dy], [0]]])
    trunk = ca.repmat(base.p, 1, corners.shape[1]) + ca.mtimes(base.R, ca.DM(corners))
    com = ca.vertcat(*[system.extra_env[f"com_{a}"] for a in "xyz"])
    pts = ca.horzcat(*[p for leg in legs for p in leg]) if legs else ca.SX.zeros(3, 0)
    return ca.Function("body_points", [system.x], [com, trunk, pts]), [len(leg) for leg in legs]


PLAYBACK_FPS = 25.0
"""Frames per second of the 3D playback's trajectories."""


def playback_samples(t, fps: float = PLAYBACK_FPS) -> np.ndarray:
    """Indices of the samples nearest to every 1/fps s of the sorted times t (each once): the frames
    of a 3D playback, whatever the run's own sampling."""
    t = np.asarray(t, float)
    if not len(t):
        return np.zeros(0, int)
    grid = np.arange(t[0], t[-1] + 0.5 / fps, 1.0 / fps)
    k = np.clip(np.searchsorted(t, grid), 1, len(t) - 1) if len(t) > 1 else np.zeros(len(grid), int)
    if len(t) > 1:
        k = np.where(np.abs(t[k - 1] - grid) <= np.abs(t[k] - grid), k - 1, k)
    return np.unique(np.concatenate([k, [len(t) - 1]]))


def euler_zyx(quat: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad) of quaternions given as rows (x, y, z, w), pinocchio's order."""
    q = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def _record_body(run: SequenceRun, system, snaps: list[tuple]) -> None:
    """Fill run.body from the stored samples and run.poses from the snapshots (t, primitive, event, x)."""
    got = body_points(system)
    if got is None or not run.x:
        return
    fun, sizes = got
    X = np.asarray(run.x, float)
    qi = [system.state_names.index(f"base_q{a}") for a in "xyzw"]
    rpy = euler_zyx(X[:, qi])
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    com = np.asarray(fun.map(len(X))(X.T)[0], float)
    run.body = {"com_z": com[2].tolist(), "roll": rpy[:, 0].tolist(), "pitch": rpy[:, 1].tolist(),
                "yaw": rpy[:, 2].tolist()}
    ends = np.cumsum([0] + sizes)
    for t, prim, event, x in snaps:
        c, trunk, pts = (np.asarray(v, float) for v in fun(x))
        run.poses.append({"t": float(t), "primitive": prim, "event": event, "com": c[:, 0].tolist(),
                          "trunk": trunk.T.tolist(), "legs": [pts[:, a:b].T.tolist() for a, b in zip(ends, ends[1:])]})


def simulate_sequence(prims: dict[str, CompiledPrimitive], graph: MotionPrimitiveGraph | None,
                      table: dict | None, seq: Sequence, settings: OracleSettings, mode: str,
                      max_points: int = 1500) -> SequenceRun:
    """Run the sequence from the start primitive's setpoint, in steps of seq.dt (else the
    oracle's); returns what happened.

    A run that cannot go on (a state that is no longer finite, a numerical failure) stops there
    and is unsafe, with the reason in `failed`; it never raises.
    """
    if seq.dt is not None:  # the sequence's own step
        settings = settings.replace(dt=float(seq.dt))
    run = SequenceRun(mode)
    snaps: list[tuple] = []
    try:
        _simulate(run, prims, graph, table, seq, settings, mode, max_points, snaps)
    except (ArithmeticError, ValueError, RuntimeError, KeyError, IndexError) as err:
        run.safe = False
        run.failed = run.failed or f"the simulation stopped: {type(err).__name__}: {str(err)[:200]}"
    if run.t and (not snaps or snaps[-1][2] != "end"):  # stopped early: the last stored sample
        snaps.append((run.t[-1], run.active[-1], "end", np.asarray(run.x[-1], float)))
    _record_body(run, prims[seq.start].system, snaps)
    return run


def _simulate(run: SequenceRun, prims: dict[str, CompiledPrimitive], graph: MotionPrimitiveGraph | None,
              table: dict | None, seq: Sequence, settings: OracleSettings, mode: str, max_points: int,
              snaps: list[tuple]) -> None:
    sim = _Simulation(run, prims, graph, table, seq, settings, mode, max_points, snaps)
    if not sim.start():
        return
    while sim.k < sim.nsteps:
        if not sim.advance():
            break
    run.final_primitive = sim.cur
    run.violation_totals = [{"primitive": p, "h": h, **v} for (p, h), v in sim.totals.items()]


class _Simulation:
    """The state of one run between chunks: the active primitive, the augmented state z, the goal,
    the next command and the step count k."""

    def __init__(self, run: SequenceRun, prims: dict[str, CompiledPrimitive], graph: MotionPrimitiveGraph | None,
                 table: dict | None, seq: Sequence, settings: OracleSettings, mode: str, max_points: int,
                 snaps: list[tuple]):
        self.run, self.prims, self.graph, self.table, self.seq = run, prims, graph, table, seq
        self.settings, self.mode, self.snaps = settings, mode, snaps
        self.dt, self.tol = settings.dt, settings.h_tolerance
        self.cur = seq.start
        self.converged = False
        self.goal, self.cmd_i = self.cur, 0
        self.nsteps = int(round(seq.duration / self.dt))
        # time is the switch-in time plus the time since switch-in the steps report (s), not steps x dt: a
        # step that ends on a switching time or a window's edge is shorter than dt, and the clock the law
        # and a replay of the run read advances by the steps' own lengths
        self.t_sw, self.c_sw = 0.0, 0.0
        self.stride = max(1, self.nsteps // max_points)
        self.k = 0
        self.seen = False  # a violation recorded since the last switch
        self.firsts: set[tuple[str, int]] = set()  # (primitive, h index) whose first violation is recorded
        self.recorded = 0  # violating samples recorded
        self.totals: dict[tuple[str, str], dict] = {}  # (primitive, h) -> every violating sample, counted
        self.z = None
        from .crosscheck.executor import ExecutorPlan  # (crosscheck imports this module)

        # the switch-in clocks the sequence's rule takes, shared with the executor on a simulator's state
        self.plan = ExecutorPlan.of(graph, table, seq, prims) if mode == "graph" and graph is not None else None

    def start(self) -> bool:
        """Switch the start primitive in at its start clock from its setpoint; False if that is not finite."""
        run, cur = self.run, self.cur
        clock = self.prims[cur].start_clock()
        x = self.prims[cur].x_star(clock)
        self.z = initial_state(self.prims[cur], x, clock)
        run.switches.append({"t": 0.0, "to": cur, "clock": clock, "reason": "start"})
        self.c_sw = clock
        run.final_primitive = cur
        if not np.isfinite(x).all():
            run.safe = False
            run.failed = f"the setpoint of {cur} is not finite at its start clock {clock:g}"
            return False
        self.snaps.append((0.0, cur, "start", np.array(x, float)))
        return True

    def switch(self, to: str, t_B: float | None, why: str, x_now: np.ndarray, t_now: float) -> None:
        self.seen = False
        t_B = self.prims[to].start_clock() if t_B is None else t_B
        self.run.switches.append({"t": t_now, "from": self.cur, "to": to, "clock": float(t_B), "reason": why})
        self.snaps.append((t_now, to, "switch", np.array(x_now, float)))
        self.cur, self.converged = to, False
        self.run.final_primitive = self.cur
        self.z = initial_state(self.prims[to], x_now, t_B)
        self.t_sw, self.c_sw = t_now, float(t_B)

    def advance(self) -> bool:
        """Run one chunk of the active primitive and act on its first event; False when the run ends."""
        p, settings, run = self.prims[self.cur], self.settings, self.run
        ch = build_chunk(p, self.dt, 64, settings.jit, settings.jit_flags, with_state=True, boundaries=False)
        try:
            zf, out = ch.run(self.z[:, None])
        except RuntimeError as err:  # the run cannot go on; what it did so far is kept
            run.safe = False
            run.failed = f"{self.cur} at t = {self.t_sw + self.z[p.system.nx + 1]:.3f} s: {err}"
            return False
        r = ch.rows
        H, M, X, S = out[r.h, 0], out[r.margin, 0], out[r.x, 0], out[r.s, 0]
        event = self._scan(p, ch.K, r.nh, H, M, X, S)
        if event is None:
            self.z = zf[:, 0]
            self.k += ch.K
            return True
        return self._act(event, X, S)

    def _scan(self, p: CompiledPrimitive, K: int, nh: int, H, M, X, S):
        """The chunk's first event (step, kind, argument), monitoring and storing each sample before it
        (S: each sample's time since switch-in)."""
        for i in range(K):
            t_now, clk = self.t_sw + S[i], self.c_sw + S[i]
            if t_now >= (self.nsteps - 0.5) * self.dt:
                return (i, "end", None)
            xi = X[:, i]
            if not np.isfinite(xi).all():
                self.run.safe = False
                self.run.failed = f"non-finite state at t = {t_now:.3f} s in {self.cur}"
                return (i, "end", None)
            hv = H[:, i]
            self._monitor(p, nh, hv, xi, t_now)
            if (self.k + i) % self.stride == 0:
                self._store(hv, xi, t_now)
            if M[i] > 0:
                self.converged = True
            event = self._commands(i, t_now)
            if event:
                return event
            if p.cls is PrimitiveClass.TRANSIENT and clk >= p.domain[1] - 1e-9:
                return self._hand_over(p, i, t_now)
            if self.mode == "graph" and self.goal != self.cur and self.converged \
                    and p.cls is not PrimitiveClass.TRANSIENT:
                event = self._graph_switch(p, i, clk, float(M[i]))
                if event:
                    return event
        return None

    def _monitor(self, p: CompiledPrimitive, nh: int, hv, xi, t_now: float) -> None:
        """Record violated safety functions: the most violated one at each of the first MAX_RECORDED
        violating samples and at the first after every switch, and every function's first violation
        in each primitive (so that one function violated for long hides no other); the first of the
        run also as a pose."""
        run = self.run
        bad = ((hv < -self.tol) | ~np.isfinite(hv)) if nh else None
        if bad is not None and bad.any():
            run.safe = False
            if not run.violations:
                self.snaps.append((t_now, self.cur, "first_violation", np.array(xi, float)))
            worst = int(np.argmin(np.where(np.isfinite(hv), hv, -np.inf)))
            first = [int(j) for j in np.flatnonzero(bad) if (self.cur, int(j)) not in self.firsts]
            keep = self.recorded < MAX_RECORDED or not self.seen or worst in first
            rows = ([worst] if keep else []) + [j for j in first if j != worst]
            self.seen, self.recorded = True, self.recorded + keep
            for j in np.flatnonzero(bad):
                v = float(hv[j]) if np.isfinite(hv[j]) else None
                tot = self.totals.setdefault((self.cur, p.h_names[j]), {"first": t_now, "last": t_now, "samples": 0,
                                                                        "least": v})
                tot["last"], tot["samples"] = t_now, tot["samples"] + 1
                if v is None or tot["least"] is not None and v < tot["least"]:
                    tot["least"] = None if v is None else v
            for j in rows:
                self.firsts.add((self.cur, j))
                v = float(hv[j]) if np.isfinite(hv[j]) else None
                run.violations.append({"t": t_now, "primitive": self.cur, "h": p.h_names[j], "value": v})

    def _store(self, hv, xi, t_now: float) -> None:
        run = self.run
        run.t.append(t_now)
        run.x.append([float(v) for v in xi])
        act = hv[hv < INACTIVE / 2]
        low = float(act.min()) if act.size else None
        run.min_h.append(low if low is not None and np.isfinite(low) else None)
        run.active.append(self.cur)

    def _commands(self, i: int, t_now: float):
        """Take the commands due by t_now; in naive mode, a new goal is switched to at once."""
        event = None
        seq = self.seq
        while self.cmd_i < len(seq.commands) and seq.commands[self.cmd_i].t <= t_now + 1e-12:
            self.goal = seq.commands[self.cmd_i].goal
            self.cmd_i += 1
            if self.mode == "naive" and self.goal != self.cur:
                event = (i, "naive", self.goal)
        return event

    def _hand_over(self, p: CompiledPrimitive, i: int, t_now: float):
        """A transient at the end of its domain hands over to `next` (in graph mode, at the verified t_B)."""
        graph, run = self.graph, self.run
        tr = graph.edge(self.cur, p.next) if graph is not None else None
        t_B = tr.switch_clock(p.domain[1]) if tr is not None else None
        if self.mode == "graph" and t_B is None:  # the primitive ends regardless; nothing vouches for it
            run.safe = False
            run.failed = run.failed or f"unverified hand-over {self.cur} -> {p.next} at t = {t_now:.3f} s"
        return (i, "transient_end", (p.next, t_B if self.mode == "graph" else None))

    def _graph_switch(self, p: CompiledPrimitive, i: int, clk: float, margin: float):
        """Towards the goal by the lookup table, at a grid time t_A the oracle verified (within dt / 2)
        that the sequence's switching rule takes (ExecutorPlan.switch_clock), from within the share of
        E_A the switch was checked from (ExecutorPlan.admits; margin: the state's RoA margin)."""
        nxt = self.table[self.cur].get(self.goal)
        if not nxt or nxt == self.cur:
            return None
        c = 0.0 if p.cls is PrimitiveClass.FIXED else grid_clock(clk, p.period)
        t_B = self.plan.switch_clock(self.cur, nxt, c, self.dt / 2)
        if t_B is None or not self.plan.admits(self.cur, nxt, c, self.dt / 2, margin, p.radius_at(clk)):
            return None
        return (i, "graph", (nxt, t_B))

    def _act(self, event, X, S) -> bool:
        """Switch (or end) at the event's step; False when the run ends."""
        i, kind, arg = event
        t_now = self.t_sw + S[i]
        self.k += i
        xi = X[:, i]
        if kind == "end":
            if np.isfinite(xi).all():
                self.snaps.append((t_now, self.cur, "end", np.array(xi, float)))
            return False
        if kind == "naive":
            self.switch(arg, None, "commanded", xi, t_now)
        elif kind == "transient_end":
            self.switch(arg[0], arg[1], "end of domain", xi, t_now)
        else:
            self.switch(arg[0], arg[1], f"towards {self.goal}", xi, t_now)
        return True
