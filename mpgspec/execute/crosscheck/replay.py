"""Replay a run's switches in MuJoCo under the primitives' compiled control laws.

The run's switches (time, primitive, clock of the new primitive) are taken as they are; the law
(x, t, s, x_sw) -> u of the active primitive (CompiledPrimitive.loop, which also gives h) is
evaluated at the control rate from MuJoCo's state and the input held until the next update. A
sampled law (the ID-QP) runs as the oracle runs it: solved at its own rate from the previous
solve's warm start (cold at switch-in), compiled, and held in between; a solve that does not
converge is counted (`law_failures`) and its last iterate applied, as CasADi's virtual machine
returns it. At a switch the primitive's clock starts at the switch's clock, s at 0 and x_sw is
MuJoCo's state.
Before t = 0 the start primitive's law holds the start state x*(t0) for `settle` seconds with its
clock frozen, so that the soft contacts carry the weight when the run begins.
With sensing errors (settings `latency`, `velocity_noise`) the law, the switch state x_sw and the
executor read the state as sensed, while h is judged on the simulator's own state under the input
the law asked from the sensed one (looplib.open_law: the ground forces of the input applied).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...compile.contacts import Events
from ...compile.events import NEVER, happened
from ...compile.primitive import INACTIVE, CompiledPrimitive
from ...oracle import looplib
from ...spec.models import PrimitiveClass
from .mjcf import MujocoRobot
from .settings import CrossCheckSettings


@dataclass
class Replay:
    """What happened in MuJoCo: states, CoM and the least h at every control update; violations of
    the active primitive's h (h < -tol); what the contacts did."""

    t: np.ndarray
    x: np.ndarray  # (samples, nx) in mpgspec's layout
    com: np.ndarray  # (samples, 3), MuJoCo's own centre of mass
    least_h: np.ndarray  # least active h at each sample
    active: list[str]
    switches: list[dict] = field(default_factory=list)  # as replayed, with the E margin of the primitive left
    safe: bool = True
    first_violation: dict | None = None
    violation_samples: int = 0
    worst: dict = field(default_factory=dict)  # primitive -> (least value of each h, when)
    contact: dict = field(default_factory=dict)
    start_offset: float = 0.0
    failed: str = ""
    wall_s: float = 0.0
    law_failures: dict = field(default_factory=dict)  # primitive -> solves of a sampled law that did not converge


def held_feet(p: CompiledPrimitive, clock: float) -> tuple[str, ...] | None:
    """Feet the primitive's dynamics hold at this clock (a contact schedule, else its contact set);
    None when contact events decide (a transient primitive of a system with contact events, whose
    feet leave or reach the ground by design)."""
    if isinstance(p.contacts, Events):
        return None if p.cls is PrimitiveClass.TRANSIENT else p.contacts.feet
    return p.contacts.held(clock)


class _Events:
    """The contact flags and event clocks of a system with contact events, kept from MuJoCo's contacts
    as mpgspec keeps them (mpgspec.compile.events): a clock is set to 0 when its event first happens
    after switch-in and advances at rate 1 (at rest at NEVER)."""

    def __init__(self, x0: np.ndarray, n0: int, n_feet: int):
        self.flags = np.asarray(x0[n0:n0 + n_feet], float) > 0.5
        self.tau = np.array(x0[n0 + n_feet:], float)  # first_touchdown, takeoff (ContactEvent's order)

    def extra(self) -> np.ndarray:
        return np.concatenate([self.flags.astype(float), self.tau])

    def advance(self, touching: np.ndarray, s: float, dt: float) -> None:
        """After a control period ending s after switch-in, with the feet touching as given."""
        self.tau = np.where(self.tau < NEVER, self.tau + dt, self.tau)
        on, was = touching.tolist(), self.flags.tolist()
        now = [any(a and not b for a, b in zip(on, was)), any(was) and not any(on)]
        for k, e in enumerate(now[: len(self.tau)]):
            if e and not bool(happened(self.tau[k], s)):
                self.tau[k] = 0.0
        self.flags = touching.copy()


