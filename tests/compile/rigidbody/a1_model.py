"""The Unitree A1 from example-robot-data as the rigid-body tests use it."""
from mpgspec.compile.rigidbody.model import RigidBodyModel, find_urdf

A1_URDF = "example-robot-data/robots/a1_description/urdf/a1.urdf"
A1_FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


def a1_model() -> RigidBodyModel:
    """The A1 with its four feet as contact frames."""
    return RigidBodyModel(find_urdf(A1_URDF), A1_FEET)
