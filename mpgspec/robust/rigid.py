"""Robust rollouts of a rigid-body primitive: mass scale, friction and a push on the base.

The plant is the system's uncertain_plant (every link's mass and inertia times k, a world-frame
force F at a base frame) holding the feet the primitive's dynamics hold: a fixed set, the set its
contact schedule holds at the clock, or the flags of the state with contact events (lift-offs are
then decided on the perturbed plant too). The controller is the primitive's own, on the nominal
model, solved at its control rate and held in between when it is sampled (the ID-QP), as the
oracle runs it. Each step is the oracle's (RK4 with the last stage just before the step's end, so
a law or contact mode switching there is not yet on, then the jump); a step's sample is the lesser of h at its two ends, with every safety function
masked outside its window as the oracle masks it. The no-slip safety functions take the plant's
ground forces and the scenario's friction coefficient mu; every other safety function is the
compiled one. With velocity errors (velocity_error_x/y/z) the law reads the floating base's
linear velocity with the scenario's error added (in the state and in the switch state x_sw it
holds), while the plant and h run on the true ones; a law that is not sampled gives its
input-dependent h (torque requests) for the input it asks at the true state. With a latency the
plant receives each law's input that many steps after the state it read, held over each step.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import casadi as ca

from ..compile.primitive import INACTIVE, CompiledPrimitive, saturate
from ..compile.rigidbody.system import no_slip
from ..oracle import looplib
from ..oracle.flow import LEFT, active, jump_of, rk4, solve_or_keep, wrap
from ..oracle.jit import cse, cse_sx
from ..spec.uncertainty_refs import VELOCITY_ERRORS
from .library import (GRADIENT_FLAGS, STEP_FLAGS, RobotLibrary, library_jump, library_plant, library_schedule_jump, robot_library,
                      step_library)
from .rollout import RobustRollout


def plant_feet(prim: CompiledPrimitive) -> list[str]:
    """The feet whose ground forces the robust plant returns, in its order."""
    frames = prim.system.model.contact_frames
    return list(frames) if prim.contacts.varies else list(prim.contacts.feet)


def library_for(prim: CompiledPrimitive, settings, reverse: bool = False) -> RobotLibrary | None:
    """The robot's compiled library (`reverse`: its variant with reverse derivatives) when the
    primitive's plant is the masked one (a contact schedule or contact events) and loops are
    compiled; None: the dynamics are inlined."""
    if not uses_library(prim, settings):
        return None
    return robot_library(prim.system, reverse)


def uses_library(prim: CompiledPrimitive, settings) -> bool:
    """Whether the robust step calls the robot's library: compiled loops and a masked plant."""
    sys = prim.system
    return bool(settings.jit) and sys.is_rigid_body and (prim.contacts.by_clock or sys.events)


def robust_plant(prim: CompiledPrimitive, frame: str, lib: RobotLibrary | None = None) -> ca.Function:
    """(x, u, k, F, t) -> (xdot, lam, c) of the primitive's dynamics perturbed (uncertain_plant),
    the dynamics called from the robot's library when given."""
    if lib is not None:
        return library_plant(prim, lib, frame)
    return prim.system.uncertain_plant(prim.contacts, frame)


def robust_jump(prim: CompiledPrimitive, frame: str, lib: RobotLibrary | None = None) -> ca.Function:
    """(x, u, t, s, k, F) -> x after a step's discrete update; with contact events and no schedule,
    lift-offs are decided on the perturbed plant (touchdowns and impacts do not depend on k or F),
    by the robot's library when given."""
    sys = prim.system
    if lib is not None and sys.events and not prim.contacts.by_clock:
        return library_jump(prim, lib, frame)
    if lib is not None and prim.contacts.by_clock:
        return library_schedule_jump(prim, lib)
    x, u, t, s = sys.x, ca.SX.sym("u", sys.nu), ca.SX.sym("t"), ca.SX.sym("s")
    k, F = ca.SX.sym("k"), ca.SX.sym("F", 3)
    if sys.events and not prim.contacts.by_clock:
        xn = sys.project(x, u, s, k, sys.push_wrench(frame, x[:sys.model.nq], F))
    else:
        xn = jump_of(prim)(x, u, t, s)
    return ca.Function("robust_jump", [x, u, t, s, k, F], [xn])


