"""Configuration-space maps for a free-flyer root with pinocchio's conventions.

q = [p (3, world), quaternion (x, y, z, w), joint angles]; v = [v_lin (3, base frame),
omega (3, base frame), joint rates]. Positions and quaternion therefore evolve as
p' = R(quat) v_lin and quat' = 0.5 quat (x) (omega, 0); `integrate_q` uses the exact SE(3)
exponential so it agrees with ``pinocchio.integrate`` for any step.
"""
from __future__ import annotations

import casadi as ca

from .model import RigidBodyModel
from .spatial import skew

_SMALL = 1e-8  # threshold on theta^2 below which Taylor expansions are used


def quat_to_rotation(quat: ca.SX) -> ca.SX:
    """Rotation matrix of a unit quaternion stored (x, y, z, w)."""
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        ca.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        ca.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)))


def quat_multiply(a: ca.SX, b: ca.SX) -> ca.SX:
    """Hamilton product a (x) b of (x, y, z, w) quaternions."""
    va, vb = a[:3], b[:3]
    w = a[3] * b[3] - ca.dot(va, vb)
    return ca.vertcat(a[3] * vb + b[3] * va + ca.cross(va, vb), w)


def _exp_coefficients(theta2: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """sin(t/2)/t, cos(t/2), (1-cos t)/t^2, (t-sin t)/t^3 with a smooth small-angle branch."""
    small = theta2 < _SMALL
    t = ca.sqrt(ca.if_else(small, 1.0, theta2))
    exact = (ca.sin(t / 2) / t, ca.cos(t / 2), (1 - ca.cos(t)) / (t * t),
             (t - ca.sin(t)) / (t * t * t))
    taylor = (0.5 - theta2 / 48, 1 - theta2 / 8, 0.5 - theta2 / 24, 1.0 / 6 - theta2 / 120)
    return tuple(ca.if_else(small, a, b) for a, b in zip(taylor, exact))


def se3_exp(quat: ca.SX, p: ca.SX, v_lin: ca.SX, omega: ca.SX) -> tuple[ca.SX, ca.SX]:
    """(p, quat) composed on the right with exp6(v_lin, omega) (both in the base frame)."""
    half_sinc, half_cos, a, b = _exp_coefficients(ca.dot(omega, omega))
    W = skew(omega)
    V = ca.SX.eye(3) + a * W + b * ca.mtimes(W, W)
    p_new = p + ca.mtimes(quat_to_rotation(quat), ca.mtimes(V, v_lin))
    dquat = ca.vertcat(half_sinc * omega, half_cos)
    return p_new, quat_multiply(quat, dquat)


def qdot(model: RigidBodyModel, q: ca.SX, v: ca.SX) -> ca.SX:
    """Time derivative of q for velocity v (length nq)."""
    if not model.floating_base:
        return v
    quat = q[3:7]
    p_dot = ca.mtimes(quat_to_rotation(quat), v[0:3])
    quat_dot = 0.5 * quat_multiply(quat, ca.vertcat(v[3:6], 0))
    return ca.vertcat(p_dot, quat_dot, v[6:])


def integrate_q(model: RigidBodyModel, q: ca.SX, v: ca.SX, dt: ca.SX | float) -> ca.SX:
    """q (+) v dt on the configuration manifold, equal to ``pinocchio.integrate(q, v*dt)``."""
    if not model.floating_base:
        return q + dt * v
    p, quat = se3_exp(q[3:7], q[0:3], dt * v[0:3], dt * v[3:6])
    return ca.vertcat(p, quat, q[7:] + dt * v[6:])


def normalize_quaternion(model: RigidBodyModel, q: ca.SX) -> ca.SX:
    """q with its base quaternion rescaled to unit norm (drift repair after integration)."""
    if not model.floating_base:
        return q
    quat = q[3:7]
    return ca.vertcat(q[0:3], quat / ca.norm_2(quat), q[7:])