class _Sim:
    """MuJoCo's model and data with the reads a replay needs."""

    def __init__(self, robot: MujocoRobot):
        import mujoco

        self.mj, self.robot = mujoco, robot
        self.m, self.d = robot.model, mujoco.MjData(robot.model)
        self.root = 1 if robot.model.nbody > 1 else 0  # the robot's root link: its subtree is the robot
        self._vel = np.zeros(6)
        self.events: _Events | None = None
        self._foot_of = {int(g): k for k, g in enumerate(robot.foot_geoms)}
        self._trunk = {int(g) for g in robot.trunk_geoms}
        self._now: list | None = None  # the geom pairs in contact at the current state, once read

    def set(self, x: np.ndarray) -> None:
        self.d.qpos[:], self.d.qvel[:] = self.robot.state.to_mujoco(x)
        self.mj.mj_forward(self.m, self.d)
        self._now = None

    def touching(self) -> np.ndarray:
        """Whether each foot sphere touches the floor."""
        on = np.zeros(len(self.robot.feet), bool)
        floor, foot_of = self.robot.floor, self._foot_of
        for a, b in self._pairs():
            k = foot_of.get(b if a == floor else a if b == floor else -1)
            if k is not None:
                on[k] = True
        return on

    def trunk_touching(self) -> bool:
        return any(a in self._trunk or b in self._trunk for a, b in self._pairs())

    def _pairs(self) -> list:
        """The geom pairs in contact now (a few: read as a list, not as arrays), read once per state."""
        if self._now is None:
            n = self.d.ncon
            self._now = self.d.contact.geom[:n].tolist() if n else []
        return self._now

    def state(self) -> np.ndarray:
        extra = self.events.extra() if self.events is not None else None
        return self.robot.state.from_mujoco(self.d.qpos, self.d.qvel, extra)

    def slip(self, k: int, radius: float) -> float:
        """Horizontal speed of the lowest point of foot k's sphere (zero when it rolls or pivots)."""
        self.mj.mj_objectVelocity(self.m, self.d, self.mj.mjtObj.mjOBJ_SITE, int(self.robot.foot_sites[k]),
                                  self._vel, 0)
        w, v = self._vel[:3], self._vel[3:]
        return float(np.hypot(v[0] - radius * w[1], v[1] + radius * w[0]))  # v + w x (0, 0, -r)

    def step(self, u: np.ndarray, n: int) -> bool:
        """n steps with the input u held; False when MuJoCo diverged (it then resets the state)."""
        bad = self.d.warning[self.mj.mjtWarning.mjWARN_BADQACC]
        before = bad.number
        self.d.ctrl[self.robot.actuators] = u
        if n > 0:  # the n steps in MuJoCo's own loop: the same steps as one call each, less Python
            self.mj.mj_step(self.m, self.d, nstep=n)
        self.mj.mj_forward(self.m, self.d)
        self._now = None
        return bad.number == before


