"""Compile a motion primitive (Definition 1) to named CasADi Functions.

Every function takes (x, t, s, x_sw): the state, the primitive's clock t, the time s since the
primitive was switched in, and the state at switch-in (used by motion profiles). The safety
oracle composes them; nothing here integrates.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import SpecError, SpecErrors
from ..spec.loader import PrimitiveInstance
from ..spec.models import PrimitiveClass
from .closed_loop import CompiledPrimitive, function_name, roa_margin_function
from .contacts import ContactPlan, Events, Fixed, Schedule, clock_phase, plan_jump, wrap_clock
from .events import event_window
from .exprs import ExprCompiler
from .guards import Guards, collect
from .laws.base import ControlContext
from .laws.kind import Setup
from .laws.registry import controller_kind
from .setpoint import compile_setpoint
from .system import CompiledSystem, OpenLoop, shadowing_error, taken_names

INACTIVE = 1e9
"""Value of a safety function outside its active window: never binding."""


def _constants(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, loop_env: dict) -> dict[str, float]:
    """Parameters, the argument's value and the `let` constants, in order; none may shadow a name
    an expression already means (a state, input, parameter, setpoint symbol, constant, function, t, s)."""
    taken = taken_names(sys, env={**sys.extra_env, **loop_env})
    errors = []
    for arg in inst.spec.arguments:
        err = shadowing_error(arg, sys, inst.locate(("arguments", arg)), f"primitive '{inst.base}': arguments.{arg}",
                              what="argument", taken=taken)
        if err is not None:
            errors.append(err)
    taken.update({a: "the primitive's argument" for a in inst.spec.arguments})
    for k in inst.spec.let:
        err = shadowing_error(k, sys, inst.locate(("let", k)), f"primitive '{inst.base}': let.{k}",
                              what="let constant", taken=taken)
        if err is not None:
            errors.append(err)
    if errors:
        raise SpecErrors(errors)
    env: dict[str, float] = dict(sys.parameters)
    env.update(inst.argument)
    for k, v in inst.spec.let.items():
        env[k] = ec.number(v, ("let", k), env)
    return env


def _clock_time(ec: ExprCompiler, inst: PrimitiveInstance, value, path: tuple, consts: dict, what: str) -> float:
    v = ec.number(value, path, consts, finite=True)
    if what == "period" and v <= 0:
        raise SpecError("period must be > 0", location=inst.locate(path), key=f"primitive '{inst.name}': period",
                        expected="T_p > 0", found=f"{v:g}", code="MPG104")
    return v


@dataclass
class _Clock:
    """The symbols every function of a primitive takes, and its clock data."""

    t: ca.SX  # the primitive's clock
    s: ca.SX  # time since switch-in
    x_sw: ca.SX  # state at switch-in
    tc: ca.SX  # the clock seen by setpoint and windows: wrapped into one period for periodic primitives
    period: float | None
    domain: tuple[float, float] | None


@dataclass
class _Mode:
    """The open loop a primitive runs on and its contact plan (None for systems without feet)."""

    loop: OpenLoop
    plan: ContactPlan | None

    @property
    def feet(self) -> tuple[str, ...]:
        """The loop's contact set (every contact frame under a schedule; none without feet)."""
        return self.plan.feet if self.plan is not None else ()

    @property
    def schedule(self) -> Schedule | None:
        return self.plan if isinstance(self.plan, Schedule) else None


