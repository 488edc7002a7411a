"""The inverse-dynamics QP of the paper's Stand primitive, as a control law k(x, t).

Decision variables X_ext = [qddot (nv), u (nu), lam (3 per foot)]; qddot is eliminated with the
dynamics, qddot = D^-1 (B u + J^T lam - H), so the QP runs over [u; lam] alone. Objective: track
a CoM acceleration a_d = yddot_d - Kp (com - y_d) - Kd (comdot - ydot_d), where y_d is the cubic
motion profile (eq. 7) from the CoM at switch-in to the CoM of the setpoint, plus a
joint-posture task (towards the setpoint's joints, or with `posture_profile` along a cubic from the
joints at switch-in, at rest, to them) and a regulariser sigma (||qddot||^2 + ||u||^2 + ||lam||^2). Constraints:
J qddot + Jdot v = gamma (the same Baumgarte target as the plant), u in U, and lam in an inner
friction pyramid |lam_x|, |lam_y| <= mu / sqrt(2) lam_z, lam_z >= f_min, where mu is the system's
coefficient or a lower design one (`friction`): the pyramid's corners touch the cone of its mu, so
forces designed for the plant's own mu keep no margin where the QP saturates them.

With `ki`, integral action: the law's memory carries the CoM error integrated over its solves (one
control period each, clipped so that ki times it stays within `ki_limit`), and a_d gains ki times it,
so a mass or motor error that would sag the stance settles at the setpoint. The integral starts at 0
at switch-in and at x*, where the error is 0, stays there: the nominal closed loop is unchanged.

The QP is solved with CasADi's active-set solver qrqp, which can be code-generated, so it runs
inside the jit-compiled oracle. Control rate: the oracle solves it at `rate` (default: at every
oracle step's start) and holds the torques in between, each solve warm-started from the previous
solution, whose multipliers give qrqp its initial active set (compile/hold.py). The continuous
law k(x, t, s, x_sw) (a cold solve at every call) is what f_cl, h and the checks that take
derivatives of the closed loop see.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import SpecError
from ..laws.base import ControlContext, cubic_profile
from ..hold import SampledLaw, warm_or_cold
from .linalg import dense_ldl_solve, dof_parents, scale_rows, tree_ldl, tree_solve_l, tree_solve_lt


def _profile_acc(s, duration, p0, v0, pf, vf):
    """Position, velocity and acceleration of the cubic profile at time s."""
    pos, vel = cubic_profile(s, duration, p0, v0, pf, vf)
    th = duration
    c2 = (3 * (pf - p0) - (2 * v0 + vf) * th) / th**2
    c3 = (2 * (p0 - pf) + (v0 + vf) * th) / th**3
    acc = ca.if_else(ca.logic_and(s >= 0, s <= th), 2 * c2 + 6 * c3 * s, ca.DM.zeros(p0.shape[0]))
    return pos, vel, acc


def _com_target(sys, x, com, x_sw, x_star):
    """The CoM goal: the setpoint's CoM height, and its horizontal place relative to the feet
    carried to where the feet stand at switch-in (rotated by the trunk's yaw then). On flat
    ground Stand is so invariant under the ground symmetry (x, y, yaw) that E leaves free; the
    setpoint's absolute x, y would pull a robot that walked away back across the floor."""
    feet = sys.model.contact_frames
    if not feet or not sys.model.n_base:
        return ca.Function("com_abs", [x], [com])(x_star)
    cx = sum(sys.extra_env[f"{f}_x"] for f in feet) / len(feet)
    cy = sum(sys.extra_env[f"{f}_y"] for f in feet) / len(feet)
    qx, qy, qz, qw = (x[i] for i in range(3, 7))
    yaw = ca.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2))
    geo = ca.Function("feet_com", [x], [ca.vertcat(cx, cy), com, yaw])
    c_sw, _, yaw_sw = geo(x_sw)
    c_st, com_st, yaw_st = geo(x_star)
    d = yaw_sw - yaw_st
    R = ca.vertcat(ca.horzcat(ca.cos(d), -ca.sin(d)), ca.horzcat(ca.sin(d), ca.cos(d)))
    return ca.vertcat(c_sw + ca.mtimes(R, com_st[:2] - c_st), com_st[2])


