"""Joint-space dynamics D(q) qdd + H(q, v) = tau in CasADi SX, checked against pinocchio.

`crba` builds composite inertias in local joint frames (so the floating-base block does not
depend on the base pose) and `rnea` is the recursive Newton-Euler algorithm with gravity
entered as a base acceleration. `RigidBodyDynamics` wraps them into cached casadi.Functions.
"""
from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property

import casadi as ca

from .frames import center_of_mass, center_of_mass_jacobian, frame_classical_drift, \
    frame_jacobian, frame_velocity
from .kinematics import TreeState, s_dot_force
from .liegroup import integrate_q, normalize_quaternion, qdot
from .model import RigidBodyModel
from .spatial import (Force, Motion, act_force, add_force, add_inertia, add_motion,
                      body_inertia, cross_force, inertia_mul, inertia_to_parent, inv_act_motion,
                      sx)


def crba(tree: TreeState) -> ca.SX:
    """Joint-space inertia matrix D(q) (symmetric, armature on the diagonal)."""
    model = tree.model
    joints = model.joints
    Yc = [body_inertia(j.mass, j.lever, j.inertia) for j in joints]
    for i in range(len(joints) - 1, -1, -1):
        if joints[i].parent >= 0:
            p = joints[i].parent
            Yc[p] = add_inertia(Yc[p], inertia_to_parent(tree.local[i], Yc[i]))
    M = ca.SX.zeros(model.nv, model.nv)
    for i, joint in enumerate(joints):
        forces = [inertia_mul(Yc[i], s) for s in tree.subspaces[i]]
        j = i
        while True:
            for a, s in enumerate(tree.subspaces[j]):
                for b, F in enumerate(forces):
                    val = s_dot_force(s, F)
                    M[joints[j].idx_v + a, joint.idx_v + b] = val
                    M[joint.idx_v + b, joints[j].idx_v + a] = val
            if joints[j].parent < 0:
                break
            forces = [act_force(tree.local[j], F) for F in forces]
            j = joints[j].parent
    return M + ca.diag(sx(model.armature))


def rnea(tree: TreeState, a: ca.SX | None = None) -> ca.SX:
    """Inverse dynamics tau = D(q) a + H(q, v); `a=None` gives H(q, v) (nonlinear effects)."""
    model = tree.model
    joints = model.joints
    g = sx(model.gravity.reshape(3, 1))
    forces: list[Force] = []
    acc_j: list[Motion] = []
    for i, joint in enumerate(joints):
        acc = tree.drift[i]
        if a is not None:
            ai = a[joint.idx_v:joint.idx_v + joint.nv]
            own = Motion(sum((s.lin * ai[k] for k, s in enumerate(tree.subspaces[i])), sx(0)),
                         sum((s.ang * ai[k] for k, s in enumerate(tree.subspaces[i])), sx(0)))
            if joint.parent >= 0:
                own = add_motion(inv_act_motion(tree.local[i], acc_j[joint.parent]), own)
            acc_j.append(own)
            acc = add_motion(acc, own)
        Y = body_inertia(joint.mass, joint.lever, joint.inertia)
        vel = tree.velocities[i]
        lin = acc.lin - ca.mtimes(tree.world[i].R.T, g)
        forces.append(add_force(inertia_mul(Y, Motion(lin, acc.ang)),
                                cross_force(vel, inertia_mul(Y, vel))))
    tau: list[ca.SX] = [None] * model.nv
    for i in range(len(joints) - 1, -1, -1):
        joint = joints[i]
        for k, s in enumerate(tree.subspaces[i]):
            tau[joint.idx_v + k] = s_dot_force(s, forces[i])
        if joint.parent >= 0:
            forces[joint.parent] = add_force(forces[joint.parent],
                                             act_force(tree.local[i], forces[i]))
    out = ca.vertcat(*tau)
    return out if a is None else out + sx(model.armature.reshape(-1, 1)) * a