def compile_primitive(inst: PrimitiveInstance, sys: CompiledSystem) -> CompiledPrimitive:
    """Build f_cl, control, h, roa_margin and setpoint for one graph node."""
    p = inst.spec
    ec = ExprCompiler(inst.locate, f"primitive '{inst.name}'")
    kind = controller_kind(p.controller, ec)
    loop = sys.open_loop(p.contacts)
    consts = _constants(inst, sys, ec, loop.env)
    clock = _clock(inst, sys, ec, consts)
    setup = kind.run_setup(inst, sys, ec, consts)
    cm = _contact_mode(inst, sys, loop, setup, clock)
    ident = function_name(inst.name)
    setpoint, x_star, x_star_dot = compile_setpoint(inst, sys, ec, consts, cm.feet, clock.t, clock.tc,
                                                    clock.period, ident)
    if sys.is_rigid_body and sys.events and cm.schedule is not None:
        setpoint = cm.schedule.with_flags(setpoint, sys)
    env: dict[str, object] = {**sys.env(), **consts, "t": clock.tc, "s": clock.s}  # t: the clock, within one period
    for i, n in enumerate(sys.state_names):
        env[f"{n}_star"] = x_star[i]
        env[f"{n}_star_dot"] = x_star_dot[i]
    ctx = ControlContext(sys, clock.t, clock.s, clock.x_sw, x_star, x_star_dot, setpoint, env, ec,
                         fixed=p.class_ is PrimitiveClass.FIXED, xdot=cm.loop.xdot, plan=cm.plan)
    ctx.info.update(setup.info)
    if cm.plan is not None:  # the report's record of the feet the primitive's dynamics hold
        ctx.info.update(cm.plan.record())
    u_raw = kind.build_law(p.controller, ctx)
    return _assemble(inst, sys, ec, clock, cm, ctx, u_raw, setpoint, ident)


def _clock(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, consts: dict) -> _Clock:
    """The period of a periodic primitive, the domain [t0, tf] of a transient, and the symbols."""
    p = inst.spec
    period = _clock_time(ec, inst, p.period, ("period",), consts, "period") if p.period is not None else None
    domain = None
    if p.domain is not None:
        domain = (_clock_time(ec, inst, p.domain[0], ("domain", 0), consts, "domain"),
                  _clock_time(ec, inst, p.domain[1], ("domain", 1), consts, "domain"))
        if domain[1] <= domain[0]:
            raise SpecError("domain must be [t0, tf] with tf > t0", location=inst.locate(("domain",)),
                            key=f"primitive '{inst.name}': domain", expected="tf > t0", found=f"{list(domain)}",
                            code="MPG104")
    t = ca.SX.sym("t")
    tc = wrap_clock(t, period)
    return _Clock(t, ca.SX.sym("s"), ca.SX.sym("x_sw", sys.nx), tc, period, domain)


def _contact_mode(inst: PrimitiveInstance, sys: CompiledSystem, loop: OpenLoop, setup: Setup, clock: _Clock) -> _Mode:
    """Under a contact schedule (the spec's, or the one the controller kind's setup sets) the clock
    sets the contact set, and flags in the state follow it (Schedule.jump); rigid bodies without one
    hold the primitive's contacts (all contact frames when it names none)."""
    schedule = _schedule(inst, sys, setup.contacts, clock.period)
    if schedule is not None:
        return _Mode(sys.scheduled_loop(schedule.mode(sys.model.contact_frames, clock.t)), schedule)
    if sys.is_rigid_body:
        contacts = inst.spec.contacts
        feet = tuple(sys.model.contact_frames if contacts is None else contacts)
        return _Mode(loop, (Events if sys.events else Fixed)(feet))
    return _Mode(loop, None)