def replay(robot: MujocoRobot, prims: dict[str, CompiledPrimitive], switches: list[dict], duration: float,
           settings: CrossCheckSettings, tol: float = 0.0, decide=None) -> Replay:
    """Run `switches` (from a SequenceRun: t, to, clock; the first is the start) for `duration` s.
    With `decide` ((t, x, clock) -> {t, to, clock} or None, e.g. executor.StateExecutor.decide),
    only the first switch is taken from `switches`: the others are decided from the simulator's
    state at each control update."""
    t_wall = time.perf_counter()
    sim, rate, n_sub = _Sim(robot), settings.control_rate, settings.substeps
    first = switches[0]
    p, clock0 = prims[first["to"]], float(first["clock"])
    x0 = p.x_star(clock0)
    sim.set(x0)
    sm = robot.state
    if sm.nx > sm.nq + sm.nv:
        sim.events = _Events(x0, sm.nq + sm.nv, len(robot.feet))
    out_failures: dict = {}
    law = _Law(p, rate, out_failures)
    settled = all(sim.step(law(sim.state(), clock0, 0.0, x0)[1], n_sub)
                  for _ in range(int(round(settings.settle * rate))))
    x = sim.state()
    offset = float(np.linalg.norm((x - x0)[: robot.state.nq]))
    n = int(np.floor(duration * rate + 1e-9)) + 1
    T, X, C, L = np.arange(n) / rate, np.full((n, len(x)), np.nan), np.full((n, 3), np.nan), np.full(n, np.nan)
    out = Replay(T, X, C, L, [], start_offset=offset, law_failures=out_failures)
    if not settled:
        out.safe, out.failed, n = False, f"the simulator diverged while {p.name} held the start state", 0
    out.switches.append({"t": 0.0, "from": None, "to": p.name, "clock": clock0, "roa_margin": None})
    contact = {"max_penetration": 0.0, "max_slip_speed": 0.0, "slip_at": None, "lift_off": None,
               "trunk_contact": None}
    sense = _Sensing(settings, robot.state)
    queue, sw = ([] if decide is not None else list(switches[1:])), (p, clock0, 0.0, sense(x))
    law = _Law(p, rate, out_failures)  # the run starts from the settled state: a fresh solve
    for k in range(n):
        t = T[k]
        x = sim.state()
        seen = sense(x) if k else sw[3]
        if decide is not None and np.isfinite(seen).all():
            made = decide(float(t), seen, sw[1] + (t - sw[2]))
            if made is not None:
                queue.append(made)
        while queue and queue[0]["t"] <= t + 0.5 / rate:
            s = queue.pop(0)
            left, c_left = sw[0], sw[1] + (t - sw[2])
            margin = float(np.asarray(left.roa_margin(x, c_left), float).ravel()[0])
            out.switches.append({"t": float(t), "from": left.name, "to": s["to"], "clock": float(s["clock"]),
                                 "roa_margin": margin if np.isfinite(margin) else None})
            sw = (prims[s["to"]], float(s["clock"]), t, seen.copy())
            law = _Law(sw[0], rate, out_failures)
        p, c0, t_sw, x_sw = sw
        clock = c0 + (t - t_sw)
        if not np.isfinite(x).all():
            out.safe, out.failed = False, f"non-finite state at t = {t:.3f} s in {p.name}"
            break
        hv, u = law(x, clock, t - t_sw, x_sw, seen if sense.on else None)
        X[k], C[k] = x, sim.d.subtree_com[sim.root]
        out.active.append(p.name)
        act = hv < INACTIVE / 2
        L[k] = float(hv[act].min()) if act.any() else np.nan
        _judge(out, p, hv, act, t, tol)
        _contacts(sim, contact, p, clock, t, settings.foot_radius)
        if not sim.step(u, n_sub):
            out.safe, out.failed = False, f"the simulator diverged after t = {t:.3f} s in {p.name}"
            break
        if sim.events is not None:
            sim.events.advance(sim.touching(), t + 1.0 / rate - t_sw, 1.0 / rate)
    out.contact = contact
    out.wall_s = time.perf_counter() - t_wall
    return out


SENSING_SEED = 0
"""Seed of the velocity-noise draws: a replay under noise is the same every time."""


class _Sensing:
    """The state the law sees: the simulator's `delay` control updates ago, its base's linear velocity
    off by a uniform draw of up to `velocity_noise` per axis (the simulator's state itself when
    neither is set)."""

    def __init__(self, settings: CrossCheckSettings, sm):
        self.on, self.delay, self.noise = settings.sensed, settings.delay, settings.velocity_noise
        self.rng = np.random.default_rng(SENSING_SEED)
        self.past: list[np.ndarray] = []
        self.v_base = slice(sm.nq, sm.nq + 3) if sm.floating else slice(0, 0)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if not self.on:
            return x
        self.past = (self.past + [x.copy()])[-(self.delay + 1):]
        seen = self.past[0].copy()
        if self.noise > 0:
            seen[self.v_base] += self.rng.uniform(-self.noise, self.noise, seen[self.v_base].size)
        return seen


