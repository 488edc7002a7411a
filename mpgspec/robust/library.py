"""One compiled library per robot: its perturbed contact dynamics and contact events, shared by
every robust rollout, gradient and uncertain-sequence stepper of its primitives.

Inlined, each target's robust step, its gradient and each primitive's sequence stepper carry their
own copy of the constrained rigid-body dynamics and of its reverse derivative (most of their C code
and gcc time). Here they are compiled once per robot:
- dyn(q, v, u, c, k, w) -> (a, lam): masked_contact_dynamics with the contact mode c, the mass
  scale k and a generalized force w as inputs, so one function serves every primitive and mode;
- events(x, u, s, k, w) -> x+: the discrete update after a step with contact events (touchdown,
  impact, lift-off on the perturbed plant, event clocks);
- touchdown(q, v, j, c) -> (q+, v+): feet flagged in j put on the ground by their legs and a plastic
  impact with the feet of c (a contact schedule's update at a step's end),
in two variants: as they are (LIBRARY_FLAGS), what the rollouts and steppers call, and with their
reverse derivatives (GRADIENT_FLAGS), built only where a search takes a push gradient. The step's own
Functions call them through casadi.external and are linked against the library; its path and symbols
carry the hash of its code, so what is compiled against it changes when the robot does. The values
are those of the inlined plant (the same expressions, evaluated in the same order).

step_library compiles one primitive's robust step and first sample the same way, once: its robust
rollouts and its uncertain-sequence stepper call the same library (a push gradient, a twin with
reverse derivatives linked against the robot's reverse variant). It is linked
against the primitive's loop library too (oracle/looplib.py) where the step calls its parts (a sampled
law's solve, a large RoA margin: rigid.loop_parts) instead of compiling them again.
"""
from __future__ import annotations

import hashlib
import threading
import weakref
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from ..compile.events import clock_rate
from ..compile.rigidbody.hybrid import contact_events, masked_contact_dynamics, masked_impact, touchdown_projection
from ..compile.rigidbody.liegroup import normalize_quaternion, qdot
from ..oracle.jit import compile_library

LIBRARY_FLAGS = ("-O2",)
"""Compiled once per robot, so worth the optimiser's time: on the A1 the dynamics run about 2x faster
than at -O1 without its superlinear passes, the flags of the large per-primitive loops
(bench/bench_jit.py)."""

STEP_FLAGS = ("-O1",)
"""gcc flags of the robust steps (rstep libraries, the analytic rollouts' chunks and the uncertain
sequences' steppers), whatever settings.jit_flags say: each is run for thousands of rollouts, and
measured on the pendulum the robust stage runs about 2x faster than at -O0 for about 2 CPU-s more gcc."""

GRADIENT_FLAGS = ("-O0",)
"""gcc flags of what only a push gradient calls (the robot library's reverse derivatives, a step's
reverse-derivative twin, the gradient itself): evaluated for the few cells a search reaches (on the
A1, 8 of the robust stage's rollouts), where the reverse derivatives are three quarters of the
robot library's C code; at -O2 they took 34 CPU-s of gcc, at -O0 2.6 (bench/RESULTS.md)."""

_BUILT: dict[tuple[int, bool], tuple] = {}
"""(id of the system, with reverse derivatives) -> (a weak reference to it, the Future of its
library): built once per process and system; an id reused by another system after the first is
freed is not mistaken for it."""
_LOCK = threading.Lock()


@dataclass(frozen=True)
class RobotLibrary:
    """The compiled library of one robot and its Functions, called through casadi.external."""

    path: Path
    dyn: ca.Function
    events: ca.Function | None
    touchdown: ca.Function


def robot_library(sys, reverse: bool = False) -> RobotLibrary | None:
    """The robot's library, built once per process and system, waiting for a build under way (None
    when gcc fails: the caller inlines the dynamics). `reverse`: the variant with reverse derivatives
    (GRADIENT_FLAGS) a push gradient goes through; the rollouts call the one without (LIBRARY_FLAGS)."""
    key = (id(sys), reverse)
    with _LOCK:
        ref, fut = _BUILT.get(key, (None, None))
        mine = ref is None or ref() is not sys
        if mine:
            fut = Future()
            _BUILT[key] = (weakref.ref(sys), fut)
    if mine:
        try:
            fut.set_result(_build(sys, reverse))
        except Exception as err:  # noqa: BLE001 - every waiter sees the same failure
            fut.set_exception(err)
    return fut.result()


