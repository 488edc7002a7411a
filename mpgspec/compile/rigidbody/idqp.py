"""The inverse-dynamics QP of the paper's Stand primitive, as a control law k(x, t).

Decision variables X_ext = [qddot (nv), u (nu), lam (3 per foot)]; qddot is eliminated with the
dynamics, qddot = D^-1 (B u + J^T lam - H), so the QP runs over [u; lam] alone. Objective: track
a CoM acceleration a_d = yddot_d - Kp (com - y_d) - Kd (comdot - ydot_d), where y_d is the cubic
motion profile (eq. 7) from the CoM at switch-in to the CoM of the setpoint, plus a light
joint-posture task and a regulariser sigma (||qddot||^2 + ||u||^2 + ||lam||^2). Constraints:
J qddot + Jdot v = gamma (the same Baumgarte target as the plant), u in U, and lam in an inner
friction pyramid |lam_x|, |lam_y| <= mu / sqrt(2) lam_z, lam_z >= 0.

The QP is solved with CasADi's active-set solver qrqp, which can be code-generated, so it runs
inside the jit-compiled oracle. Control rate: the QP is solved afresh at every Runge-Kutta stage
(continuous-time control; four solves per integration step).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ...errors import SpecError
from ..controllers import ControlContext, cubic_profile
from .linalg import dof_parents, scale_rows, tree_ldl, tree_solve_l, tree_solve_lt


def _profile_acc(s, duration, p0, v0, pf, vf):
    """Position, velocity and acceleration of the cubic profile at time s."""
    pos, vel = cubic_profile(s, duration, p0, v0, pf, vf)
    th = duration
    c2 = (3 * (pf - p0) - (2 * v0 + vf) * th) / th**2
    c3 = (2 * (p0 - pf) + (v0 + vf) * th) / th**3
    acc = ca.if_else(ca.logic_and(s >= 0, s <= th), 2 * c2 + 6 * c3 * s, ca.DM.zeros(p0.shape[0]))
    return pos, vel, acc


def idqp_law(c, ctx: ControlContext) -> ca.Function:
    """k(x, t, s, x_sw) = the torque part of the ID-QP solution, as a Function callable in MX."""
    sys = ctx.sys
    if not sys.is_rigid_body:
        raise SpecError("the ID-QP needs a rigid-body system", location=ctx.ec.locate(("controller", "type")),
                        key=f"{ctx.ec.owner}: controller.type", expected="system kind rigid_body",
                        found="an analytic system", code="MPG108")
    m, dyn = sys.model, sys.dyn
    nq, nv, nu = m.nq, m.nv, m.nu
    x, contacts = sys.x, ctx.contacts
    q, v = x[:nq], x[nq:]
    sub = lambda e: ca.substitute(e, ca.vertcat(dyn.q, dyn.v), ca.vertcat(q, v))  # noqa: E731
    M, H = sub(dyn.M_expr), sub(dyn.nle_expr)  # D(q), H(q, v)
    J, drift = sub(dyn.contact_jacobian_expr(contacts)), sub(dyn.contact_drift_expr(contacts))
    nc = J.shape[0]
    gamma = -2 * sys.baumgarte.alpha * ca.mtimes(J, v)
    if nc:
        heights = ca.vertcat(*[ca.vertcat(0, 0, sys.extra_env[f"{f}_z"]) for f in contacts])
        gamma = gamma - sys.baumgarte.beta**2 * heights
    qd = sys.xdot[:nq]  # qdot(q, v), linear in v
    com = ca.vertcat(*[sys.extra_env[f"com_{a}"] for a in "xyz"])
    comdot = ca.jtimes(com, q, qd)
    Jc = ca.jacobian(comdot, v)
    drift_c = ca.jtimes(comdot, q, qd)
    com_fn = ca.Function("com", [x], [com, comdot])
    y0, y0dot = com_fn(ctx.x_sw)
    yf, _ = com_fn(ctx.x_star)
    kp, kd = ca.DM(c.kp), ca.DM(c.kd)
    yd, yd_dot, yd_acc = _profile_acc(ctx.s, c.profile_duration, y0, y0dot, yf, ca.DM.zeros(3))
    a_d = yd_acc - kp * (com - yd) - kd * (comdot - yd_dot)
    S = ca.DM(np.hstack([np.zeros((nu, nv - nu)), np.eye(nu)]))
    qj, qj_star = x[nq - nu:nq], ctx.x_star[nq - nu:nq]
    a_post = -c.posture_kp * (qj - qj_star) - c.posture_kd * ca.mtimes(S, v)
    # qddot is eliminated with the dynamics: qddot = D^-1 (B u + J^T lam - H) = Aq w + bq, w = [u; lam]
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
    mu = sys.friction / np.sqrt(2.0)
    rows = []
    for k in range(nc // 3):
        for ax in (0, 1):
            for sign in (1, -1):
                r = np.zeros(nw)
                r[nu + 3 * k + ax] = sign
                r[nu + 3 * k + 2] = -mu
                rows.append(r)
    A_fc = ca.DM(np.array(rows)) if rows else ca.DM(0, nw)
    A = ca.vertcat(A_con, A_fc)
    lba = ca.vertcat(con, -np.inf * ca.DM.ones(A_fc.shape[0]))
    uba = ca.vertcat(con, ca.DM.zeros(A_fc.shape[0]))
    lbx = np.full(nw, -np.inf)
    ubx = np.full(nw, np.inf)
    lbx[:nu], ubx[:nu] = sys.u_lo, sys.u_hi
    lbx[nu + 2::3] = 0.0
    args = [x, ctx.t, ctx.s, ctx.x_sw]
    data = ca.Function("idqp_data", args, [ca.densify(Hqp), gqp, ca.densify(A), lba, uba])
    solver = ca.conic("idqp", "qrqp", {"h": ca.Sparsity.dense(nw, nw), "a": ca.Sparsity.dense(A.shape[0], nw)},
                      {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False,
                       "max_iter": c.max_iter})
    X = [ca.MX.sym(n, *a.shape) for n, a in zip(("x", "t", "s", "x_sw"), args)]
    Hm, gm, Am, lbam, ubam = data(*X)
    sol = solver(h=Hm, g=gm, a=Am, lba=lbam, uba=ubam, lbx=lbx, ubx=ubx)
    ctx.info["id_qp"] = {"solver": "qrqp", "variables": nw, "constraints": int(A.shape[0]),
                         "control_rate": "every Runge-Kutta stage"}
    return ca.Function("k_idqp", X, [sol["x"][:nu]])
