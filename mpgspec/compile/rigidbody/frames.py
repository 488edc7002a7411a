"""Point Jacobians, their drift and centre-of-mass quantities as SX expressions.

All Jacobians are pinocchio's LOCAL_WORLD_ALIGNED: velocities of a point attached to the robot,
with world axes, as a linear map of the generalised velocity v (not of qdot).
"""
from __future__ import annotations

import casadi as ca

from .kinematics import TreeState
from .spatial import act_point, sx


def frame_jacobian(tree: TreeState, name: str, angular: bool = False) -> ca.SX:
    """3 x nv linear (or 6 x nv with angular rows below) Jacobian of frame `name`."""
    model = tree.model
    frame = model.frame(name)
    lin = ca.SX.zeros(3, model.nv)
    ang = ca.SX.zeros(3, model.nv)
    if frame.joint < 0:
        return ca.vertcat(lin, ang) if angular else lin
    x = tree.frame_position(name)
    for j in tree.support(frame.joint):
        joint, M = model.joints[j], tree.world[j]
        r = x - M.p
        for k, s in enumerate(tree.subspaces[j]):
            w = ca.mtimes(M.R, s.ang)
            lin[:, joint.idx_v + k] = ca.mtimes(M.R, s.lin) + ca.cross(w, r)
            ang[:, joint.idx_v + k] = w
    return ca.vertcat(lin, ang) if angular else lin


def frame_classical_drift(tree: TreeState, name: str) -> ca.SX:
    """J_dot v of the frame origin: its classical (world-axes) acceleration at zero qddot.

    For a point at r in joint frame i with spatial velocity (v, w) and acceleration (a, dw):
    R_oi (a + dw x r + w x (v + w x r)). This equals pinocchio's
    getFrameClassicalAcceleration(LOCAL_WORLD_ALIGNED).linear after
    forwardKinematics(q, v, 0) (not getFrameAcceleration, which omits the w x v term).
    """
    frame = tree.model.frame(name)
    if frame.joint < 0:
        return ca.SX.zeros(3, 1)
    r = sx(frame.translation.reshape(3, 1))
    vel, acc = tree.velocities[frame.joint], tree.drift[frame.joint]
    v_point = vel.lin + ca.cross(vel.ang, r)
    a_local = acc.lin + ca.cross(acc.ang, r) + ca.cross(vel.ang, v_point)
    return ca.mtimes(tree.world[frame.joint].R, a_local)


def frame_velocity(tree: TreeState, name: str) -> ca.SX:
    """World-axes linear velocity of the frame origin (= J v)."""
    frame = tree.model.frame(name)
    if frame.joint < 0:
        return ca.SX.zeros(3, 1)
    vel = tree.velocities[frame.joint]
    r = sx(frame.translation.reshape(3, 1))
    return ca.mtimes(tree.world[frame.joint].R, vel.lin + ca.cross(vel.ang, r))


def center_of_mass(tree: TreeState) -> ca.SX:
    """World position of the robot's centre of mass."""
    model = tree.model
    total = ca.SX.zeros(3, 1)
    for joint, M in zip(model.joints, tree.world):
        total += joint.mass * act_point(M, sx(joint.lever.reshape(3, 1)))
    return total / model.total_mass


def center_of_mass_jacobian(tree: TreeState) -> ca.SX:
    """3 x nv Jacobian of the centre of mass (world axes), like pinocchio.jacobianCenterOfMass.

    Column of dof s of joint j: (m_sub R s_lin + w_s x (h_sub - m_sub p_j)) / m_total, with
    m_sub and h_sub the mass and world first moment of the subtree rooted at j.
    """
    model = tree.model
    n = len(model.joints)
    m_sub = [j.mass for j in model.joints]
    h_sub = [j.mass * act_point(M, sx(j.lever.reshape(3, 1)))
             for j, M in zip(model.joints, tree.world)]
    for i in range(n - 1, -1, -1):
        parent = model.joints[i].parent
        if parent >= 0:
            m_sub[parent] += m_sub[i]
            h_sub[parent] = h_sub[parent] + h_sub[i]
    J = ca.SX.zeros(3, model.nv)
    for i, joint in enumerate(model.joints):
        M = tree.world[i]
        r = h_sub[i] - m_sub[i] * M.p
        for k, s in enumerate(tree.subspaces[i]):
            w = ca.mtimes(M.R, s.ang)
            J[:, joint.idx_v + k] = (m_sub[i] * ca.mtimes(M.R, s.lin) + ca.cross(w, r)) \
                / model.total_mass
    return J
