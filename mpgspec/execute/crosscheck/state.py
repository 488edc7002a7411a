"""mpgspec's state x <-> MuJoCo's (qpos, qvel).

mpgspec (pinocchio's conventions): x = [p, quat (x, y, z, w), q_joints, v_base, w_base, qdot_joints,
contact flags, event clocks], with v_base and w_base the base's linear and angular velocity in the
base frame. MuJoCo's free joint: qpos = [p, quat (w, x, y, z)], qvel = [v in the world frame, w in the body
frame]; joints in the URDF's tree order, matched here by name. So v_mujoco = R v_base,
w_mujoco = w_base, with R the base's rotation (body to world).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def quat_matrix(q_wxyz) -> np.ndarray:
    """Rotation matrix (body to world) of a quaternion, w first; normalised first."""
    q = np.asarray(q_wxyz, float)
    w, x, y, z = (q / math.sqrt(q.dot(q))).tolist()  # np.linalg.norm's arithmetic, on Python floats
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def xyzw_to_wxyz(q) -> np.ndarray:
    return np.asarray(q, float)[[3, 0, 1, 2]]


def wxyz_to_xyzw(q) -> np.ndarray:
    return np.asarray(q, float)[[1, 2, 3, 0]]


@dataclass(frozen=True)
class StateMap:
    """Index maps between one system's state layout and one MuJoCo model."""

    nx: int
    nq: int  # mpgspec's (pinocchio's) configuration size
    nv: int
    floating: bool
    qpos: np.ndarray  # MuJoCo qpos address of each actuated joint, in mpgspec's joint order
    dof: np.ndarray  # MuJoCo dof address of each actuated joint
    base_qpos: int  # qpos address of the free joint (-1: fixed base)
    base_dof: int
    mj_nq: int
    mj_nv: int

    @classmethod
    def of(cls, system, model) -> "StateMap":
        import mujoco

        m = system.model
        jid = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in m.joint_names]
        if min(jid) < 0:
            raise ValueError(f"joints missing in the MuJoCo model: {[j for j, i in zip(m.joint_names, jid) if i < 0]}")
        free = [i for i in range(model.njnt) if model.jnt_type[i] == mujoco.mjtJoint.mjJNT_FREE]
        return cls(system.nx, m.nq, m.nv, bool(m.floating_base), model.jnt_qposadr[jid].copy(),
                   model.jnt_dofadr[jid].copy(), int(model.jnt_qposadr[free[0]]) if free else -1,
                   int(model.jnt_dofadr[free[0]]) if free else -1, int(model.nq), int(model.nv))

    @property
    def n_base_q(self) -> int:
        return 7 if self.floating else 0

    @property
    def n_base_v(self) -> int:
        return 6 if self.floating else 0

    def to_mujoco(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(qpos, qvel) of mpgspec's state x."""
        x = np.asarray(x, float)
        qpos, qvel = np.zeros(self.mj_nq), np.zeros(self.mj_nv)
        bq, bv, nq = self.n_base_q, self.n_base_v, self.nq
        if self.floating:
            a, d = self.base_qpos, self.base_dof
            qpos[a:a + 3] = x[:3]
            qpos[a + 3:a + 7] = xyzw_to_wxyz(x[3:7])
            qvel[d:d + 3] = quat_matrix(qpos[a + 3:a + 7]) @ x[nq:nq + 3]
            qvel[d + 3:d + 6] = x[nq + 3:nq + 6]
        qpos[self.qpos] = x[bq:nq]
        qvel[self.dof] = x[nq + bv:nq + self.nv]
        return qpos, qvel

    def from_mujoco(self, qpos, qvel, extra=None) -> np.ndarray:
        """mpgspec's state of (qpos, qvel); the states after them (contact flags and event clocks of
        systems with contact events) given as `extra`."""
        qpos, qvel = np.asarray(qpos, float), np.asarray(qvel, float)
        x = np.zeros(self.nx)
        bq, bv, nq = self.n_base_q, self.n_base_v, self.nq
        if self.floating:
            a, d = self.base_qpos, self.base_dof
            x[:3] = qpos[a:a + 3]
            x[3:7] = wxyz_to_xyzw(qpos[a + 3:a + 7])
            x[nq:nq + 3] = quat_matrix(qpos[a + 3:a + 7]).T @ qvel[d:d + 3]
            x[nq + 3:nq + 6] = qvel[d + 3:d + 6]
        x[bq:nq] = qpos[self.qpos]
        x[nq + bv:nq + self.nv] = qvel[self.dof]
        if extra is not None:
            x[nq + self.nv:] = extra
        return x