def prefetch(sys, reverse: bool = False) -> None:
    """Generate the robot library's C code now and leave its gcc running in the background (beside
    the stages before the robust one), with the reverse-derivative variant when a search will take a
    gradient; robot_library later finds them compiled, or waits for them. The CasADi work stays in
    this thread: a process forked while another thread runs CasADi can inherit its locks held and hang."""
    try:
        for rev in (False, True) if reverse else (False,):
            _build(sys, rev, wait=False)
    except Exception:  # noqa: BLE001 - the robust stage builds again and reports its own failure
        pass


def _build(sys, reverse: bool, wait: bool = True) -> RobotLibrary | None:
    m = sys.model
    q, v, u = ca.SX.sym("q", m.nq), ca.SX.sym("v", m.nv), ca.SX.sym("u", m.nu)
    c, k, w = ca.SX.sym("c", len(m.contact_frames)), ca.SX.sym("k"), ca.SX.sym("w", m.nv)
    a, lam = masked_contact_dynamics(sys, q, v, u, c, k, w)
    j = ca.SX.sym("j", len(m.contact_frames))
    q_new = touchdown_projection(sys, q, ca.vertsplit(j))
    v_new = ca.if_else(ca.sum1(j) > 0, masked_impact(sys, q_new, v, c), v)
    parts = {"dyn": ([q, v, u, c, k, w], [a, lam]), "touchdown": ([q, v, j, c], [q_new, v_new])}
    if sys.events:
        x, s = sys.x, ca.SX.sym("s")
        x_new = ca.vertcat(normalize_quaternion(m, x[:m.nq]), x[m.nq:])
        parts["events"] = ([x, u, s, k, w], [contact_events(sys, x_new, u, s, k, w)])
    digest = hashlib.sha256()
    for name, (ins, outs) in parts.items():
        digest.update(ca.Function(name, ins, outs).serialize().encode())
    tag = f"robot_{digest.hexdigest()[:16]}" + ("r" if reverse else "")
    fns = [ca.Function(f"{tag}_{name}", ins, outs, {"cse": True}) for name, (ins, outs) in parts.items()]
    path = compile_library(tag, fns, GRADIENT_FLAGS if reverse else LIBRARY_FLAGS, reverse=reverse, wait=wait)
    if path is None:
        return None
    ext = {name: ca.external(f"{tag}_{name}", str(path)) for name in parts}
    return RobotLibrary(path, ext["dyn"], ext.get("events"), ext["touchdown"])


def library_plant(prim, lib: RobotLibrary, frame: str) -> ca.Function:
    """(x, u, k, F, t) -> (xdot, lam, c) as the system's uncertain_plant with a contact schedule or
    contact events, the dynamics called from the robot's library."""
    sys, m = prim.system, prim.system.model
    feet, plan = m.contact_frames, prim.contacts
    xs, ts, Fs = sys.x, ca.SX.sym("t"), ca.SX.sym("F", 3)
    xq, xv = xs[:m.nq], xs[m.nq:m.nq + m.nv]
    if plan.by_clock:
        mode = plan.mode(feet, ts)
        cs = ca.vertcat(*[mode[f] for f in feet])
    else:
        cs = xs[m.nq + m.nv:m.nq + m.nv + len(feet)]
    pre = ca.Function("plant_in", [xs, ts, Fs], [xq, xv, cs, sys.push_wrench(frame, xq, Fs)])
    a_s = ca.SX.sym("a", m.nv)
    xdot = ca.vertcat(qdot(m, xq, xv), a_s, ca.DM.zeros(sys.nx - m.nq - m.nv - len(sys.event_clocks)),
                      *[clock_rate(xs[i]) for i in sys.event_clocks])
    post = ca.Function("plant_out", [xs, a_s], [xdot])
    x, u, k = ca.MX.sym("x", sys.nx), ca.MX.sym("u", sys.nu), ca.MX.sym("k")
    F, t = ca.MX.sym("F", 3), ca.MX.sym("t")
    q, v, c, w = pre(x, t, F)
    a, lam = lib.dyn(q, v, u, c, k, w)
    return ca.Function("uncertain_plant", [x, u, k, F, t], [post(x, a), lam, c],
                       ["x", "u", "k", "F", "t"], ["xdot", "lam", "c"])


