"""Contact-constrained, aerial and impact dynamics of point-foot robots in CasADi SX.

For a contact set with stacked LOCAL_WORLD_ALIGNED point Jacobian J (3 rows per foot):

    D a + H = B u + J^T lam,        J a + Jdot v = gamma,

with lam the force the ground exerts on each foot in world axes (the sign convention of
pinocchio's constraintDynamics/forwardDynamics lambda_c, so lam_z > 0 when the ground pushes
up). gamma = 0 for ideal contact; with Baumgarte stabilisation
gamma = -2 alpha J v - beta^2 e, where e is the foot position error: by default only its
height above the ground (e = (0, 0, fk_z - ground_height) per foot, no tangential anchor), or
fk - anchors when anchors are given. The system is solved by the Schur complement
lam = (J D^-1 J^T)^-1 (gamma - Jdot v - J D^-1 (B u - H)), a = D^-1 (B u - H + J^T lam), using
the tree-sparse L^T D L factor of D and a dense LDL^T of J D^-1 J^T.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import casadi as ca

from .dynamics import RigidBodyDynamics
from .liegroup import qdot
from .linalg import dense_ldl_solve, dof_parents, scale_rows, tree_ldl, tree_solve_l, \
    tree_solve_lt


@dataclass(frozen=True)
class Baumgarte:
    """Contact-drift stabilisation gains: J a + Jdot v = -2 alpha J v - beta^2 e."""

    alpha: float
    beta: float
    ground_height: float = 0.0


def contact_acceleration_target(J: ca.SX, v: ca.SX, positions: ca.SX, gains: Baumgarte,
                                anchors: ca.SX | None = None) -> ca.SX:
    """gamma = -2 alpha J v - beta^2 e for feet at `positions` (3 x nc)."""
    if anchors is None:
        nc = positions.shape[1]
        err = ca.vertcat(*[ca.vertcat(0, 0, positions[2, k] - gains.ground_height)
                           for k in range(nc)])
    else:
        err = ca.vec(positions) - ca.vec(anchors)
    return -2 * gains.alpha * ca.mtimes(J, v) - gains.beta ** 2 * err


def solve_contact(M: ca.SX, h: ca.SX, tau: ca.SX, J: ca.SX, drift: ca.SX,
                  parents: Sequence[int], gamma: ca.SX | None = None) -> tuple[ca.SX, ca.SX]:
    """(a, lam) of the constrained dynamics; J with zero rows gives the aerial dynamics."""
    L, D = tree_ldl(M, parents)
    z = tree_solve_lt(L, parents, tau - h)
    if J.shape[0] == 0:
        return tree_solve_l(L, parents, scale_rows(D, z)), ca.SX(0, 1)
    Y = tree_solve_lt(L, parents, J.T)  # J D^-1 J^T = Y^T diag(D)^-1 Y
    DY = scale_rows(D, Y)
    rhs = -drift - ca.mtimes(DY.T, z)
    if gamma is not None:
        rhs = rhs + gamma
    lam = dense_ldl_solve(ca.mtimes(Y.T, DY), rhs)
    a = tree_solve_l(L, parents, scale_rows(D, z + ca.mtimes(Y, lam)))
    return a, lam


def impact_map(M: ca.SX, J: ca.SX, v_minus: ca.SX,
               parents: Sequence[int]) -> tuple[ca.SX, ca.SX]:
    """Plastic impact: v+ = v- - D^-1 J^T (J D^-1 J^T)^-1 J v-; returns (v+, impulse).

    The impulse P = -(J D^-1 J^T)^-1 J v- is what the ground imparts to the feet
    (D (v+ - v-) = J^T P), so J v+ = 0 and kinetic energy cannot increase.
    """
    L, D = tree_ldl(M, parents)
    Y = tree_solve_lt(L, parents, J.T)
    DY = scale_rows(D, Y)
    impulse = -dense_ldl_solve(ca.mtimes(Y.T, DY), ca.mtimes(J, v_minus))
    return v_minus + tree_solve_l(L, parents, ca.mtimes(DY, impulse)), impulse


class ContactDynamics:
    """Forward dynamics of a RigidBodyDynamics with a fixed subset of its contact frames.

    Functions: `forward` (q, v, u) -> (a, lam); `rhs` (x, u) -> xdot with x = [q; v] and
    xdot = [qdot(q, v); a]; `impact` (q, v) -> (v_plus, impulse). u enters through
    B = [0_{6 x nu}; I_nu]. An empty contact set gives the aerial dynamics a = D^-1 (B u - H).
    """

    def __init__(self, dyn: RigidBodyDynamics, contacts: Sequence[str] = (),
                 baumgarte: Baumgarte | None = None) -> None:
        unknown = [c for c in contacts if c not in dyn.model.contact_frames]
        if unknown:
            raise KeyError(f"{unknown} are not contact frames of the model")
        self.dyn, self.contacts, self.baumgarte = dyn, tuple(contacts), baumgarte
        self.u = ca.SX.sym("u", dyn.model.nu)
        self.parents = dof_parents(dyn.model)

    @property
    def tau_expr(self) -> ca.SX:
        return ca.mtimes(ca.DM(self.dyn.model.actuation_matrix), self.u)

    @cached_property
    def jacobian_expr(self) -> ca.SX:
        return self.dyn.contact_jacobian_expr(self.contacts) if self.contacts \
            else ca.SX(0, self.dyn.model.nv)

    @cached_property
    def solution(self) -> tuple[ca.SX, ca.SX]:
        """(a, lam) as SX expressions of (dyn.q, dyn.v, self.u)."""
        return self.solve(self.tau_expr)

    def solve(self, tau: ca.SX) -> tuple[ca.SX, ca.SX]:
        """(a, lam) under the generalized force tau (B u, plus any external force mapped by J^T)."""
        dyn = self.dyn
        J = self.jacobian_expr
        drift = dyn.contact_drift_expr(self.contacts) if self.contacts else ca.SX(0, 1)
        gamma = None
        if self.baumgarte is not None and self.contacts:
            positions = ca.horzcat(*[dyn.tree.frame_position(n) for n in self.contacts])
            gamma = contact_acceleration_target(J, dyn.v, positions, self.baumgarte)
        return solve_contact(dyn.M_expr, dyn.nle_expr, tau, J, drift, self.parents, gamma)

    def _fun(self, name: str, inputs: list, in_names: list, outputs: list,
             out_names: list) -> ca.Function:
        return ca.Function(name, inputs, outputs, in_names, out_names, self.dyn._opts)

    @cached_property
    def forward(self) -> ca.Function:
        a, lam = self.solution
        return self._fun("forward", [self.dyn.q, self.dyn.v, self.u], ["q", "v", "u"],
                         [a, lam], ["a", "lam"])

    @cached_property
    def rhs(self) -> ca.Function:
        dyn = self.dyn
        x = ca.vertcat(dyn.q, dyn.v)
        xdot = ca.vertcat(qdot(dyn.model, dyn.q, dyn.v), self.solution[0])
        return self._fun("rhs", [x, self.u], ["x", "u"], [xdot], ["xdot"])

    @cached_property
    def impact(self) -> ca.Function:
        dyn = self.dyn
        v_plus, impulse = impact_map(dyn.M_expr, self.jacobian_expr, dyn.v, self.parents)
        return self._fun("impact", [dyn.q, dyn.v], ["q", "v"], [v_plus, impulse],
                         ["v_plus", "impulse"])
