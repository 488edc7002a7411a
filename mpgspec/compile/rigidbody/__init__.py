"""Symbolic floating-base rigid-body dynamics (CasADi SX) for URDF robots.

The algorithms (CRBA, RNEA, frame kinematics, Jacobians, classical drift J̇q̇, centre of mass) are
written here in spatial algebra over pinocchio's parsed Model (joint placements, inertias, axes),
rather than taken from pinocchio.casadi, which the PyPI `pin` wheels do not ship, or from
adam-robotics, which needs an edited URDF for the A1, uses another gravity constant and another
torque convention. Writing them keeps one source of truth (pinocchio's model), gives plain SX
graphs that jit-compile to a few microseconds per right-hand side, and is checked against
pinocchio's own algorithms to 1e-8 in tests/compile/rigidbody.
"""
from .constrained import Baumgarte, ContactDynamics, impact_map, solve_contact
from .dynamics import RigidBodyDynamics, crba, rnea
from .model import RigidBodyModel, find_urdf

__all__ = ["Baumgarte", "ContactDynamics", "RigidBodyDynamics",
           "RigidBodyModel", "crba", "find_urdf", "impact_map", "rnea", "solve_contact"]