def _narrow(inst: PrimitiveInstance, cm: _Mode, period: float | None) -> tuple[tuple, float]:
    """(phase intervals [lo, hi) of the last roa.before_touchdown.window seconds before each scheduled touchdown,
    E's radius there over roa.radius); none without before_touchdown. A located SpecError (MPG108) when the
    primitive has no periodic contact schedule with touchdowns."""
    nb = inst.spec.roa.before_touchdown
    if nb is None:
        return (), 1.0
    sched = cm.schedule
    tds = sched.touchdowns if sched is not None and sched.period else []
    if not tds:
        raise SpecError("roa.before_touchdown needs scheduled touchdowns", location=inst.locate(("roa", "before_touchdown")),
                        key=f"primitive '{inst.name}': roa.before_touchdown",
                        expected="a periodic primitive whose contact schedule puts a foot down (a gait)",
                        found="no scheduled touchdown" if sched is not None else "no contact schedule", code="MPG108")
    w, T = float(nb.window), float(period)
    if not w < T:
        raise SpecError("the window before a touchdown must be shorter than the period",
                        location=inst.locate(("roa", "before_touchdown", "window")),
                        key=f"primitive '{inst.name}': roa.before_touchdown.window", expected=f"< {T:g} s",
                        found=f"{w:g}", code="MPG104")
    out = []
    for td in tds:
        lo = td - w
        out += [(lo, td)] if lo >= 0 else [(0.0, td), (lo + T, T)] if td > 0 else [(lo + T, T)]
    return tuple(sorted((round(a, 12), round(b, 12)) for a, b in out if b > a)), float(nb.radius) / float(inst.spec.roa.radius)


def _assemble(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, clock: _Clock, cm: _Mode,
              ctx: ControlContext, u_raw, setpoint: ca.Function, ident: str) -> CompiledPrimitive:
    """Close the loop: saturate the law, compose dynamics and safety functions with it, size E."""
    p = inst.spec
    sat_u = saturate(sys.u, sys.u_lo, sys.u_hi)
    args = [sys.x, clock.t, clock.s, clock.x_sw]
    f_u = ca.Function("f_u", args + [sys.u], [ca.substitute(cm.loop.xdot, sys.u, sat_u) if sys.nu else cm.loop.xdot])
    # safety functions may name inputs (the saturated control)
    henv = {**ctx.env, **cm.loop.env, **{n: sat_u[i] for i, n in enumerate(sys.input_names)}}
    hs, hs_raw, names, windows = _safety_functions(inst, sys, ec, henv, cm, clock, sat_u)
    windowed = any(w is not None for w in windows)
    h_u = ca.Function("h_u", args + [sys.u], [ca.vertcat(*hs) if hs else ca.SX(0, 1)])
    h_all = ca.Function("h_raw", args + [sys.u], [ca.vertcat(*hs_raw)]) if windowed else h_u
    jump = plan_jump(cm.plan, sys, clock.t)
    f_cl, control, h, loop_fn = _close_loop(ident, args, u_raw, f_u, h_u, sys)
    loop_raw = _close_loop(ident + "_raw", args, u_raw, f_u, h_all, sys)[3] if windowed else loop_fn
    open_loop = _open_loop(ident, args, f_u, h_all, sys)
    loop_u = open_loop if ctx.sampled is not None else None
    W = _roa_metric(inst, sys)
    radius = float(p.roa.radius) if p.roa.radius is not None else 0.0  # 0 until a verifier sizes E
    info = {**ctx.info, "roa_W": W.tolist()}  # the report's record
    narrow, ratio = _narrow(inst, cm, clock.period)
    roa_margin = roa_margin_function(sys, setpoint, W, radius, ident, narrow, ratio, clock.period)
    grid = p.grid
    return CompiledPrimitive(
        name=inst.name, cls=p.class_, system=sys, period=clock.period, domain=clock.domain, next=p.next,
        horizon=p.horizon, grid_A=grid.t_A if grid else 0, grid_B=grid.t_B if grid else 0, h_names=names,
        grid_phase=float(grid.phase) if grid else 0.0, narrow=narrow, narrow_ratio=ratio,
        radius=radius, f_cl=f_cl, control=control, h=h, roa_margin=roa_margin, setpoint=setpoint, W=W, info=info,
        contacts=cm.plan, jump=jump, loop=loop_fn, loop_raw=loop_raw, windows=windows,
        boundaries=_boundaries(windows, cm.plan, clock.period, clock.domain),
        hybrid=sys.events or cm.schedule is not None, sampled=ctx.sampled, loop_u=loop_u, open_loop=open_loop,
        guards=_guards(f_cl, control, sys, ctx.sampled),
    )


