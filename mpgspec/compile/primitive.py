"""Compile a motion primitive (Definition 1) to named CasADi Functions.

Every function takes (x, t, s, x_sw): the state, the primitive's clock t, the time s since the
primitive was switched in, and the state at switch-in (used by motion profiles). The safety
oracle composes them; nothing here integrates.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import SpecError, SpecErrors
from ..spec.loader import PrimitiveInstance
from ..spec.models import PrimitiveClass
from .closed_loop import CompiledPrimitive, function_name, roa_margin_function
from .contacts import Events, Fixed, Schedule, plan_jump, wrap_clock
from .controllers import LAWS, ControlContext
from .events import event_window
from .expr_casadi import interp_cubic, interp_linear
from .exprs import ExprCompiler
from .system import CompiledSystem, shadowing_error, taken_names

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


def compile_primitive(inst: PrimitiveInstance, sys: CompiledSystem) -> CompiledPrimitive:
    """Build f_cl, control, h, roa_margin and setpoint for one graph node."""
    p = inst.spec
    ec = ExprCompiler(inst.locate, f"primitive '{inst.name}'")
    loop = sys.open_loop(p.contacts)
    consts = _constants(inst, sys, ec, loop.env)
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
    s = ca.SX.sym("s")
    x_sw = ca.SX.sym("x_sw", sys.nx)
    x = sys.x
    # clock seen by setpoint and windows: wrapped into one period for periodic primitives
    tc = wrap_clock(t, period)
    trot = _trot_setup(inst, sys, ec, consts) if p.controller.type == "trot" else None
    schedule = _schedule(inst, sys, trot, period)
    plan = mode = None  # the contact plan, and its mode: foot -> 1 while held (of the clock under a schedule)
    if schedule is not None:  # the clock sets the contact set (flags in the state follow it, Schedule.jump)
        plan = schedule
        mode = schedule.mode(sys.model.contact_frames, t)
        loop = sys.scheduled_loop(mode)
    elif sys.is_rigid_body:
        plan = (Events if sys.events else Fixed)(tuple(loop.contacts))
        mode = plan.mode(sys.model.contact_frames)
    env: dict[str, object] = {**sys.env(), **consts, "t": tc, "s": s}  # t: the clock, within one period
    sp = p.setpoint
    table = None  # (times, samples, interpolation) of a tabulated setpoint
    if sp.named is not None:
        unknown = [k for k in sp.named if k not in sys.state_names]
        if unknown:
            raise SpecError("setpoint names an unknown state", location=inst.locate(("setpoint", "named", unknown[0])),
                            key=f"primitive '{inst.name}': setpoint.named", expected="state names of the system",
                            found=repr(unknown[0]), code="MPG106")
        base = sys.default_state(loop.contacts)
        x_star_t = ca.vertcat(*[ec.sx(sp.named[n], ("setpoint", "named", n), {**consts, "t": t}) if n in sp.named
                                else ca.SX(base[i]) for i, n in enumerate(sys.state_names)])
        if sp.feet_on_ground:
            from .rigidbody.system import feet_on_ground

            x_fixed = feet_on_ground(sys, np.array(ca.Function("x0", [t], [x_star_t])(0.0)).ravel())
            i = sys.state_names.index("base_z")
            x_star_t = ca.vertcat(x_star_t[:i], x_fixed[i], x_star_t[i + 1:])
    elif sp.expr is not None:
        if len(sp.expr) != sys.nx:
            raise SpecError("setpoint needs one expression per state", location=inst.locate(("setpoint", "expr")),
                            key=f"primitive '{inst.name}': setpoint.expr", expected=f"{sys.nx}", found=f"{len(sp.expr)}",
                            code="MPG106")
        x_star_t = ec.vector(sp.expr, ("setpoint", "expr"), {**consts, "t": t})
    elif sp.file is not None:
        ts, ys = _samples_from_csv(inst, sys, loop.contacts)
        table = (ts, ys, sp.interpolation)
        interp = interp_cubic if sp.interpolation == "cubic" else interp_linear
        x_star_t = ca.vertcat(*[interp(t, ts, ys[:, i]) for i in range(sys.nx)])
    else:
        if any(len(r) != sys.nx for r in sp.samples):
            raise SpecError("each sample needs one value per state", location=inst.locate(("setpoint", "samples")),
                            key=f"primitive '{inst.name}': setpoint.samples", expected=f"{sys.nx} values",
                            found=f"{sorted({len(r) for r in sp.samples})}", code="MPG106")
        ts = np.asarray(sp.times, float)
        ys = np.asarray(sp.samples, float)
        table = (ts, ys, sp.interpolation)
        interp = interp_cubic if sp.interpolation == "cubic" else interp_linear
        x_star_t = ca.vertcat(*[interp(t, ts, ys[:, i]) for i in range(sys.nx)])
    x_star_raw = ca.Function("x_star_raw", [t], [x_star_t])
    x_star = x_star_raw(tc)
    x_star_dot = ca.jacobian(x_star_raw(t), t)
    x_star_dot = ca.substitute(x_star_dot, t, tc)
    setpoint = ca.Function(f"setpoint_{function_name(inst.name)}", [t], [x_star])
    if table is not None and len(table[0]) > TABLE_KNOTS:  # a lookup, not a tree of thousands of branches
        setpoint = _table_setpoint(f"setpoint_{function_name(inst.name)}", *table, period)
    if sys.is_rigid_body and sys.events and schedule is not None:
        setpoint = schedule.with_flags(setpoint, sys)
    for i, n in enumerate(sys.state_names):
        env[f"{n}_star"] = x_star[i]
        env[f"{n}_star_dot"] = x_star_dot[i]
    ctx = ControlContext(sys, t, s, x_sw, x_star, x_star_dot, setpoint, env, ec,
                         fixed=p.class_ is PrimitiveClass.FIXED, xdot=loop.xdot, contacts=loop.contacts, mode=mode)
    if trot is not None:
        ctx.info["trot"] = {k: v for k, v in trot.items() if k != "gains"}
    u_raw = LAWS[p.controller.type](p.controller, ctx)
    sat_u = saturate(sys.u, sys.u_lo, sys.u_hi)
    args = [x, t, s, x_sw]
    ident = function_name(inst.name)
    f_u = ca.Function("f_u", args + [sys.u], [ca.substitute(loop.xdot, sys.u, sat_u) if sys.nu else loop.xdot])
    # safety functions may name inputs (the saturated control)
    henv = {**env, **loop.env, **{n: sat_u[i] for i, n in enumerate(sys.input_names)}}
    hs, hs_raw, names, windows = [], [], [], []
    for j, sf in enumerate(inst.safe_set):
        path = ("safe_set", j)
        if sf.use is not None:
            try:
                scheduled = schedule is not None  # contact conditions bind by the mode
                items = sys.builtin_safe_set(sf.use, loop.contacts, mode=mode if scheduled else None,
                                             env=loop.env if scheduled else None)
            except KeyError:
                raise SpecError("this safe-set block does not apply to the system", location=inst.locate(path + ("use",)),
                                key=f"primitive '{inst.name}': safe_set.{j}.use", expected="a block of the project or, "
                                "for rigid bodies, joint_limits, ground_contact, no_slip or aerial",
                                found=repr(sf.use), code="MPG302") from None
        elif sf.h is not None:
            items = [(sf.name, ec.sx(sf.h, path + ("h",), henv))]
        else:
            items = [(sf.name, sf.tol - ca.fabs(ec.sx(sf.eq, path + ("eq",), henv)))]
        for name, hv in items:
            hv = ca.substitute(hv, sys.u, sat_u) if sys.nu else hv
            hs_raw.append(hv)
            if isinstance(sf.when, tuple):
                a, b = float(sf.when[0]), float(sf.when[1])
                windows.append((a, b))
                hv = ca.if_else(ca.logic_and(tc >= a, tc < b), hv, INACTIVE)
            elif sf.when is not None:  # anchored on a contact event: the loader checked the system has them
                w = event_window(sf.when, sys.state_names)
                windows.append(w)
                hv = ca.if_else(w.active(x[w.clock], s), hv, INACTIVE)
            else:
                windows.append(None)
            hs.append(hv)
            names.append(name or f"h{j}")
    h_u = ca.Function("h_u", args + [sys.u], [ca.vertcat(*hs) if hs else ca.SX(0, 1)])
    jump = plan_jump(plan, sys, t)
    f_cl, control, h, loop_fn = _close_loop(ident, args, u_raw, f_u, h_u, sys)
    if any(w is not None for w in windows):
        h_raw = ca.Function("h_raw", args + [sys.u], [ca.vertcat(*hs_raw)])
        loop_raw = _close_loop(ident + "_raw", args, u_raw, f_u, h_raw, sys)[3]
    else:
        loop_raw = loop_fn
    loop_u = None
    if ctx.sampled is not None:
        h_all = h_raw if any(w is not None for w in windows) else h_u
        loop_u = _open_loop(ident, args, f_u, h_all, sys)
    roa = p.roa
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
    radius = float(roa.radius) if roa.radius is not None else 0.0  # 0 until a verifier sizes E
    info = {**ctx.info, **(plan.record() if plan is not None else {}), "roa_W": W.tolist()}  # the report's record
    roa_margin = roa_margin_function(sys, setpoint, W, radius, ident)
    grid = p.grid
    return CompiledPrimitive(
        name=inst.name, cls=p.class_, system=sys, period=period, domain=domain, next=p.next, horizon=p.horizon,
        grid_A=grid.t_A if grid else 0, grid_B=grid.t_B if grid else 0, h_names=names, radius=radius,
        f_cl=f_cl, control=control, h=h, roa_margin=roa_margin, setpoint=setpoint, W=W, info=info,
        contacts=plan, jump=jump, loop=loop_fn, loop_raw=loop_raw, windows=windows,
        boundaries=_boundaries(windows, schedule.phases if schedule else None, period, domain),
        hybrid=sys.events or schedule is not None, sampled=ctx.sampled, loop_u=loop_u,
    )


def _boundaries(windows, schedule, period, domain) -> tuple[float, ...]:
    """Clock times at which the safe set or the contact mode switches: the oracle steps onto each.

    For a periodic primitive they are taken within one period (the clock wraps); a transient's end
    t_f is one, so its rollouts stop exactly at t_f.
    """
    times = {v for w in windows if isinstance(w, tuple) for v in w}
    times |= {float(until) for until, _ in (schedule or [])}
    if domain is not None:
        times.add(float(domain[1]))
    if period is not None:
        times = {v % period for v in times}
    return tuple(sorted(times))


def _trot_setup(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, consts: dict) -> dict:
    """Speed, calibrated command, gains and the gait table's header of a trot controller."""
    from ..spec.paths import ReadProblem
    from .rigidbody.trot import check_quadruped, gains_of, gait_header, trot_inputs

    c = inst.spec.controller
    owner = f"primitive '{inst.name}'"
    check_quadruped(sys, ec)
    speed = ec.number(c.speed, ("controller", "speed"), consts, finite=True)
    out = {"speed": speed, "command": speed, "gait": None, "inputs": trot_inputs(c, sys, speed)}
    if c.gait is not None:
        where = inst.locate(("controller", "gait"))
        raw, path = spec_file(inst, c.gait, where, f"{owner}: controller.gait")
        if not path.is_file():
            raise SpecError("the gait table does not exist", location=where, key=f"{owner}: controller.gait",
                            expected="a table written by `mpgspec gait`", found=str(raw), code="MPG110",
                            hint="generate it with `mpgspec gait <project>/gaits.yaml`")
        try:
            head = gait_header(path)
        except ReadProblem as prob:
            raise SpecError(f"cannot read the gait table: {prob.message}", location=where,
                            key=f"{owner}: controller.gait", expected=prob.expected or "a table written by "
                            "`mpgspec gait`", found=f"{raw} ({prob.found})" if prob.found else raw,
                            code="MPG110") from None
        if head.get("inputs") != out["inputs"]:
            raise SpecError("the gait table is stale: it was generated for other settings", location=where,
                            key=f"{owner}: controller.gait", expected=f"inputs {out['inputs']}",
                            found=f"inputs {head.get('inputs')}", code="MPG110",
                            hint="regenerate it with `mpgspec gait <project>/gaits.yaml`")
        try:
            out["command"] = float(head["command"])
        except (KeyError, ValueError):
            raise SpecError("the gait table has no calibrated command", location=where,
                            key=f"{owner}: controller.gait", expected="a header line '# command: <m/s>'",
                            found=str(head.get("command")), code="MPG110") from None
        out["gait"] = {k: head[k] for k in head}
        out["gait_file"] = str(raw)
    out["gains"] = gains_of(c, out["command"])
    return out


