"""Contact events: the contact set as part of the state, with touchdown, lift-off and impacts.

With `contact_events: true` the state gains one flag per contact frame, c_i in {0, 1}, constant
in continuous time. The dynamics enforce the contact rows of feet with c_i = 1 only: inactive
rows are masked out of J and given a unit diagonal in the Schur complement, so their force is
zero. After every integration step the discrete part of the hybrid system runs:

- touchdown: a foot with c_i = 0 whose height reaches 0 while moving down gets c_i = 1, its leg
  puts it on the ground (touchdown_projection), and the plastic impact map
  v+ = v- - D^-1 Jn^T (Jn D^-1 Jn^T)^-1 Jn v- of the new contact set applies;
- lift-off: a foot with c_i = 1 whose normal force under the step's input is below 0 gets c_i = 0.

Events are detected at step boundaries (no event localisation): their time is known to one step.
After the flags the state holds the event clocks of compile/events.py (first touchdown: a foot
touches down; takeoff: the last foot in contact lifts off), which the same update records.
"""
from __future__ import annotations

import casadi as ca

from .linalg import dense_ldl_solve, dof_parents, scale_rows, tree_ldl, tree_solve_l, tree_solve_lt


def _mask(c: ca.SX) -> ca.SX:
    return ca.vertcat(*[ca.vertcat(c[i], c[i], c[i]) for i in range(c.shape[0])])


def masked_contact_dynamics(sys, q: ca.SX, v: ca.SX, u: ca.SX, c: ca.SX, k=None, w=None) -> tuple[ca.SX, ca.SX]:
    """(a, lam) with the contact rows of feet whose flag is 0 switched off (their lam is 0).

    k scales every link's mass and inertia and w is an external generalized force (robust checks):
    k M a + k H = B u + w + J^T lam is the nominal system under (B u + w) / k, with lam k times its
    solution's."""
    dyn, m = sys.dyn, sys.model
    sub = lambda e: ca.substitute(e, ca.vertcat(dyn.q, dyn.v), ca.vertcat(q, v))  # noqa: E731
    parents = dof_parents(m)
    M, H = sub(dyn.M_expr), sub(dyn.nle_expr)
    J = sub(dyn.contact_jacobian_expr(m.contact_frames))
    drift = sub(dyn.contact_drift_expr(m.contact_frames))
    mask = _mask(c)
    heights = ca.vertcat(*[ca.vertcat(0, 0, sys.extra_env[f"{f}_z"]) for f in m.contact_frames])
    heights = ca.substitute(heights, sys.x[:m.nq], q)
    b = sys.baumgarte
    gamma = -2 * b.alpha * ca.mtimes(J, v) - b.beta**2 * heights
    Jm = ca.diag(mask) @ J
    L, D = tree_ldl(M, parents)
    tau = ca.mtimes(ca.DM(m.actuation_matrix), u)
    if w is not None:
        tau = tau + w
    z = tree_solve_lt(L, parents, (tau if k is None else tau / k) - H)
    Y = tree_solve_lt(L, parents, Jm.T)
    DY = scale_rows(D, Y)
    K = ca.mtimes(Y.T, DY) + ca.diag(1 - mask)
    lam = dense_ldl_solve(K, mask * (gamma - drift) - ca.mtimes(DY.T, z))
    a = tree_solve_l(L, parents, scale_rows(D, z + ca.mtimes(Y, lam)))
    return a, (lam if k is None else k * lam)


def masked_impact(sys, q: ca.SX, v: ca.SX, c: ca.SX) -> ca.SX:
    """v+ of a plastic impact with the feet whose flag is 1."""
    dyn, m = sys.dyn, sys.model
    parents = dof_parents(m)
    M = ca.substitute(dyn.M_expr, dyn.q, q)
    J = ca.substitute(dyn.contact_jacobian_expr(m.contact_frames), dyn.q, q)
    mask = _mask(c)
    Jm = ca.diag(mask) @ J
    L, D = tree_ldl(M, parents)
    Y = tree_solve_lt(L, parents, Jm.T)
    DY = scale_rows(D, Y)
    P = -dense_ldl_solve(ca.mtimes(Y.T, DY) + ca.diag(1 - mask), ca.mtimes(Jm, v))
    return v + tree_solve_l(L, parents, ca.mtimes(DY, P))


