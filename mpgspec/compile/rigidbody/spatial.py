"""Spatial algebra on CasADi SX with pinocchio's conventions, kept compact on purpose.

A placement is a pair ``(R, p)`` mapping child coordinates to parent coordinates
(x_parent = R x_child + p). Motions are ``(linear, angular)`` and forces ``(force, torque)``
pairs of 3-vectors, both expressed at the origin of the frame they live in. Working with 3x3
blocks instead of 6x6 Plücker matrices keeps the graphs small, and exact 0/1 constants are
folded away by SX simplification (e.g. rotations about coordinate axes).
"""
from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np

Vec = ca.SX
Mat = ca.SX


class Placement(NamedTuple):
    R: Mat
    p: Vec


class Motion(NamedTuple):
    lin: Vec
    ang: Vec


class Force(NamedTuple):
    f: Vec
    n: Vec


class Inertia(NamedTuple):
    """Spatial inertia about the frame origin: mass, first moment h = m c, inertia I_o."""

    m: float
    h: Vec
    I: Mat


def zeros3() -> Vec:
    return ca.SX.zeros(3, 1)


def skew(x: Vec) -> Mat:
    return ca.vertcat(ca.horzcat(0, -x[2], x[1]),
                      ca.horzcat(x[2], 0, -x[0]),
                      ca.horzcat(-x[1], x[0], 0))


def sx(x) -> ca.SX:
    return x if isinstance(x, ca.SX) else ca.SX(ca.DM(np.asarray(x, dtype=float)))


def rotation_about(axis: np.ndarray, c: ca.SX, s: ca.SX) -> Mat:
    """Rotation by angle (cos c, sin s) about a constant unit axis; exact for coordinate axes."""
    k = np.flatnonzero(np.abs(axis) > 0)
    if k.size == 1 and abs(abs(axis[k[0]]) - 1.0) == 0.0:
        i = int(k[0])
        s = s if axis[i] > 0 else -s
        j, l = (i + 1) % 3, (i + 2) % 3
        R = ca.SX.zeros(3, 3)
        R[i, i] = 1
        R[j, j], R[j, l], R[l, j], R[l, l] = c, -s, s, c
        return R
    a = sx(axis)
    return c * ca.SX.eye(3) + s * skew(a) + (1 - c) * ca.mtimes(a, a.T)


def compose(A: Placement, B: Placement) -> Placement:
    return Placement(ca.mtimes(A.R, B.R), A.p + ca.mtimes(A.R, B.p))


def constant_placement(R: np.ndarray, p: np.ndarray) -> Placement:
    return Placement(sx(R), sx(np.reshape(p, (3, 1))))


def act_point(M: Placement, x: Vec) -> Vec:
    return M.p + ca.mtimes(M.R, x)


def act_motion(M: Placement, m: Motion) -> Motion:
    """Express a child-frame motion in the parent frame."""
    ang = ca.mtimes(M.R, m.ang)
    return Motion(ca.mtimes(M.R, m.lin) + ca.cross(M.p, ang), ang)


def inv_act_motion(M: Placement, m: Motion) -> Motion:
    """Express a parent-frame motion in the child frame."""
    return Motion(ca.mtimes(M.R.T, m.lin - ca.cross(M.p, m.ang)), ca.mtimes(M.R.T, m.ang))


def act_force(M: Placement, f: Force) -> Force:
    """Express a child-frame force in the parent frame."""
    force = ca.mtimes(M.R, f.f)
    return Force(force, ca.mtimes(M.R, f.n) + ca.cross(M.p, force))


def cross_motion(a: Motion, b: Motion) -> Motion:
    """Spatial cross product a x b of two motions."""
    return Motion(ca.cross(a.ang, b.lin) + ca.cross(a.lin, b.ang), ca.cross(a.ang, b.ang))


def cross_force(a: Motion, f: Force) -> Force:
    """Dual cross product a x* f of a motion and a force."""
    return Force(ca.cross(a.ang, f.f), ca.cross(a.ang, f.n) + ca.cross(a.lin, f.f))


def add_motion(a: Motion, b: Motion) -> Motion:
    return Motion(a.lin + b.lin, a.ang + b.ang)


def add_force(a: Force, b: Force) -> Force:
    return Force(a.f + b.f, a.n + b.n)


def body_inertia(mass: float, lever: np.ndarray, inertia_com: np.ndarray) -> Inertia:
    """Origin-based inertia of a body given its CoM lever and inertia about the CoM."""
    c = np.reshape(lever, 3)
    I_o = inertia_com + mass * (c @ c * np.eye(3) - np.outer(c, c))
    return Inertia(float(mass), sx(np.reshape(mass * c, (3, 1))), sx(I_o))


def inertia_mul(Y: Inertia, m: Motion) -> Force:
    """Momentum Y m: f = m v - h x w, n = I_o w + h x v."""
    return Force(Y.m * m.lin - ca.cross(Y.h, m.ang), ca.mtimes(Y.I, m.ang) + ca.cross(Y.h, m.lin))


def inertia_to_parent(M: Placement, Y: Inertia) -> Inertia:
    """Re-express an origin-based inertia in the parent frame (parallel-axis theorem)."""
    Rh = ca.mtimes(M.R, Y.h)
    P, RH = skew(M.p), skew(Rh)
    I = ca.mtimes(ca.mtimes(M.R, Y.I), M.R.T) - ca.mtimes(RH, P) - ca.mtimes(P, RH) \
        - Y.m * ca.mtimes(P, P)
    return Inertia(Y.m, Rh + Y.m * M.p, I)


def add_inertia(A: Inertia, B: Inertia) -> Inertia:
    return Inertia(A.m + B.m, A.h + B.h, A.I + B.I)