class _Law:
    """The active primitive's law from its switch-in: a sampled law solved every `every` control
    updates from the previous solve's warm start and held in between (through its loop library, as
    the oracle's chunks run it); any other law evaluated at every update (_evaluate)."""

    def __init__(self, p: CompiledPrimitive, rate: float, failures: dict):
        self.p, self.failures = p, failures
        self.held = looplib.held_law(p)
        self.open = looplib.open_law(p) if self.held is None else None
        if self.held is not None:
            period = p.sampled.period
            self.every = max(1, int(round(period * rate))) if period else 1
            self.w, self.u, self.k = np.zeros(p.sampled.nw), None, 0

    def __call__(self, x, clock: float, s: float, x_sw, seen=None) -> tuple[np.ndarray, np.ndarray]:
        """(h at x, u): with `seen`, the law reads that state instead of x, and h is the loop's at x
        under the input the law asks at `seen` (the input-dependent h, such as the friction cone, read
        the input the plant receives), whether the law is sampled or not."""
        if self.held is None:
            if seen is None:
                return _evaluate(self.p, x, clock, s, x_sw)
            u = _evaluate(self.p, seen, clock, s, x_sw)[1]
            if self.open is None:  # a primitive built without its open loop: h of the law's own input at x
                return _evaluate(self.p, x, clock, s, x_sw)[0], u
            hv, u_applied = self.open(x, clock, s, x_sw, u)
            return np.asarray(hv, float).ravel(), np.asarray(u_applied, float).ravel()
        solve, open_loop = self.held
        if self.k % self.every == 0:
            at = x if seen is None else seen
            try:
                self.u, self.w = solve(at, clock, s, x_sw, self.w)
            except RuntimeError:  # the compiled solver reports no convergence: its last iterate, from the VM
                u, w = self.p.sampled.solve(at, clock, s, x_sw, self.w)
                self.u, self.w = np.asarray(u, float).ravel(), np.asarray(w, float).ravel()
                self.failures[self.p.name] = self.failures.get(self.p.name, 0) + 1
        self.k += 1
        hv, u = open_loop(x, clock, s, x_sw, self.u)
        return np.asarray(hv, float).ravel(), np.asarray(u, float).ravel()


def _evaluate(p: CompiledPrimitive, x, clock: float, s: float, x_sw) -> tuple[np.ndarray, np.ndarray]:
    """(h, u): the safety functions and the saturated input of the primitive's compiled loop (through
    its loop library when one is attached: compiled code, not CasADi's virtual machine)."""
    law = looplib.law(p)
    if law is not None:
        hv, u = law(x, clock, s, x_sw)
    elif p.loop is not None:
        _xdot, hv, _u_raw, u = p.loop(x, clock, s, x_sw)
    else:
        hv, u = p.h(x, clock, s, x_sw), p.control(x, clock, s, x_sw)[1]
    return np.asarray(hv, float).ravel(), np.asarray(u, float).ravel()


def _judge(out: Replay, p: CompiledPrimitive, hv: np.ndarray, act: np.ndarray, t: float, tol: float) -> None:
    got = out.worst.get(p.name)
    if got is None:  # built once per primitive, not at every update
        got = out.worst[p.name] = (np.full(len(hv), np.inf), np.zeros(len(hv)))
    least, when = got
    finite = bool(np.isfinite(hv).all())
    v = np.where(act, hv if finite else np.nan_to_num(hv, nan=-np.inf), np.inf)
    lower = v < least
    if lower.any():
        least[lower], when[lower] = v[lower], t
    bad = act & ~(hv >= -tol)  # NaN counts as violated
    if bad.any():
        out.safe = False
        out.violation_samples += 1
        if out.first_violation is None:
            j = int(np.argmin(np.where(bad, np.nan_to_num(hv, nan=-np.inf), np.inf)))
            out.first_violation = {"t": float(t), "primitive": p.name, "h": p.h_names[j],
                                   "value": float(hv[j]) if np.isfinite(hv[j]) else None}


def _contacts(sim: _Sim, c: dict, p: CompiledPrimitive, clock: float, t: float, radius: float) -> None:
    """Penetration of the feet, slip of the held feet, the first lift-off of a held foot, the trunk."""
    low = float(sim.d.site_xpos[sim.robot.foot_sites, 2].min())
    if -low > c["max_penetration"]:  # the deepest foot below the floor's top (0 when none is)
        c["max_penetration"] = -low
    held = held_feet(p, clock)
    if held is not None:
        on = sim.touching()
        for k, f in enumerate(sim.robot.feet):
            if f in held:
                if not on[k] and c["lift_off"] is None:
                    c["lift_off"] = {"t": float(t), "foot": f, "primitive": p.name}
                if on[k]:
                    v = sim.slip(k, radius)
                    if v > c["max_slip_speed"]:
                        c["max_slip_speed"], c["slip_at"] = v, {"t": float(t), "foot": f}
    if c["trunk_contact"] is None and sim.trunk_touching():
        c["trunk_contact"] = float(t)