def no_slip_rows(prim: CompiledPrimitive) -> dict[int, tuple[int, int]]:
    """h row -> (foot index in plant_feet, 0 normal force | 1 friction cone)."""
    feet = plant_feet(prim)
    rows = {}
    for j, name in enumerate(prim.h_names):
        for kind, prefix in enumerate(("normal_force[", "friction_cone[")):
            if name.startswith(prefix) and name.endswith("]") and name[len(prefix):-1] in feet:
                rows[j] = (feet.index(name[len(prefix):-1]), kind)
    return rows


class RigidRobustRollout(RobustRollout):
    """RobustRollout of a rigid-body target: theta holds the named parameters (mass_scale,
    friction, ...), d the push's world force (3 entries, or none); latency in whole steps."""

    GRAD_FLAGS = GRADIENT_FLAGS

    def __init__(self, prim: CompiledPrimitive, names: list[str], frame: str, push: bool, segments: int,
                 settings, horizon: float, duration: float | None = None, gradient: bool = True, latency: int = 0):
        self.names, self.push, self.frame, self.latency = list(names), push, frame, latency
        self.lib = library_for(prim, settings)
        self.libs = (self.lib.path,) if self.lib is not None else ()
        self.plant_fn = robust_plant(prim, frame, self.lib)
        super().__init__(prim, self.plant_fn, [], segments, settings, horizon, duration, gradient)

    def _loop(self, prim, plant_fn, dist_inputs, dt):
        parts, path = compiled_step(prim, plant_fn, self.names, self.frame, self.push, self.settings, self.lib,
                                    latency=self.latency)
        self.libs += (path,) if path is not None else ()
        return parts

    def _reverse_parts(self):
        """The step with its reverse derivative where the forward step is in a library: a twin of it
        compiled against the robot's reverse variant (only the targets whose search takes a
        gradient pay for either)."""
        if self.lib is None:
            return self._step, self._first
        lib = library_for(self.prim, self.settings, reverse=True)
        parts, path = compiled_step(self.prim, robust_plant(self.prim, self.frame, lib), self.names, self.frame,
                                    self.push, self.settings, lib, reverse=True, latency=self.latency)
        if lib is not None:
            self.libs += (lib.path,)
        if path is not None:
            self.libs += (path,)
        return parts[:2]


def compiled_step(prim: CompiledPrimitive, plant_fn: ca.Function, names: list[str], frame: str, push: bool, settings,
                  lib: RobotLibrary | None, reverse: bool = False, latency: int = 0) -> tuple[tuple, Path | None]:
    """(rigid_step's parts with step and first from shared_step, the step library's path or None):
    with the robot's library the step calls the primitive's loop library where it has one
    (loop_parts); if the step library fails, the step is built again with everything inlined.
    `reverse`: with the reverse derivatives a push gradient takes (a library of its own, built only
    when a search needs it; the rollouts and the sequence stepper share the forward one)."""
    reverse = reverse and push and prim.sampled is None
    called, paths = loop_parts(prim, lib, reverse)
    parts = rigid_step(prim, plant_fn, names, frame, push, settings.dt, lib, called, latency)
    step, first, path = shared_step(parts, lib, settings, reverse, paths)
    if path is None and called:
        parts = rigid_step(prim, plant_fn, names, frame, push, settings.dt, lib, latency=latency)
        step, first = parts[:2]
    return (step, first, *parts[2:]), path


