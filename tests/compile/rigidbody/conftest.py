"""The A1 model and its symbolic dynamics, built once for all rigid-body tests."""
import pytest

from a1_model import a1_model

from mpgspec.compile.rigidbody import RigidBodyDynamics, RigidBodyModel


@pytest.fixture(scope="session")
def model() -> RigidBodyModel:
    return a1_model()


@pytest.fixture(scope="session")
def dyn(model) -> RigidBodyDynamics:
    return RigidBodyDynamics(model)