def idqp_law(c, ctx: ControlContext) -> ca.Function:
    """k(x, t, s, x_sw) = the torque part of the ID-QP solution, as a Function callable in MX."""
    sys = ctx.sys
    if not sys.is_rigid_body:
        raise SpecError("the ID-QP needs a rigid-body system", location=ctx.ec.locate(("controller", "type")),
                        key=f"{ctx.ec.owner}: controller.type", expected="system kind rigid_body",
                        found="an analytic system", code="MPG108")
    if c.friction is not None and c.friction > sys.friction:
        raise SpecError("the ID-QP's design friction coefficient exceeds the system's: its forces would leave the "
                        "friction cone C judges", location=ctx.ec.locate(("controller", "friction")),
                        key=f"{ctx.ec.owner}: controller.friction", expected=f"at most the system's friction "
                        f"{sys.friction:g}", found=f"{c.friction:g}", code="MPG104")
    if c.ki is not None and c.rate is None:
        raise SpecError("the ID-QP's integral action needs a control rate", location=ctx.ec.locate(("controller", "ki")),
                        key=f"{ctx.ec.owner}: controller.rate", expected="a rate (Hz): the integral advances once per "
                        "solve", found="no rate", code="MPG104")
    integ = ca.SX.sym("com_integral", 3) if c.ki is not None else None
    qp = _qp(c, ctx, integ)
    X, solve, nws, na = _warm_solve(c, qp, [sys.x, ctx.t, ctx.s, ctx.x_sw], integ)
    where = ("controller", "rate") if c.rate is not None else ("controller", "type")
    ctx.sampled = SampledLaw(1.0 / c.rate if c.rate is not None else None, solve, nws, ctx.ec.locate(where),
                             f"{ctx.ec.owner}: controller.rate")
    ctx.info["id_qp"] = {"solver": "qrqp", "variables": qp.nw, "constraints": na,
                         "control_rate": ctx.sampled.describe(), "warm_start": bool(c.warm_start),
                         **({"integral_gain": [float(k) for k in c.ki]} if c.ki is not None else {})}
    return ca.Function("k_idqp", X, [solve(*X, ca.DM.zeros(nws))[0]])


@dataclass
class _QP:
    """min 1/2 w^T H w + g^T w s.t. lba <= A w <= uba, lbx <= w <= ubx over w = [u; lam], with the
    optimum w_eq when no inequality is active and ok = 1 when that is the optimum."""

    H: ca.SX
    g: ca.SX
    A: ca.SX
    lba: ca.SX
    uba: ca.SX
    lbx: np.ndarray
    ubx: np.ndarray
    w_eq: ca.SX
    ok: ca.SX
    nw: int
    nu: int
    err: ca.SX  # the CoM error y_d - com, which integral action integrates


def _contact_rows(sys, contacts, q, v):
    """D(q), H(q, v), the contact Jacobian J, its drift Jdot v and the Baumgarte target gamma."""
    dyn = sys.dyn
    sub = lambda e: ca.substitute(e, ca.vertcat(dyn.q, dyn.v), ca.vertcat(q, v))  # noqa: E731
    M, H = sub(dyn.M_expr), sub(dyn.nle_expr)  # D(q), H(q, v)
    J, drift = sub(dyn.contact_jacobian_expr(contacts)), sub(dyn.contact_drift_expr(contacts))
    gamma = -2 * sys.baumgarte.alpha * ca.mtimes(J, v)
    if J.shape[0]:
        heights = ca.vertcat(*[ca.vertcat(0, 0, sys.extra_env[f"{f}_z"]) for f in contacts])
        gamma = gamma - sys.baumgarte.beta**2 * heights
    return M, H, J, drift, gamma


def _tasks(c, ctx: ControlContext, q, v, integ=None):
    """The CoM task (Jc qddot + drift_c = a_d along the cubic profile, with ki times the integral `integ` of
    its error when given), the posture task S qddot = a_post and the CoM error y_d - com."""
    sys, x = ctx.sys, ctx.sys.x
    nq, nv, nu = sys.model.nq, sys.model.nv, sys.model.nu
    qd = sys.xdot[:nq]  # qdot(q, v), linear in v
    com = ca.vertcat(*[sys.extra_env[f"com_{a}"] for a in "xyz"])
    comdot = ca.jtimes(com, q, qd)
    Jc = ca.jacobian(comdot, v)
    drift_c = ca.jtimes(comdot, q, qd)
    com_fn = ca.Function("com", [x], [com, comdot])
    y0, y0dot = com_fn(ctx.x_sw)
    yf = _com_target(sys, x, com, ctx.x_sw, ctx.x_star)
    kp, kd = ca.DM(c.kp), ca.DM(c.kd)
    yd, yd_dot, yd_acc = _profile_acc(ctx.s, c.profile_duration, y0, y0dot, yf, ca.DM.zeros(3))
    a_d = yd_acc - kp * (com - yd) - kd * (comdot - yd_dot)
    if integ is not None:
        a_d = a_d + ca.DM(c.ki) * integ
    S = ca.DM(np.hstack([np.zeros((nu, nv - nu)), np.eye(nu)]))
    qj, qj_star = x[nq - nu:nq], ctx.x_star[nq - nu:nq]
    vj = ca.mtimes(S, v)
    if c.posture_profile:  # from the joints at switch-in, at rest: a leg's motion at the switch is damped, not carried on
        zero = ca.DM.zeros(nu)
        pd_, pd_dot, pd_acc = _profile_acc(ctx.s, c.profile_duration, ctx.x_sw[nq - nu:nq], zero, qj_star, zero)
        a_post = pd_acc - c.posture_kp * (qj - pd_) - c.posture_kd * (vj - pd_dot)
    else:
        a_post = -c.posture_kp * (qj - qj_star) - c.posture_kd * vj
    return Jc, drift_c, a_d, S, a_post, yd - com