def loop_parts(prim: CompiledPrimitive, lib: RobotLibrary | None,
               reverse: bool) -> tuple[dict[str, ca.Function], tuple[Path, ...]]:
    """(the compiled parts a robust step calls instead of inlining them, by kind; the libraries they
    are in), from the primitive's loop library: a sampled law's solve (the ID-QP: most of a step's
    code) and, when no gradient goes through it (`reverse` false: its unit has no reverse derivative),
    a large RoA margin; none without the robot's library (the step is then no library of its own) or
    a loop library. The control law stays inlined: measured (bench/bench_rstep.py), a unit of its own
    with its reverse derivative costs more gcc at -O1 than it saves, and at -O0 slows the gradient
    1.3x."""
    loops = looplib.attach(prim) if lib is not None else None
    if loops is None:
        return {}, ()
    called = {}
    if prim.sampled is not None and loops.get("solve") is not None:
        called["solve"] = loops.get("solve")
    if not reverse and loops.get("roa_margin") is not None:
        called["roa_margin"] = loops.get("roa_margin")
    return called, tuple(loops.paths) if called else ()


def shared_step(parts: tuple, lib: RobotLibrary | None, settings, reverse: bool = False,
                libs: tuple[Path, ...] = ()) -> tuple[ca.Function, ca.Function, Path | None]:
    """(step, first, library path) of rigid_step's parts: with the robot's library, compiled once per
    primitive into one library (with reverse derivatives when `reverse`: compiled_step sets it only
    where a push goes through a law that holds no input), linked against it and `libs` (the loop
    library's parts it calls), that its robust rollouts and its sequence stepper share; else as they
    are (path None)."""
    step, first = parts[:2]
    if lib is None:
        return step, first, None
    shared = step_library(step, first, reverse, GRADIENT_FLAGS if reverse else STEP_FLAGS, (lib.path, *libs))
    return shared if shared is not None else (step, first, None)


def robust_h(prim: CompiledPrimitive, rows: dict) -> tuple[ca.Function, list[int]]:
    """(the primitive's safety functions without the no-slip `rows` the perturbed plant replaces,
    the rows kept): the same expressions of the closed loop's inputs, without the nominal contact
    dynamics that only the replaced rows need (most of a rigid body's loop and of its derivative)."""
    loop = prim.loop_u if prim.sampled is not None else prim.loop_raw
    ins = loop.sx_in() if loop.is_a("SXFunction") else loop.mx_in()
    h = loop.call(ins)[1]
    kept = [j for j in range(h.shape[0]) if j not in rows]
    return ca.Function(f"h_{loop.name()}", ins, [h[kept]], loop.name_in(), ["h"]), kept