def _guards(f_cl: ca.Function, control: ca.Function, sys: CompiledSystem, sampled) -> Guards:
    """The closed loop's guards; a sampled law has none between its solves (each solve is at a
    step's start, its input held over the step), so its steps need no location."""
    if sampled is not None:
        when = "at every step's start" if sampled.period is None else f"every {sampled.period:g} s, at a step's start"
        return Guards(why=f"the law is solved {when} and held in between: it switches only where a step starts")
    return collect(f_cl, labels=_saturation_guards(control, sys))


def _safety_functions(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, henv: dict, cm: _Mode,
                      clock: _Clock, sat_u):
    """(h active in its window, h always active, names, windows) over the safe set C: written
    functions, and the blocks a rigid-body system provides (`use`)."""
    hs, hs_raw, names, windows = [], [], [], []
    for j, sf in enumerate(inst.safe_set):
        path = ("safe_set", j)
        if sf.use is not None:
            items = _builtin_block(inst, sys, sf.use, path, cm, clock.t)
        elif sf.h is not None:
            items = [(sf.name, _finite_if_constant(inst, path + ("h",), ec.sx(sf.h, path + ("h",), henv)))]
        else:
            items = [(sf.name, sf.tol - ca.fabs(ec.sx(sf.eq, path + ("eq",), henv)))]
        for name, hv, *own in items:  # a block may give its rows their own clock windows
            hv = ca.substitute(hv, sys.u, sat_u) if sys.nu else hv
            hs_raw.append(hv)
            when = own[0] if own else sf.when
            if isinstance(when, tuple):
                a, b = float(when[0]), float(when[1])
                if not own:
                    _check_in_period(inst, path, a, b, clock.period)
                windows.append((a, b))
                hv = ca.if_else(ca.logic_and(clock.tc >= a, clock.tc < b), hv, INACTIVE)
            elif sf.when is not None:  # anchored on a contact event: the loader checked the system has them
                w = event_window(sf.when, sys.state_names)
                windows.append(w)
                hv = ca.if_else(w.active(sys.x[w.clock], clock.s), hv, INACTIVE)
            else:
                windows.append(None)
            hs.append(hv)
            names.append(name or f"h{j}")
    return hs, hs_raw, names, windows


def _finite_if_constant(inst: PrimitiveInstance, path: tuple, hv):
    """h as given, unless it is a constant that is not a finite number (`1/0`, `inf - inf`): a safe
    set that is everything or nothing, refused here rather than found by every oracle call."""
    if hv.is_constant() and not np.all(np.isfinite(np.asarray(ca.DM(hv), float))):
        raise SpecError("the safety function is a constant that is not a finite number",
                        location=inst.locate(path), key=f"primitive '{inst.name}': {'.'.join(map(str, path))}",
                        expected="an expression of the state and clock with finite values",
                        found=f"{float(ca.DM(hv)[0]):g}", code="MPG205")
    return hv


def _check_in_period(inst: PrimitiveInstance, path: tuple, a: float, b: float, period: float | None) -> None:
    """A clock window of a periodic primitive lies in one period [0, T]: its clock wraps into it, so
    a window beyond T would never (or only partly) be active."""
    if period is not None and (a < 0 or b > period * (1 + 1e-12)):
        raise SpecError("the window lies outside the primitive's period", location=inst.locate(path + ("when",)),
                        key=f"primitive '{inst.name}': {'.'.join(map(str, path))}.when",
                        expected=f"[start, end) within [0, {period:g}] (the clock wraps into one period)",
                        found=f"[{a:g}, {b:g})", code="MPG104")


