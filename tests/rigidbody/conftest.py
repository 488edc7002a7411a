"""The A1 project compiled once for the rigid-body tests (the session's a1_project)."""
import pytest


@pytest.fixture(scope="session")
def a1(a1_project):
    return a1_project