def rigid_step(prim: CompiledPrimitive, plant_fn: ca.Function, names: list[str], frame: str, push: bool, dt: float,
               lib: RobotLibrary | None = None, called: dict | None = None, latency: int = 0):
    """(step (z, d) -> (z next, [h; RoA margin]), first (x0, t0, s0, theta, d) -> ([h; margin], hold), nth,
    nd, hold size) of one oracle step on the perturbed plant, z = [x; t; s; x_sw; theta; hold]; lib:
    the robot's library the plant and the contact events are called from (inlined without); called:
    compiled parts (loop_parts: solve, roa_margin) called instead of the primitive's own.

    latency (whole steps): the plant receives, held over each step, the input the law asked at the
    start of the step `latency` steps earlier (a sampled law: the input it held then); the hold ends
    with those inputs, oldest first, and starts with the law's input at switch-in in every slot."""
    sys = prim.system
    nx, nu = sys.nx, sys.nu
    nth, nd = len(names), 3 if push else 0
    called = called or {}
    law = prim.sampled
    if law is not None and "solve" in called:
        law = replace(law, solve=called["solve"])
    margin = called.get("roa_margin", prim.roa_margin)
    nw = law.nw if law is not None else 0
    nlaw = 1 + nu + nw if law is not None else 0
    nhold = nlaw + latency * nu
    z, d = ca.MX.sym("z", 2 * nx + 2 + nth + nhold), ca.MX.sym("d", nd)
    x, t, s, xsw = z[:nx], z[nx], z[nx + 1], z[nx + 2:2 * nx + 2]
    th, hold = z[2 * nx + 2:2 * nx + 2 + nth], z[2 * nx + 2 + nth:]
    k = th[names.index("mass_scale")] if "mass_scale" in names else 1.0
    mu = th[names.index("friction")] if "friction" in names else sys.friction
    kt = th[names.index("torque_scale")] if "torque_scale" in names else None  # the torque delivered / commanded

    def delivered(u):
        return u if kt is None else kt * u

    def seen(xx):  # the state the law reads
        return sensed(sys, names, th, xx)
    F = d if nd else ca.DM.zeros(3)
    rows = no_slip_rows(prim)
    gated = prim.contacts.varies  # contact conditions bind while held
    # the SX pieces the step calls, each generated once, with common subexpressions eliminated
    plant_fn, jump = cse_sx(plant_fn), cse_sx(robust_jump(prim, frame, lib))
    h_fn, kept = robust_h(prim, rows)
    ctrl, loop = cse_sx(prim.control), cse_sx(h_fn)
    held = hold[1:1 + nu] if law is not None else None
    fifo = hold[nlaw:]  # the inputs asked and not yet applied, oldest first (latency)
    applied = fifo[:nu] if latency else None

    def control(xx, tt, ss, u_held):  # (u_raw, u) at a state; a sampled law holds its input
        if latency:  # the input asked `latency` steps ago, held over the step
            return applied, saturate(applied, sys.u_lo, sys.u_hi)
        if law is not None:
            return u_held, saturate(u_held, sys.u_lo, sys.u_hi)
        return ctrl(seen(xx), tt, ss, seen(xsw))

    def raw_h(xx, tt, ss, ur):  # the safety functions the plant does not replace, unwindowed
        return loop(xx, tt, ss, xsw, ur) if law is not None else loop(xx, tt, ss, xsw)

    def h_of(xx, tt, ss, ur, lam, c):
        h = raw_h(xx, tt, ss, ur)
        parts = []
        for j in range(len(prim.h_names)):
            if j not in rows:
                v = h[kept.index(j)]
            else:
                i, kind = rows[j]
                v = no_slip(lam[3 * i], lam[3 * i + 1], lam[3 * i + 2], mu)[kind]
                v = ca.if_else(c[i] > 0.5, v, 1e3) if gated else v
            parts.append(v)
        return ca.vertcat(*parts) if parts else ca.MX(0, 1)

    def f(xx, tt, ss):
        return plant_fn(xx, delivered(control(xx, tt, ss, held)[1]), k, F, tt)[0]

    ur0, u0 = control(x, t, s, held)
    k1, lam0, c0 = plant_fn(x, delivered(u0), k, F, t)
    te = dt - min(LEFT, dt / 2)  # the step's end seen from inside it, as switched_flow sees it
    x_end, _ = rk4(f, x, (t, s), dt, te, k1)
    ur1, u1 = control(x_end, t + te, s + te, held)
    _, lam1, c1 = plant_fn(x_end, delivered(u1), k, F, t + te)
    xn = jump(x_end, delivered(u0), t + dt, s + dt, k, F)
    act = active(prim, wrap(prim, t + dt / 2), x, s, xn, dt)
    hs = ca.fmin(h_of(x, t, s, ur0, lam0, c0), h_of(x_end, t + te, s + te, ur1, lam1, c1))
    if len(prim.h_names):
        hs = ca.if_else(act, hs, INACTIVE)
    hold_next = _hold_next(law, hold[:nlaw], seen(xn), t + dt, s + dt, seen(xsw), held, dt) if law is not None \
        else ca.MX(0, 1)
    if latency:  # this step's request joins the queue
        asked = held if law is not None else ctrl(seen(x), t, s, seen(xsw))[0]
        hold_next = ca.vertcat(hold_next, fifo[nu:], asked)
    out = ca.vertcat(hs, margin(xn, t + dt))
    step = cse(ca.Function("robust_rigid_step", [z, d], [ca.vertcat(xn, t + dt, s + dt, xsw, th, hold_next), out]))
    # the first sample: h at the step's start, windowed at that instant
    h_start = h_of(x, t, s, ur0, lam0, c0)
    if len(prim.h_names):
        h_start = ca.if_else(active(prim, wrap(prim, t), x, s, x, 0.0), h_start, INACTIVE)
    def queue(x0, t0, s0, th0, u_0):  # the latency queue at switch-in: the law's request then, in every slot
        if not latency:
            return ca.MX(0, 1)
        x_seen = sensed(sys, names, th0, x0)
        asked = u_0 if law is not None else ctrl(x_seen, t0, s0, x_seen)[0]
        return ca.repmat(asked, latency, 1)

    first = _first(law, sys.nx, margin, ca.Function("o", [z, d], [h_start]), nth, nd,
                   lambda x0, th0: sensed(sys, names, th0, x0), queue)
    return step, first, nth, nd, nhold


