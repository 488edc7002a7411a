"""Pydantic models of the spec language: system, motion primitives (Definition 1) and project.

The models validate structure only; expressions stay text here and are parsed and compiled to
CasADi by later stages. Unknown keys are rejected so a typo never passes silently. They live in
base.py, system.py, primitive.py and project.py; this module gathers them.
"""
from .base import ExprText, Strict
from .controllers import ExpressionController, IDQPController, LQRController, MotionProfile, PDController
from .kinds import controller_union
from .primitive import (ContactEvent, Controller, ContactPhase, EventWindow, ExplicitRoA, Grid, Primitive,
                        PrimitiveClass, SafetyFunction, Setpoint)
from .project import (ASSERTION_KEYS, Assertion, EdgeRef, EdgeWithClass, ForbidEdge, GoalCommand, OracleConfig,
                      PlanRef, Project, RequireConclusive, RequireEdge, RequirePlan, RequireReachable,
                      RequireSimulation, Sequence)
from .system import AnalyticSystem, BaumgarteGains, ControlAffine, RigidBodySystem, System

__all__ = [
    "ASSERTION_KEYS", "AnalyticSystem", "Assertion", "BaumgarteGains", "ContactEvent", "ContactPhase", "ControlAffine",
    "Controller", "EdgeRef", "EdgeWithClass", "EventWindow", "ExplicitRoA", "ExprText", "ExpressionController", "ForbidEdge", "GoalCommand", "Grid",
    "IDQPController", "LQRController", "MotionProfile", "OracleConfig", "PDController", "PlanRef", "Primitive",
    "PrimitiveClass", "Project", "RequireConclusive", "RequireEdge", "RequirePlan", "RequireReachable", "RequireSimulation",
    "RigidBodySystem", "SafetyFunction", "Sequence", "Setpoint", "Strict", "System", "refresh_controllers",
]


def refresh_controllers() -> None:
    """Rebuild the `controller:` union of Primitive, and Project that holds it, from the kinds
    registered now (after one was added in-process, spec/kinds.py)."""
    Primitive.model_fields["controller"].annotation = controller_union().__origin__
    Primitive.model_rebuild(force=True)
    Project.model_rebuild(force=True)