def _qp(c, ctx: ControlContext, integ=None) -> _QP:
    """The QP over [u; lam]: qddot = D^-1 (B u + J^T lam - H) = Aq w + bq eliminated, the contact
    rows as equalities, u in U and lam in the inner friction pyramid."""
    sys = ctx.sys
    m = sys.model
    nq, nv, nu = m.nq, m.nv, m.nu
    q, v = sys.x[:nq], sys.x[nq:nq + nv]  # contact flags and event clocks may follow
    M, H, J, drift, gamma = _contact_rows(sys, ctx.plan.feet, q, v)
    nc = J.shape[0]
    Jc, drift_c, a_d, S, a_post, err = _tasks(c, ctx, q, v, integ)
    B = ca.DM(m.actuation_matrix)
    parents = dof_parents(m)
    L, Dg = tree_ldl(M, parents)

    def solve_D(rhs):
        return tree_solve_l(L, parents, scale_rows(Dg, tree_solve_lt(L, parents, rhs)))

    Aq = solve_D(ca.horzcat(B, J.T))
    bq = -solve_D(H)
    nw = nu + nc
    Q = ca.mtimes(Jc.T, Jc) + c.posture_weight * ca.mtimes(S.T, S) + c.regularization * ca.DM.eye(nv)
    Hqp = 2 * (ca.mtimes([Aq.T, Q, Aq]) + c.regularization * ca.DM.eye(nw))
    gqp = 2 * ca.mtimes(Aq.T, ca.mtimes(Q, bq) - ca.mtimes(Jc.T, a_d - drift_c) - c.posture_weight * ca.mtimes(S.T, a_post))
    A_con = ca.mtimes(J, Aq)
    con = gamma - drift - ca.mtimes(J, bq)
    mu = sys.friction if c.friction is None else c.friction  # the design coefficient: a margin below the plant's
    A_fc = _friction_pyramid(mu / np.sqrt(2.0), nu, nc)
    A = ca.vertcat(A_con, A_fc)
    lba = ca.vertcat(con, -np.inf * ca.DM.ones(A_fc.shape[0]))
    uba = ca.vertcat(con, ca.DM.zeros(A_fc.shape[0]))
    lbx = np.full(nw, -np.inf)
    ubx = np.full(nw, np.inf)
    lbx[:nu], ubx[:nu] = sys.u_lo, sys.u_hi
    lbx[nu + 2::3] = c.f_min
    w_eq, ok = _no_inequality_active(Aq, Q, c.regularization, gqp, A_con, con, A_fc, lbx, ubx, nu)
    return _QP(Hqp, gqp, A, lba, uba, lbx, ubx, w_eq, ok, nw, nu, err)


