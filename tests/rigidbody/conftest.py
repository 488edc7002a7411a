"""The A1 project compiled once for the rigid-body tests."""
from pathlib import Path

import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.spec.loader import load_project

SPEC = Path(__file__).parents[2] / "specs" / "a1"


@pytest.fixture(scope="session")
def a1():
    spec = load_project(SPEC / "project.yaml")
    return spec, compile_project(spec), settings_for(spec)