def leg_joints(m, frame: str) -> list[int]:
    """Configuration indices of the 1-dof joints on the chain from the base to `frame`."""
    return sorted(j.idx_q for j in m.chain(frame))


def touchdown_projection(sys, q: ca.SX, joined: list) -> ca.SX:
    """q with each joining foot put on the ground by its own leg: one Gauss-Newton step on its
    height over the leg's joints (minimal norm). A scheduled touchdown finds the foot up to
    a tracking error off the ground (millimetres); left there, the constraint's Baumgarte term
    would move the foot after the impact. A foot's leg is the chain of actuated joints from the
    base to the foot."""
    m = sys.model
    q_new = q
    for i, f in enumerate(m.contact_frames):
        leg = leg_joints(m, f)
        if not leg:
            continue
        z0 = sys.extra_env[f"{f}_z"]
        z, Jz = (ca.substitute(e, sys.x[:m.nq], q) for e in (z0, ca.jacobian(z0, sys.x[:m.nq])[:, leg]))
        dq = -z * Jz.T / (ca.mtimes(Jz, Jz.T) + 1e-12)
        step = ca.vertcat(*[dq[leg.index(k)] if k in leg else 0 for k in range(m.nq)])
        q_new = q_new + ca.if_else(joined[i], step, ca.DM.zeros(m.nq))
    return q_new


def contact_events(sys, x_new: ca.SX, u: ca.SX, s=ca.inf, k=None, w=None) -> ca.SX:
    """The discrete update after a step ending s after switch-in: touchdowns (with impact) and
    lift-offs, and the first touchdown and takeoff since switch-in on the event clocks. k and w as
    in masked_contact_dynamics decide lift-offs on a perturbed plant (the impact map does not
    depend on k)."""
    from ...spec.models import ContactEvent
    from ..events import record

    m = sys.model
    nq, nv, nf = m.nq, m.nv, len(m.contact_frames)
    q, v, c = x_new[:nq], x_new[nq:nq + nv], x_new[nq + nv:nq + nv + nf]
    keys = [f"{f}_{k}" for f in m.contact_frames for k in ("z", "vz")]
    env = dict(zip(keys, ca.vertsplit(ca.substitute(ca.vertcat(*[sys.extra_env[k] for k in keys]), sys.x, x_new))))
    _, lam = masked_contact_dynamics(sys, q, v, u, c, k, w)
    c_new = []
    for i, f in enumerate(m.contact_frames):
        z, vz = env[f"{f}_z"], env[f"{f}_vz"]
        touch = ca.logic_and(c[i] < 0.5, ca.logic_and(z <= 0, vz < 0))
        lift = ca.logic_and(c[i] > 0.5, lam[3 * i + 2] < 0)
        c_new.append(ca.if_else(touch, 1, ca.if_else(lift, 0, c[i])))
    c_new = ca.vertcat(*c_new)
    joins = [ca.logic_and(c_new[i] > 0.5, c[i] < 0.5) for i in range(nf)]
    touched = sum(joins)
    # the step that detects a touchdown ends with the foot up to one step's travel below the ground:
    # put it on the ground by its leg, as a scheduled touchdown does, so that the constraint's
    # Baumgarte term does not move it after the impact
    q = touchdown_projection(sys, q, joins)
    v_new = ca.if_else(touched > 0, masked_impact(sys, q, v, c_new), v)
    now = {ContactEvent.FIRST_TOUCHDOWN: touched > 0,  # a foot touched down
           ContactEvent.TAKEOFF: ca.logic_and(ca.sum1(c) > 0.5, ca.sum1(c_new) < 0.5)}  # the last one lifted off
    tau = x_new[nq + nv + nf:]  # the event clocks, in the order of ContactEvent
    clocks = [record(tau[k], now[e], s) for k, e in enumerate(ContactEvent)]
    return ca.vertcat(q, v_new, c_new, *clocks)