def _friction_pyramid(mu: float, nu: int, nc: int) -> ca.DM:
    """Rows of |lam_x|, |lam_y| <= mu lam_z per foot, as A_fc w <= 0 over w = [u; lam]."""
    nw = nu + nc
    rows = []
    for k in range(nc // 3):
        for ax in (0, 1):
            for sign in (1, -1):
                r = np.zeros(nw)
                r[nu + 3 * k + ax] = sign
                r[nu + 3 * k + 2] = -mu
                rows.append(r)
    return ca.DM(np.array(rows)) if rows else ca.DM(0, nw)


def _warm_solve(c, qp: _QP, args: list, integ=None):
    """(X, solve, nws, na): solve(x, t, s, x_sw, w) -> (u, w_next) by qrqp warm-started from w (the
    previous solution and its multipliers), or the shortcut w_eq when no inequality is active; nws entries
    of w. With integral action (`integ`, the QP's data depending on it) w ends with the integral, advanced
    by one control period of the CoM error (an output of the data) and clipped at ki_limit / ki."""
    nw = qp.nw
    ni = 0 if integ is None else 3
    data = ca.Function("idqp_data", args + ([integ] if ni else []),
                       [ca.densify(qp.H), qp.g, ca.densify(qp.A), qp.lba, qp.uba, qp.w_eq, qp.ok]
                       + ([qp.err] if ni else []))
    solver = ca.conic("idqp", "qrqp", {"h": ca.Sparsity.dense(nw, nw), "a": ca.Sparsity.dense(qp.A.shape[0], nw)},
                      {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False,
                       "max_iter": c.max_iter})
    na = int(qp.A.shape[0])
    nws = 2 * nw + na if c.warm_start else 0  # [X_ext; lam_x; lam_a] of the previous solve
    # the QP's data, the warm start and the shortcut's solution; qrqp runs only when the shortcut fails
    P = [ca.MX.sym(n, data.sparsity_out(i)) for i, n in enumerate(("H", "g", "A", "lba", "uba", "w_eq"))]
    W = ca.MX.sym("w", nws)
    warm = dict(x0=W[:nw], lam_x0=W[nw:2 * nw], lam_a0=W[2 * nw:]) if nws else {}
    sol = solver(h=P[0], g=P[1], a=P[2], lba=P[3], uba=P[4], lbx=qp.lbx, ubx=qp.ubx, **warm)
    active_set = ca.Function("idqp_active_set", P + [W],
                             [sol["x"], ca.vertcat(sol["x"], sol["lam_x"], sol["lam_a"]) if nws else W])
    shortcut = ca.Function("idqp_shortcut", P + [W], [P[5], ca.vertcat(P[5], ca.DM.zeros(nw + na)) if nws else W])
    path = ca.Function.if_else("idqp_path", shortcut, active_set)
    X = [ca.MX.sym(n, *a.shape) for n, a in zip(("x", "t", "s", "x_sw"), args)]
    Xw = ca.MX.sym("w", nws + ni)
    Wq, I = Xw[:nws], Xw[nws:]
    out = data(*X, I) if ni else data(*X)
    w_sol, w_next = path(out[6], *out[:6], Wq)
    w_next = warm_or_cold(w_next) if nws else Wq
    if ni:  # one control period of the CoM error, clipped where ki I would pass ki_limit (no limit where ki = 0)
        cap = ca.DM([c.ki_limit / k if k > 0 else 0.0 for k in c.ki])
        I_next = ca.fmin(ca.fmax(I + out[7] / c.rate, -cap), cap)
        w_next = ca.vertcat(w_next, warm_or_cold(I_next))
    solve = ca.Function("k_idqp_warm", X + [Xw], [w_sol[:qp.nu], w_next], ["x", "t", "s", "x_sw", "w"], ["u", "w_next"])
    return X, solve, nws + ni, na


def _no_inequality_active(Aq, Q, sigma: float, gqp, A_con, con, A_fc, lbx, ubx, nu: int):
    """The QP's optimum when no inequality is active, and 1 when it satisfies them all (it is then
    the optimum: the inequality multipliers are zero), else 0.

    The contact rows fix lam given u: G lam = con - P u with [P, G] = A_con (G = J D^-1 J^T), so
    w = w0 + T u with T = [I; L_u], and the equality-constrained QP is an SPD system in u alone.
    """
    nw = A_con.shape[1]
    P, G = A_con[:, :nu], A_con[:, nu:]
    if G.shape[0]:
        sol = dense_ldl_solve(G, ca.horzcat(con, -P))
        lam0, L_u = sol[:, 0], sol[:, 1:]
    else:
        lam0, L_u = ca.SX(0, 1), ca.SX(0, nu)
    T = ca.vertcat(ca.SX.eye(nu), L_u)
    w0 = ca.vertcat(ca.SX.zeros(nu), lam0)
    AT, Aw0 = ca.mtimes(Aq, T), ca.mtimes(Aq, w0)
    Hr = 2 * (ca.mtimes([AT.T, Q, AT]) + sigma * ca.mtimes(T.T, T))
    gr = ca.mtimes(T.T, 2 * (ca.mtimes([Aq.T, Q, Aw0]) + sigma * w0) + gqp)
    w = w0 + ca.mtimes(T, -dense_ldl_solve(Hr, gr))
    lo, hi = np.flatnonzero(np.isfinite(lbx)).tolist(), np.flatnonzero(np.isfinite(ubx)).tolist()
    slack = ca.vertcat(w[lo] - ca.DM(lbx[lo]), ca.DM(ubx[hi]) - w[hi], -ca.mtimes(A_fc, w))
    ok = ca.sum1(slack >= 0) + ca.sum1(ca.fabs(w) < ca.inf) == slack.shape[0] + nw  # NaN fails both
    return w, ok
