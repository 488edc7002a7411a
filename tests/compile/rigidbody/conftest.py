"""The A1 model and its symbolic dynamics, built once for all rigid-body tests."""
import pytest

from mpgspec.compile.rigidbody import RigidBodyDynamics, RigidBodyModel


@pytest.fixture(scope="session")
def model() -> RigidBodyModel:
    return RigidBodyModel.a1()


@pytest.fixture(scope="session")
def dyn(model) -> RigidBodyDynamics:
    return RigidBodyDynamics(model)