def _schedule(inst: PrimitiveInstance, sys: CompiledSystem, trot: dict | None, period: float | None) -> Schedule | None:
    """The spec's contact schedule, or the one the trot's timing implies; None without either."""
    frames = tuple(sys.model.contact_frames) if sys.is_rigid_body else ()
    if trot is not None:
        return Schedule(tuple((u, tuple(f)) for u, f in trot["gains"].schedule(frames)), period, frames)
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


def spec_file(inst: PrimitiveInstance, raw: str, where, key: str):
    """(name, path) of a file a primitive names: `{<argument>}` takes the node's value (one file per
    node), and the path must stay inside the project folder or an allowed folder (spec.paths)."""
    from ..spec.paths import confine

    for k, v in inst.argument.items():
        raw = raw.replace("{" + k + "}", f"{v:g}")
    if not inst.roots:  # an instance built without the loader: no project folder known
        return raw, (inst.source.parent / raw).resolve()
    return raw, confine(raw, inst.source.parent, inst.roots, where=where, key=key)


def _samples_from_csv(inst: PrimitiveInstance, sys: CompiledSystem, contacts) -> tuple[np.ndarray, np.ndarray]:
    """Times and full-state samples of a setpoint table; states without a column take their default.

    The table must lie inside the project folder (or an allowed folder), be a regular UTF-8 file
    of at most MAX_FILE_BYTES and hold finite numbers; errors never echo more than a short piece
    of a line.
    """
    from ..spec.paths import MAX_FILE_BYTES, ReadProblem, clip, clip_repr, read_text_bounded

    where = inst.locate(("setpoint", "file"))
    key = f"primitive '{clip(inst.name, 60)}': setpoint.file"
    raw, path = spec_file(inst, inst.spec.setpoint.file, where, key)

    def fail(msg, expected, found, line=0):
        loc = where if not line else type(where)(str(path), line, 1)
        raise SpecError(msg, location=loc, key=key, expected=expected, found=found, code="MPG110")

    try:
        lines = ["" if ln.startswith("#") else ln for ln in read_text_bounded(path, MAX_FILE_BYTES).splitlines()]
    except ReadProblem as p:
        fail(f"cannot read the setpoint table: {p.message}", p.expected or "a CSV file relative to the spec",
             f"{clip_repr(raw)} ({p.found})" if p.found else clip_repr(raw))
    first = next((k for k, ln in enumerate(lines) if ln.strip()), len(lines))  # after `# key: value` lines
    header = [h.strip() for h in lines[first].split(",")] if first < len(lines) else []
    if not header or header[0] != "t":
        fail("the first column must be the time", "a header 't,<state>,...'",
             clip_repr(lines[first] if first < len(lines) else ""), first + 1)
    unknown = [h for h in header[1:] if h not in sys.state_names]
    if unknown:
        fail("unknown state in the header", "state names of the system", clip_repr(unknown[0]), first + 1)
    rows = []
    for n, text in enumerate(lines[first + 1:], start=first + 2):
        if not text.strip():
            continue
        try:
            vals = [float(v) for v in text.split(",")]
        except ValueError:
            fail("not a number", "numbers separated by commas", repr(text[:60]), n)
        if not all(np.isfinite(vals)):
            fail("not a finite number", "finite numbers (no nan or inf)", repr(text[:60]), n)
        if len(vals) != len(header):
            fail("wrong number of columns", f"{len(header)}", f"{len(vals)}", n)
        rows.append(vals)
    data = np.asarray(rows, float).reshape(-1, len(header))
    if data.shape[0] < 2 or np.any(np.diff(data[:, 0]) <= 0):
        fail("times must be strictly increasing, with at least two rows", "increasing t", f"{data.shape[0]} rows")
    ys = np.tile(sys.default_state(contacts), (data.shape[0], 1))
    for j, name in enumerate(header[1:], start=1):
        ys[:, sys.state_names.index(name)] = data[:, j]
    return data[:, 0], ys


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


TABLE_KNOTS = 64
"""Tabulated setpoints with more samples than this are evaluated by a linear lookup (CasADi's
interpolant) in an MX Function instead of an SX expression tree."""


def _table_setpoint(name: str, ts: np.ndarray, ys: np.ndarray, interpolation: str, period) -> ca.Function:
    """t -> x*(t) from a table by linear lookup, held outside its range, wrapped into one period."""
    if interpolation != "linear":
        ts_f = np.linspace(ts[0], ts[-1], 8 * len(ts))  # cubic tables: sampled densely, then linear
        from scipy.interpolate import CubicSpline

        ys, ts = CubicSpline(ts, ys, axis=0)(ts_f), ts_f
    lookup = ca.interpolant(name + "_lookup", "linear", [np.asarray(ts, float)],
                            np.asarray(ys, float).ravel(order="C"))
    t = ca.MX.sym("t")
    tc = wrap_clock(t, period)
    return ca.Function(name, [t], [lookup(ca.fmin(ca.fmax(tc, float(ts[0])), float(ts[-1])))])
