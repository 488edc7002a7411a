"""Control laws k(x, t) of a primitive compiled to CasADi: expression, PD on outputs (with the
cubic motion profile of eq. 7) and LQR from the linearisation at a fixed setpoint."""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.linalg

from ..errors import CompileError, SpecError
from ..spec.models import ExpressionController, LQRController, PDController
from .exprs import ExprCompiler
from .system import CompiledSystem


@dataclass
class ControlContext:
    """Symbols available to a control law."""

    sys: CompiledSystem
    t: ca.SX  # primitive clock
    s: ca.SX  # time since switch-in
    x_sw: ca.SX  # state at switch-in
    x_star: ca.SX  # x*(t)
    x_star_dot: ca.SX  # d/dt x*(t)
    x_star_fn: ca.Function  # t -> x*(t)
    env: dict
    ec: ExprCompiler
    fixed: bool
    xdot: ca.SX | None = None  # open-loop xdot(x, u) of the primitive's dynamics mode
    contacts: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)


def cubic_profile(s, duration: float, p0, v0, pf, vf):
    """Eq. (7): cubic from (p0, v0) at s = 0 to (pf, vf) at s = duration; held outside [0, duration]."""
    th = duration
    c0, c1 = p0, v0
    c2 = (3 * (pf - p0) - (2 * v0 + vf) * th) / th**2
    c3 = (2 * (p0 - pf) + (v0 + vf) * th) / th**3
    sc = ca.fmin(ca.fmax(s, 0), th)
    pos = c0 + c1 * sc + c2 * sc**2 + c3 * sc**3
    vel = c1 + 2 * c2 * sc + 3 * c3 * sc**2
    after = s > th
    return ca.if_else(after, pf, pos), ca.if_else(after, vf, vel)


def _matrix(v, n: int, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 1:
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"{what} must be {n} numbers (diagonal) or a {n}x{n} matrix; got shape {a.shape}")
    return a


def expression_law(c: ExpressionController, ctx: ControlContext) -> ca.SX:
    if len(c.u) != ctx.sys.nu:
        raise SpecError("one expression per input is needed", location=ctx.ec.locate(("controller", "u")),
                        key=f"{ctx.ec.owner}: controller.u", expected=f"{ctx.sys.nu}", found=f"{len(c.u)}",
                        code="MPG106")
    return ctx.ec.vector(c.u, ("controller", "u"), ctx.env)


def pd_law(c: PDController, ctx: ControlContext) -> ca.SX:
    """u = B_y(-Kp (y - y_d) - Kd (ydot - ydot_d)) + ff, ydot = dy/dx * xdot(x, 0) (outputs of positions)."""
    sys, x = ctx.sys, ctx.sys.x
    y = ctx.ec.vector(c.outputs, ("controller", "outputs"), ctx.env)
    ny = y.shape[0]
    Jy = ca.jacobian(y, x)
    xdot = sys.xdot if ctx.xdot is None else ctx.xdot
    drift = ca.substitute(xdot, sys.u, ca.DM.zeros(sys.nu)) if sys.nu else xdot
    ydot = ca.mtimes(Jy, drift)
    y_of = ca.Function("y", [x], [y, ydot])
    yd, yd_dot = y_of(ctx.x_star)
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
        u = u + sys.static_torque(ctx.contacts)
    return u


def _task_jacobian(sys: CompiledSystem, ydot: ca.SX, xdot: ca.SX) -> ca.SX:
    """J_y: how the inputs' own coordinates move the outputs (rigid bodies: d ydot / d(actuated joint rates));
    for other systems d ydot / dx times d xdot / du."""
    if sys.is_rigid_body:
        m = sys.model
        v_act = sys.x[m.nq + m.n_base:]
        return ca.jacobian(ydot, v_act)
    return ca.mtimes(ca.jacobian(ydot, sys.x), ca.jacobian(xdot, sys.u))


def lqr_law(c: LQRController, ctx: ControlContext) -> ca.SX:
    """Continuous-time LQR at the fixed setpoint; K, u*, and closed-loop eigenvalues go to info."""
    sys = ctx.sys
    if not ctx.fixed:
        raise SpecError("LQR needs a fixed setpoint", location=ctx.ec.locate(("controller", "type")),
                        key=f"{ctx.ec.owner}: controller.type", expected="class: fixed", found="a time-varying setpoint",
                        code="MPG108")
    xs = np.array(ctx.x_star_fn(0.0)).ravel()
    try:
        Q = _matrix(c.Q, sys.nx, "Q")
        R = _matrix(c.R, sys.nu, "R")
    except ValueError as err:
        raise SpecError(str(err), location=ctx.ec.locate(("controller",)), key=f"{ctx.ec.owner}: controller",
                        code="MPG106") from None
    xdot = sys.xdot if ctx.xdot is None else ctx.xdot
    f = ca.Function("f", [sys.x, sys.u], [xdot])
    A_fn = ca.Function("A", [sys.x, sys.u], [ca.jacobian(xdot, sys.x), ca.jacobian(xdot, sys.u)])
    if c.u_eq is not None:
        env = {**ctx.env}
        us = np.array([ctx.ec.number(v, ("controller", "u_eq", i), {k: float(v2) for k, v2 in env.items()
                                                                      if isinstance(v2, (int, float))})
                       for i, v in enumerate(c.u_eq)])
    else:  # Gauss-Newton on xdot(x*, u) = 0
        us = np.zeros(sys.nu)
        for _ in range(20):
            r = np.array(f(xs, us)).ravel()
            B = np.array(A_fn(xs, us)[1])
            step, *_ = np.linalg.lstsq(B, -r, rcond=None)
            us = us + step
            if np.linalg.norm(step) < 1e-12:
                break
    resid = float(np.linalg.norm(np.array(f(xs, us)).ravel()))
    A, B = (np.array(m) for m in A_fn(xs, us))
    try:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as err:
        raise CompileError(f"{ctx.ec.owner}: LQR Riccati equation has no stabilising solution ({err})") from None
    K = np.linalg.solve(R, B.T @ P)
    ctx.info["lqr"] = {
        "K": K.tolist(),
        "u_eq": us.tolist(),
        "equilibrium_residual": resid,
        "closed_loop_eigenvalues": [[float(z.real), float(z.imag)] for z in np.linalg.eigvals(A - B @ K)],
    }
    dx = sys.wrapped_error(sys.x - ctx.x_star)
    return ca.DM(us) - ca.mtimes(ca.DM(K), dx)


def idqp(c, ctx: ControlContext):
    from .rigidbody.idqp import idqp_law

    return idqp_law(c, ctx)


LAWS = {"expression": expression_law, "pd": pd_law, "lqr": lqr_law, "id_qp": idqp}