def library_jump(prim, lib: RobotLibrary, frame: str) -> ca.Function:
    """(x, u, t, s, k, F) -> x after a step's contact events on the perturbed plant, from the
    robot's library (robust_jump with contact events and no schedule)."""
    sys, m = prim.system, prim.system.model
    Fs = ca.SX.sym("F", 3)
    xs = sys.x
    wrench = ca.Function("push", [xs, Fs], [sys.push_wrench(frame, xs[:m.nq], Fs)])
    x, u, t, s = ca.MX.sym("x", sys.nx), ca.MX.sym("u", sys.nu), ca.MX.sym("t"), ca.MX.sym("s")
    k, F = ca.MX.sym("k"), ca.MX.sym("F", 3)
    return ca.Function("robust_jump", [x, u, t, s, k, F], [lib.events(x, u, s, k, wrench(x, F))])


def library_schedule_jump(prim, lib: RobotLibrary) -> ca.Function:
    """(x, u, t, s, k, F) -> x after a step under a contact schedule (Schedule.jump: the clock decides,
    not k or F), the touchdown and impact called from the robot's library."""
    sys, m = prim.system, prim.system.model
    feet, plan = m.contact_frames, prim.contacts
    xs, ts = sys.x, ca.SX.sym("t")
    nq, nv = m.nq, m.nv
    mode, before = plan.mode(feet, ts), plan.mode(feet, ts, before=True)
    c = ca.vertcat(*[mode[f] for f in feet])
    joins = ca.vertcat(*[ca.logic_and(mode[f] > 0.5, before[f] < 0.5) for f in feet])
    tail = ca.vertcat(c, xs[nq + nv + len(feet):]) if sys.events else xs[nq + nv:]
    pre = ca.Function("jump_in", [xs, ts], [sys.project(xs)[:nq], xs[nq:nq + nv], joins, c, tail])
    x, u, t, s = ca.MX.sym("x", sys.nx), ca.MX.sym("u", sys.nu), ca.MX.sym("t"), ca.MX.sym("s")
    k, F = ca.MX.sym("k"), ca.MX.sym("F", 3)
    q, v, j, cc, rest = pre(x, t)
    q_new, v_new = lib.touchdown(q, v, j, cc)
    return ca.Function("robust_jump", [x, u, t, s, k, F], [ca.vertcat(q_new, v_new, rest)])


def step_library(step: ca.Function, first: ca.Function, reverse: bool, flags: tuple[str, ...],
                 libs: tuple[Path, ...]) -> tuple[ca.Function, ca.Function, Path] | None:
    """(step, first, library path): one primitive's robust step and first sample compiled into one
    library linked against `libs` (the robot's), with their reverse derivatives when a gradient is
    taken through them; the names carry the hash of both. None when gcc fails."""
    digest = hashlib.sha256((step.serialize() + first.serialize()).encode()).hexdigest()[:16]
    tag = f"rstep_{digest}"
    named = [_renamed(fn, f"{tag}_{kind}") for fn, kind in ((step, "step"), (first, "first"))]
    path = compile_library(tag, named, flags, reverse=reverse, large=True, libs=libs)
    if path is None:
        return None
    return ca.external(f"{tag}_step", str(path)), ca.external(f"{tag}_first", str(path)), path


def _renamed(fn: ca.Function, name: str) -> ca.Function:
    """fn under another name (a call of it, its inputs and outputs named as fn's)."""
    a = fn.mx_in()
    return ca.Function(name, a, fn.call(a), fn.name_in(), fn.name_out())