def _builtin_block(inst: PrimitiveInstance, sys: CompiledSystem, use: str, path: tuple, cm: _Mode,
                   t: ca.SX) -> list:
    """The safety functions of a block the system provides, over the primitive's loop and contact
    plan (under a schedule contact conditions bind by the mode of the clock)."""
    try:
        return sys.builtin_safe_set(use, cm.loop, cm.plan, t)
    except KeyError:
        raise SpecError("this safe-set block does not apply to the system", location=inst.locate(path + ("use",)),
                        key=f"primitive '{inst.name}': {'.'.join(map(str, path))}.use", expected="a block of the "
                        "project or, for rigid bodies, joint_limits, ground_contact, no_slip, aerial or (under a "
                        "contact schedule) touchdown_gap",
                        found=repr(use), code="MPG302") from None


def _roa_metric(inst: PrimitiveInstance, sys: CompiledSystem) -> np.ndarray:
    """W of the explicit RoA E = {||x - x*(t)||_W < r}: roa.matrix, or diag(roa.weights) (ones by
    default); event clocks have no distance to x*."""
    roa = inst.spec.roa
    if roa.matrix is not None:
        W = np.asarray(roa.matrix, float)
        if W.shape != (sys.nx, sys.nx) or not np.allclose(W, W.T) or np.linalg.eigvalsh(W).min() <= 0:
            raise SpecError("roa.matrix must be symmetric positive definite", location=inst.locate(("roa", "matrix")),
                            key=f"primitive '{inst.name}': roa.matrix", expected=f"an SPD {sys.nx}x{sys.nx} matrix",
                            found=f"shape {W.shape}", code="MPG106")
    else:
        w = np.ones(sys.nx) if roa.weights is None else np.asarray(roa.weights, float)
        if w.shape != (sys.nx,):
            # with contact events, name the states they append (flags, event clocks)
            tail = sys.state_names[sys.event_clocks[0] - len(sys.model.contact_frames):] if sys.events else []
            raise SpecError("roa.weights needs one weight per state", location=inst.locate(("roa", "weights")),
                            key=f"primitive '{inst.name}': roa.weights", expected=f"{sys.nx}", found=f"{w.size}",
                            code="MPG106", hint=f"the states end with {', '.join(tail)}" if tail else "")
        W = np.diag(w)
    W[sys.event_clocks, :] = 0.0  # times since contact events: no distance to x*
    W[:, sys.event_clocks] = 0.0
    return W


def _boundaries(windows, plan: ContactPlan | None, period, domain) -> tuple[float, ...]:
    """Clock times at which the safe set or the contact mode switches: the oracle steps onto each.

    For a periodic primitive they are taken within one period (the clock wraps); a transient's end
    t_f is one, so its rollouts stop exactly at t_f.
    """
    times = {v for w in windows if isinstance(w, tuple) for v in w}
    times |= set(plan.boundaries if plan is not None else ())
    if domain is not None:
        times.add(float(domain[1]))
    if period is not None:
        times = {clock_phase(v, period) for v in times}
    return tuple(sorted(times))


def _schedule(inst: PrimitiveInstance, sys: CompiledSystem, planned: Schedule | None,
              period: float | None) -> Schedule | None:
    """The contact schedule the controller kind's setup plans (run on the primitive's clock, so with
    its period), else the spec's; None without either."""
    frames = tuple(sys.model.contact_frames) if sys.is_rigid_body else ()
    if planned is not None:
        return Schedule(tuple((float(u), tuple(f)) for u, f in planned.phases), period, frames)
    sched = inst.spec.contact_schedule
    if sched is None:
        return None
    if not sys.is_rigid_body:
        raise SpecError("a contact schedule needs a rigid-body system", location=inst.locate(("contact_schedule",)),
                        key=f"primitive '{inst.name}': contact_schedule", expected="system kind rigid_body",
                        found="an analytic system", code="MPG108")
    feet = sys.model.contact_frames
    for k, ph in enumerate(sched):
        bad = [f for f in ph.feet if f not in feet]
        if bad:
            raise SpecError("unknown contact frame", location=inst.locate(("contact_schedule", k, "feet")),
                            key=f"primitive '{inst.name}': contact_schedule.{k}.feet",
                            expected="one of " + ", ".join(feet), found=repr(bad[0]), code="MPG106")
    return Schedule(tuple((float(ph.until), tuple(ph.feet)) for ph in sched), period, frames)


