"""The symmetry of flat ground: moving a floating-base state in x and y or turning it about the vertical
gives a state whose motion is the same, moved and turned. Periodic gaits are therefore periodic
up to this symmetry; their Floquet multipliers come from the reduced state, and the three neutral
ones (base_x, base_y, yaw) are reported by name.

reduce: x -> (z, tilt quaternion (x, y) in the heading frame, joints, velocities); velocities are
in the base frame (pinocchio's convention), so turning leaves them as they are.
lift: the reduced state -> the full state at x = y = 0 and yaw 0.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .liegroup import quat_multiply, quat_to_rotation

NEUTRAL = ("base_x", "base_y", "yaw")


def _yaw(quat):
    R = quat_to_rotation(quat)
    return ca.atan2(R[1, 0], R[0, 0])


def _unturn(quat):
    """quat with its yaw removed: qz(-yaw) (x) quat."""
    psi = _yaw(quat)
    qz = ca.vertcat(0, 0, ca.sin(-psi / 2), ca.cos(-psi / 2))
    return quat_multiply(qz, quat)


def reduce_function(sys) -> ca.Function:
    m = sys.model
    x = ca.SX.sym("x", sys.nx)
    q = _unturn(x[3:7])
    z = ca.vertcat(x[2], q[0], q[1], x[7:m.nq], x[m.nq:m.nq + m.nv])
    return ca.Function("reduce", [x], [z])


def lift_function(sys) -> ca.Function:
    m = sys.model
    nr = 3 + (m.nq - 7) + m.nv
    z = ca.SX.sym("z", nr)
    qx, qy = z[1], z[2]
    qz = ca.SX(0)
    for _ in range(6):  # yaw(q) = 0 <=> qx qy + qz qw = 0
        qw = ca.sqrt(1 - qx**2 - qy**2 - qz**2)
        qz = -qx * qy / qw
    qw = ca.sqrt(1 - qx**2 - qy**2 - qz**2)
    rest = ca.DM.zeros(sys.nx - m.nq - m.nv)
    x = ca.vertcat(0, 0, z[0], qx, qy, qz, qw, z[3:3 + m.nq - 7], z[3 + m.nq - 7:], rest)
    return ca.Function("lift", [z], [x])


def generators(sys, x: np.ndarray) -> dict[str, np.ndarray]:
    """Tangent vectors at x of moving in x, in y and of turning about the vertical (by name)."""
    gx, gy = np.zeros(sys.nx), np.zeros(sys.nx)
    gx[0], gy[0 + 1] = 1.0, 1.0
    quat = np.asarray(x[3:7], float)
    dq = 0.5 * np.array(quat_multiply(ca.DM([0, 0, 1, 0]), ca.DM(quat))).ravel()
    gyaw = np.zeros(sys.nx)
    gyaw[0], gyaw[1] = -x[1], x[0]
    gyaw[3:7] = dq
    return {"base_x": gx, "base_y": gy, "yaw": gyaw}


def lift_jacobian(sys) -> ca.Function:
    """z -> d lift / d z (exact)."""
    lift = lift_function(sys)
    z = lift.sx_in(0)
    return ca.Function("lift_jacobian", [z], [ca.jacobian(lift(z), z)])


def reduced_monodromy(sys, run, x0: np.ndarray, neutral=NEUTRAL, eps: float = 1e-6) -> tuple[np.ndarray, dict]:
    """The derivative of a period map on the reduced state at x0, by central differences, and the
    multipliers along the generators named in `neutral` (1 when the map respects the symmetry).

    run(X) maps columns of full states to their images after one period. Each neutral multiplier
    compares the map's derivative along a generator at x0 with the generator at the image (the
    symmetry maps one onto the other exactly); its invariance defect is the relative mismatch.
    """
    red, lift = reduce_function(sys), lift_function(sys)
    z = np.array(red(x0), float).ravel()
    base = np.array(lift(z), float).ravel()
    Dl = np.array(lift_jacobian(sys)(z), float)
    g0 = generators(sys, base)
    G = np.stack([g0[k] / np.linalg.norm(g0[k]) for k in neutral], 1) if neutral else np.zeros((base.size, 0))
    n, m = z.size, G.shape[1]
    b = base[:, None]
    XT = run(np.hstack([b + eps * Dl, b - eps * Dl, b + eps * G, b - eps * G, b]))
    R = np.array([np.array(red(XT[:, j]), float).ravel() for j in range(2 * n)]).T
    M = (R[:, :n] - R[:, n:]) / (2 * eps)
    gT = generators(sys, XT[:, -1])
    found = {}
    for i, k in enumerate(neutral):
        Pg = (XT[:, 2 * n + i] - XT[:, 2 * n + m + i]) / (2 * eps) * np.linalg.norm(g0[k])
        found[k] = {"multiplier": float(gT[k] @ Pg / (gT[k] @ gT[k])),
                    "invariance_defect": float(np.linalg.norm(Pg - gT[k]) / np.linalg.norm(gT[k]))}
    return M, found
