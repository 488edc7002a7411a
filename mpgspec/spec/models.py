"""Pydantic models of the spec language: system, motion primitives (Definition 1) and project.

The models validate structure only; expressions stay text here and are parsed and compiled to
CasADi by later stages. Unknown keys are rejected so a typo never passes silently. They live in
base.py, system.py, primitive.py and project.py; this module gathers them.
"""
from .base import ExprText, Strict
from .primitive import (ContactEvent, Controller, ContactPhase, EventWindow, ExplicitRoA, ExpressionController, Grid,
                        IDQPController, LQRController, MotionProfile, PDController, Primitive, PrimitiveClass,
                        SafetyFunction, Setpoint)
from .project import (ASSERTION_KEYS, Assertion, EdgeRef, EdgeWithClass, ForbidEdge, GoalCommand, OracleConfig,
                      PlanRef, Project, RequireConclusive, RequireEdge, RequirePlan, RequireReachable,
                      RequireSimulation, Sequence)
from .system import AnalyticSystem, BaumgarteGains, ControlAffine, RigidBodySystem, System

__all__ = [
    "ASSERTION_KEYS", "AnalyticSystem", "Assertion", "BaumgarteGains", "ContactEvent", "ContactPhase", "ControlAffine",
    "Controller", "EdgeRef", "EdgeWithClass", "EventWindow", "ExplicitRoA", "ExprText", "ExpressionController", "ForbidEdge", "GoalCommand", "Grid",
    "IDQPController", "LQRController", "MotionProfile", "OracleConfig", "PDController", "PlanRef", "Primitive",
    "PrimitiveClass", "Project", "RequireConclusive", "RequireEdge", "RequirePlan", "RequireReachable", "RequireSimulation",
    "RigidBodySystem", "SafetyFunction", "Sequence", "Setpoint", "Strict", "System",
]