def _saturation_guards(control: ca.Function, sys: CompiledSystem) -> tuple[ca.Function, list[str]] | None:
    """The guards input saturation gives the closed loop (as saturate writes it) and their names."""
    if not control.is_a("SXFunction"):
        return None
    a = control.sx_in()
    ur = control(*a)[0]
    exprs, names = [], []
    for i, name in enumerate(sys.input_names):
        ui, lo, hi = ur[i], sys.u_lo[i], sys.u_hi[i]
        if np.isfinite(lo):
            exprs.append(lo - ui)
            names.append(f"saturation: {name} at its lower bound {lo:g}")
            ui = ui + ca.fmax(lo - ui, 0)
        if np.isfinite(hi):
            exprs.append(ui - hi)
            names.append(f"saturation: {name} at its upper bound {hi:g}")
    return ca.Function("saturation_guards", a, [ca.vertcat(*exprs) if exprs else ca.SX(0, 1)]), names


def saturate(u, lo: np.ndarray, hi: np.ndarray):
    """Clip u to [lo, hi] in a form that lets NaN through (fmin/fmax would replace it by a bound).

    Unbounded inputs are left as they are, so polynomial closed loops stay polynomial.
    """
    parts = []
    for i in range(u.shape[0]):
        ui = u[i]
        if np.isfinite(lo[i]):
            ui = ui + ca.fmax(lo[i] - ui, 0)
        if np.isfinite(hi[i]):
            ui = ui - ca.fmax(ui - hi[i], 0)
        parts.append(ui)
    return ca.vertcat(*parts) if parts else u


def _close_loop(ident: str, args: list, u_raw, f_u: ca.Function, h_u: ca.Function, sys: CompiledSystem):
    """Compose the open loop and the safety functions with the control law.

    An expression law is inlined (SX); a law given as a Function (an optimisation-based law such
    as the ID-QP) is called from an MX graph, so f_cl, h and control solve it at every call (continuous
    time). The oracle's chunks solve such a law at its control rate instead (`sampled`, `loop_u`).
    """
    k = u_raw if isinstance(u_raw, ca.Function) else ca.Function("k", args, [u_raw])
    sym = ca.SX.sym if k.is_a("SXFunction") else ca.MX.sym
    a = [sym(n, *arg.shape) for n, arg in zip(("x", "t", "s", "x_sw"), args)]
    ur = k(*a)
    us = saturate(ur, sys.u_lo, sys.u_hi)
    names = ["x", "t", "s", "x_sw"]
    f_cl = ca.Function(f"f_cl_{ident}", a, [f_u(*a, ur)], names, ["xdot"])
    control = ca.Function(f"k_{ident}", a, [ur, us], names, ["u_raw", "u"])
    h = ca.Function(f"h_{ident}", a, [h_u(*a, ur)], names, ["h"])
    loop = ca.Function(f"loop_{ident}", a, [f_u(*a, ur), h_u(*a, ur), ur, us], names, ["xdot", "h", "u_raw", "u"])
    return f_cl, control, h, loop


def _open_loop(ident: str, args: list, f_u: ca.Function, h_u: ca.Function, sys: CompiledSystem) -> ca.Function:
    """(x, t, s, x_sw, u_raw) -> (xdot, h, u_raw, u): the loop under a held input, saturated as the
    closed loop saturates it."""
    a = [ca.SX.sym(n, *arg.shape) for n, arg in zip(("x", "t", "s", "x_sw"), args)] + [ca.SX.sym("u", sys.nu)]
    ur = a[4]
    return ca.Function(f"loop_u_{ident}", a, [f_u(*a), h_u(*a), ur, saturate(ur, sys.u_lo, sys.u_hi)],
                       ["x", "t", "s", "x_sw", "u_held"], ["xdot", "h", "u_raw", "u"])