class RigidBodyDynamics:
    """Cached casadi.Functions of a RigidBodyModel's kinematics and dynamics.

    Inputs are named q (nq), v (nv), a (nv), dt (1). Contact-frame quantities stack the
    model's `contact_frames` in order (3 rows each, world axes). Use `state(q, v)` to build the
    same expressions on other SX symbols when composing larger graphs.
    """

    def __init__(self, model: RigidBodyModel, cse: bool = True) -> None:
        self.model = model
        self.q = ca.SX.sym("q", model.nq)
        self.v = ca.SX.sym("v", model.nv)
        self.a = ca.SX.sym("a", model.nv)
        self.dt = ca.SX.sym("dt")
        self.tree = self.state(self.q, self.v)
        self._opts = {"cse": cse}

    def state(self, q: ca.SX, v: ca.SX | None = None) -> TreeState:
        return TreeState(self.model, q, v)

    def _fun(self, name: str, inputs: Sequence[str], outputs: Sequence[ca.SX],
             out_names: Sequence[str]) -> ca.Function:
        return ca.Function(name, [getattr(self, k) for k in inputs], list(outputs),
                           list(inputs), list(out_names), self._opts)

    # --- expressions on the object's own symbols -------------------------------------
    @cached_property
    def M_expr(self) -> ca.SX:
        return crba(self.tree)

    @cached_property
    def nle_expr(self) -> ca.SX:
        return rnea(self.tree)

    @cached_property
    def contact_positions_expr(self) -> ca.SX:
        """3 x nc world positions of the contact frames."""
        return ca.horzcat(*[self.tree.frame_position(n) for n in self.model.contact_frames])

    def contact_jacobian_expr(self, names: Sequence[str]) -> ca.SX:
        return ca.vertcat(*[frame_jacobian(self.tree, n) for n in names])

    def contact_drift_expr(self, names: Sequence[str]) -> ca.SX:
        return ca.vertcat(*[frame_classical_drift(self.tree, n) for n in names])

    def contact_velocity_expr(self, names: Sequence[str]) -> ca.SX:
        return ca.vertcat(*[frame_velocity(self.tree, n) for n in names])

    # --- functions ---------------------------------------------------------------------
    @cached_property
    def M(self) -> ca.Function:
        """q -> D(q) (nv x nv)."""
        return self._fun("M", ["q"], [self.M_expr], ["M"])

    @cached_property
    def nle(self) -> ca.Function:
        """(q, v) -> H(q, v): Coriolis, centrifugal and gravity terms."""
        return self._fun("nle", ["q", "v"], [self.nle_expr], ["h"])

    @cached_property
    def rnea(self) -> ca.Function:
        """(q, v, a) -> tau = D(q) a + H(q, v)."""
        return self._fun("rnea", ["q", "v", "a"], [rnea(self.tree, self.a)], ["tau"])

    @cached_property
    def fk_frames(self) -> ca.Function:
        """q -> 3 x nc world positions of the contact frames."""
        return self._fun("fk_frames", ["q"], [self.contact_positions_expr], ["p"])

    @cached_property
    def J_contacts(self) -> ca.Function:
        """q -> (3 nc) x nv stacked LOCAL_WORLD_ALIGNED linear Jacobians of the contacts."""
        J = self.contact_jacobian_expr(self.model.contact_frames)
        return self._fun("J_contacts", ["q"], [J], ["J"])

    @cached_property
    def Jdot_v(self) -> ca.Function:
        """(q, v) -> 3 nc classical contact-point accelerations at zero qddot."""
        drift = self.contact_drift_expr(self.model.contact_frames)
        return self._fun("Jdot_v", ["q", "v"], [drift], ["Jdot_v"])

    @cached_property
    def com(self) -> ca.Function:
        return self._fun("com", ["q"], [center_of_mass(self.tree)], ["com"])

    @cached_property
    def J_com(self) -> ca.Function:
        return self._fun("J_com", ["q"], [center_of_mass_jacobian(self.tree)], ["J_com"])

    @cached_property
    def integrate(self) -> ca.Function:
        """(q, v, dt) -> q (+) v dt via the SE(3) exponential (pinocchio.integrate)."""
        return self._fun("integrate", ["q", "v", "dt"],
                         [integrate_q(self.model, self.q, self.v, self.dt)], ["q_next"])

    @cached_property
    def qdot(self) -> ca.Function:
        """(q, v) -> dq/dt (nq)."""
        return self._fun("qdot", ["q", "v"], [qdot(self.model, self.q, self.v)], ["qdot"])

    @cached_property
    def normalize(self) -> ca.Function:
        """q -> q with a unit base quaternion."""
        return self._fun("normalize", ["q"], [normalize_quaternion(self.model, self.q)], ["q_unit"])

    def frame_placement(self, name: str) -> ca.Function:
        """q -> (R, p) world placement of any model frame."""
        M = self.tree.frame_placement(name)
        return self._fun(f"placement_{name}", ["q"], [M.R, M.p], ["R", "p"])

    def frame_jacobian(self, name: str) -> ca.Function:
        """q -> 6 x nv LOCAL_WORLD_ALIGNED Jacobian (linear rows first) of any frame."""
        return self._fun(f"J_{name}", ["q"], [frame_jacobian(self.tree, name, True)], ["J"])