def sensed(sys, names: list[str], th, x):
    """x as the laws read it: the floating base's linear velocity (the state's first three velocity
    entries, in the base frame) plus the velocity errors among the parameters `names` (values th)."""
    axes = [names.index(n) if n in names else None for n in VELOCITY_ERRORS]
    if all(a is None for a in axes):
        return x
    nq = sys.model.pin_model.nq
    err = ca.vertcat(*[th[a] if a is not None else 0 for a in axes])
    return ca.vertcat(x[:nq], x[nq:nq + 3] + err, x[nq + 3:])


def _hold_next(law, hold, xn, t, s, xsw, held, dt: float):
    """The hold's entries after a step ending at clock t (s since switch-in) in state xn: the law is
    solved at the start of every m-th step, from the previous solve's warm start."""
    nu = held.shape[0]
    m, cnt, w = law.steps(dt), hold[0], hold[1 + nu:]
    c_next = ca.if_else(cnt + 1 > m - 0.5, 0, cnt + 1)
    if m == 1:
        u_next, w_next = law.solve(xn, t, s, xsw, w)
    else:
        u_next, w_next = solve_or_keep(law, nu)(c_next < 0.5, xn, t, s, xsw, w, held)
    return ca.vertcat(c_next, u_next, w_next)


def _first(law, nx: int, margin: ca.Function, h_start: ca.Function, nth: int, nd: int, seen, queue) -> ca.Function:
    """(x0, t0, s0, theta0, d0) -> ([h; RoA margin] at switch-in, the hold's entries then), h_start
    (z, d) -> h evaluated on z0 = [x0; t0; s0; x0; theta0; hold0]; a sampled law is solved at once,
    from the state it reads, seen(x0, theta0), which is also the switch state it reads; queue(x0, t0, s0,
    theta0, u0) -> the latency queue's entries at switch-in, after the law's hold."""
    x0, t0, s0 = ca.MX.sym("x0", nx), ca.MX.sym("t0"), ca.MX.sym("s0")
    th0, d0 = ca.MX.sym("th0", nth), ca.MX.sym("d0", nd)
    if law is not None:
        u_0, w0 = law.solve(seen(x0, th0), t0, s0, seen(x0, th0), ca.DM.zeros(law.nw))
        hold0 = ca.vertcat(0, u_0, w0, queue(x0, t0, s0, th0, u_0))
    else:
        hold0 = queue(x0, t0, s0, th0, None)
    out0 = h_start(ca.vertcat(x0, t0, s0, x0, th0, hold0), d0 if nd else ca.MX(0, 1))
    return ca.Function("robust_rigid_first", [x0, t0, s0, th0, d0], [ca.vertcat(out0, margin(x0, t0)),
                                                                 hold0])
