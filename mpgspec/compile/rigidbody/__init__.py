"""Symbolic floating-base rigid-body dynamics (CasADi SX) for URDF robots."""
from .constrained import Baumgarte, ContactDynamics, impact_map, solve_contact
from .dynamics import RigidBodyDynamics, crba, rnea
from .model import A1_FEET, A1_URDF, RigidBodyModel, find_urdf

__all__ = ["A1_FEET", "A1_URDF", "Baumgarte", "ContactDynamics", "RigidBodyDynamics",
           "RigidBodyModel", "crba", "find_urdf", "impact_map", "rnea", "solve_contact"]
