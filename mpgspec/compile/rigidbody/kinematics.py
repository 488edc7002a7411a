"""Symbolic kinematics of a RigidBodyModel for given SX q (and v), shared across algorithms.

`TreeState` evaluates each quantity once (lazily) so mass matrix, bias forces, contact
Jacobians and drifts built from the same state reuse the same SX nodes. Joint-level
quantities live in the local joint frame, as in pinocchio.
"""
from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from .liegroup import quat_to_rotation
from .model import Joint, RigidBodyModel
from .spatial import (Motion, Placement, act_point, add_motion, compose, constant_placement,
                      cross_motion, inv_act_motion, rotation_about, sx, zeros3)


def joint_transform(joint: Joint, q: ca.SX) -> Placement:
    """Placement of joint frame i in its parent joint frame: jointPlacement * jMi(q)."""
    fixed = constant_placement(joint.rotation, joint.translation)
    qi = q[joint.idx_q:joint.idx_q + joint.nq]
    if joint.kind == "free":
        motion = Placement(quat_to_rotation(qi[3:7]), qi[0:3])
    elif joint.kind == "revolute":
        motion = Placement(rotation_about(joint.axis, ca.cos(qi[0]), ca.sin(qi[0])), zeros3())
    else:
        motion = Placement(ca.SX.eye(3), sx(joint.axis.reshape(3, 1)) * qi[0])
    if np.array_equal(joint.rotation, np.eye(3)) and not joint.translation.any():
        return motion
    return compose(fixed, motion)


def subspace(joint: Joint) -> list[Motion]:
    """Columns of the joint motion subspace S (local frame), one Motion per dof."""
    if joint.kind == "free":
        e = [sx(np.eye(3)[:, [k]]) for k in range(3)]
        return [Motion(c, zeros3()) for c in e] + [Motion(zeros3(), c) for c in e]
    axis = sx(joint.axis.reshape(3, 1))
    return [Motion(zeros3(), axis)] if joint.kind == "revolute" else [Motion(axis, zeros3())]


def joint_velocity(joint: Joint, v: ca.SX) -> Motion:
    """S_i v_i: the joint's own spatial velocity contribution (local frame)."""
    vi = v[joint.idx_v:joint.idx_v + joint.nv]
    if joint.kind == "free":
        return Motion(vi[0:3], vi[3:6])
    axis = sx(joint.axis.reshape(3, 1))
    return Motion(zeros3(), axis * vi[0]) if joint.kind == "revolute" else \
        Motion(axis * vi[0], zeros3())


def s_dot_force(s: Motion, f) -> ca.SX:
    """Projection s^T f of a force onto a motion-subspace column."""
    return ca.dot(s.lin, f.f) + ca.dot(s.ang, f.n)


class TreeState:
    """Lazily evaluated kinematic quantities of the tree at symbolic (q, v)."""

    def __init__(self, model: RigidBodyModel, q: ca.SX, v: ca.SX | None = None) -> None:
        self.model, self.q, self.v = model, q, v
        self.subspaces = [subspace(j) for j in model.joints]

    @cached_property
    def local(self) -> list[Placement]:
        """liMi: placement of each joint frame in its parent joint frame."""
        return [joint_transform(j, self.q) for j in self.model.joints]

    @cached_property
    def world(self) -> list[Placement]:
        """oMi: placement of each joint frame in the world."""
        out: list[Placement] = []
        for j, liMi in zip(self.model.joints, self.local):
            out.append(liMi if j.parent < 0 else compose(out[j.parent], liMi))
        return out

    @cached_property
    def velocities(self) -> list[Motion]:
        """Spatial velocity of each joint frame, expressed in that frame."""
        out: list[Motion] = []
        for j, liMi in zip(self.model.joints, self.local):
            vj = joint_velocity(j, self.v)
            if j.parent < 0:
                out.append(vj)
            else:
                out.append(add_motion(inv_act_motion(liMi, out[j.parent]), vj))
        return out

    @cached_property
    def drift(self) -> list[Motion]:
        """Spatial acceleration of each joint frame at zero qddot and zero gravity."""
        out: list[Motion] = []
        for j, liMi, vi in zip(self.model.joints, self.local, self.velocities):
            if j.parent < 0:
                out.append(Motion(zeros3(), zeros3()))  # v_i = S v_J, so v_i x v_J = 0
                continue
            c = cross_motion(vi, joint_velocity(j, self.v))
            out.append(add_motion(inv_act_motion(liMi, out[j.parent]), c))
        return out

    def frame_placement(self, name: str) -> Placement:
        frame = self.model.frame(name)
        fixed = constant_placement(frame.rotation, frame.translation)
        if frame.joint < 0:
            return fixed
        return compose(self.world[frame.joint], fixed)

    def frame_position(self, name: str) -> ca.SX:
        frame = self.model.frame(name)
        if frame.joint < 0:
            return sx(frame.translation.reshape(3, 1))
        return act_point(self.world[frame.joint], sx(frame.translation.reshape(3, 1)))

    def support(self, joint: int) -> list[int]:
        """Joint indices from `joint` up to the root."""
        chain = []
        while joint >= 0:
            chain.append(joint)
            joint = self.model.joints[joint].parent
        return chain

    def world_subspace(self, joint: int) -> list[Motion]:
        """Columns of S for `joint` expressed in world coordinates at the world origin."""
        M = self.world[joint]
        out = []
        for s in self.subspaces[joint]:
            ang = ca.mtimes(M.R, s.ang)
            out.append(Motion(ca.mtimes(M.R, s.lin) + ca.cross(M.p, ang), ang))
        return out
