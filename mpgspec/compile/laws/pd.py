"""PD on outputs y(x) (paper eq. 8), optionally along the cubic motion profile of eq. (7)."""
from __future__ import annotations

import casadi as ca

from ...errors import SpecError
from ...spec.controllers import PDController
from ..system import CompiledSystem
from .base import ControlContext, cubic_profile


def pd_law(c: PDController, ctx: ControlContext) -> ca.SX:
    """u = B_y(-Kp (y - y_d) - Kd (ydot - ydot_d)) + ff, ydot = dy/dx * xdot(x, 0) (outputs of positions)."""
    sys, x = ctx.sys, ctx.sys.x
    y = ctx.ec.vector(c.outputs, ("controller", "outputs"), ctx.env)
    for i in range(y.shape[0]):  # y(x): the clock, s, inputs or setpoint symbols have no place here
        free = [v.name() for v in ca.symvar(y[i]) if not ca.depends_on(x, v)]
        if free:
            raise SpecError("an output may depend only on the state", location=ctx.ec.locate(("controller", "outputs", i)),
                            key=f"{ctx.ec.owner}: controller.outputs.{i}",
                            expected="an expression of states, parameters and constants",
                            found=f"{str(c.outputs[i])[:60]!r} names {', '.join(sorted(set(free)))}", code="MPG106",
                            hint="the desired output comes from the setpoint; use feedforward for time-varying terms")
    ny = y.shape[0]
    Jy = ca.jacobian(y, x)
    xdot = sys.xdot if ctx.xdot is None else ctx.xdot
    drift = ca.substitute(xdot, sys.u, ca.DM.zeros(sys.nu)) if sys.nu else xdot
    ydot = ca.mtimes(Jy, drift)
    y_of = ca.Function("y", [x], [y, ydot])
    yd, yd_dot = y_of(ctx.x_star)
    if c.target is not None:
        yd, yd_dot = ca.DM(c.target), ca.DM.zeros(ny)
    if c.profile is not None:
        y0, y0_dot = y_of(ctx.x_sw)
        yd, yd_dot = cubic_profile(ctx.s, c.profile.duration, y0, y0_dot, yd, yd_dot)
    e = y - yd
    out_states = [sys.state_names.index(o) if isinstance(o, str) and o in sys.state_names else -1 for o in c.outputs]
    e = ca.vertcat(*[
        (e[i] - sys.wrap[j] * ca.floor((e[i] + sys.wrap[j] / 2) / sys.wrap[j])) if j >= 0 and sys.wrap[j] > 0 else e[i]
        for i, j in enumerate(out_states)
    ])
    v = -ca.mtimes(ca.diag(ca.DM(c.kp)), e) - ca.mtimes(ca.diag(ca.DM(c.kd)), ydot - yd_dot)
    if c.input_map == "jacobian_transpose":
        By = _task_jacobian(sys, ydot, xdot).T
    elif c.input_map is not None:
        By = ca.DM(c.input_map)
        if By.shape != (sys.nu, ny):
            raise SpecError("input_map must be inputs x outputs", location=ctx.ec.locate(("controller", "input_map")),
                            key=f"{ctx.ec.owner}: controller.input_map", expected=f"{sys.nu}x{ny}",
                            found=f"{By.shape[0]}x{By.shape[1]}", code="MPG106")
    elif ny == sys.nu:
        By = ca.DM.eye(ny)
    else:
        raise SpecError("outputs and inputs differ in number; give input_map", location=ctx.ec.locate(("controller",)),
                        key=f"{ctx.ec.owner}: controller.input_map", expected=f"{sys.nu} outputs or an input_map",
                        found=f"{ny} outputs", code="MPG106")
    u = ca.mtimes(By, v)
    if c.feedforward is not None:
        u = u + ctx.ec.vector(c.feedforward, ("controller", "feedforward"), ctx.env)
    if c.gravity_compensation:
        if not sys.is_rigid_body:
            raise SpecError("gravity compensation needs a rigid-body system",
                            location=ctx.ec.locate(("controller", "gravity_compensation")),
                            key=f"{ctx.ec.owner}: controller.gravity_compensation", expected="system kind rigid_body",
                            found="an analytic system", code="MPG108")
        u = u + sys.static_torque(ctx.plan.feet)
    if c.limit is not None:
        u = _limited(u, c.limit, sys, ctx)
    return u


def _limited(u: ca.SX, limit, sys: CompiledSystem, ctx: ControlContext) -> ca.SX:
    """u clamped to [-limit, limit] per input: the law's own bound, inside the actuators' U."""
    lim = [float(limit)] * sys.nu if not isinstance(limit, list) else [float(v) for v in limit]
    if len(lim) != sys.nu:
        raise SpecError("limit needs one number, or one per input", location=ctx.ec.locate(("controller", "limit")),
                        key=f"{ctx.ec.owner}: controller.limit", expected=f"1 or {sys.nu} values",
                        found=f"{len(lim)} values", code="MPG106")
    lim_dm = ca.DM(lim)
    return ca.fmin(ca.fmax(u, -lim_dm), lim_dm)


def _task_jacobian(sys: CompiledSystem, ydot: ca.SX, xdot: ca.SX) -> ca.SX:
    """J_y: how the inputs' own coordinates move the outputs (rigid bodies: d ydot / d(actuated joint rates));
    for other systems d ydot / dx times d xdot / du."""
    if sys.is_rigid_body:
        m = sys.model
        v_act = sys.x[m.nq + m.n_base:m.nq + m.nv]
        return ca.jacobian(ydot, v_act)
    return ca.mtimes(ca.jacobian(ydot, sys.x), ca.jacobian(xdot, sys.u))
