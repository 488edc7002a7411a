"""`mpgspec gait` errors are located like every spec error: the checks verify runs come before any
orbit (and before verify's gait-table staleness check), and a failed orbit is reported with its
residual and what to try, never as an internal error."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mpgspec.cli import main
from mpgspec.errors import SpecError
from mpgspec.robots.quadruped.gait.library import GaitTable, compare, generate, write
from mpgspec.robots.quadruped.gait.orbit import Orbit

A1 = Path(__file__).parents[2] / "specs" / "a1"


@pytest.fixture
def mistyped(tmp_path) -> Path:
    """A copy of specs/a1 whose trot pose names a joint the A1 does not have."""
    shutil.copytree(A1, tmp_path / "a1")
    walk = tmp_path / "a1" / "primitives" / "walk.yaml"
    walk.write_text(walk.read_text().replace("pose: {FL_thigh_joint: 0.8", "pose: {FL_thigh_jiont: 0.8", 1))
    return tmp_path / "a1"


def test_a_mistyped_pose_joint_is_located_in_gait(mistyped):
    with pytest.raises(SpecError) as err:
        generate(mistyped / "gaits.yaml", progress=lambda m: None)
    e = err.value
    assert e.code == "MPG106" and "controller.pose" in e.key and "FL_thigh_jiont" in e.found
    assert "FL_thigh_joint" in e.expected  # the valid joints are named
    assert e.location is not None and e.location.file.endswith("walk.yaml")


def test_a_mistyped_pose_joint_is_located_in_verify_before_the_staleness_check(mistyped, capsys):
    rc = main(["verify", str(mistyped / "project.yaml"), "--no-write", "-q"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "MPG106" in err and "unknown joint in the trot's pose" in err and "MPG110" not in err


def test_a_failed_orbit_is_reported_not_raised(tmp_path):
    orbit = Orbit(0.4, 0.41, 0.36, 0.001, np.zeros(1), np.zeros((3, 1)), "max_iter", 3.2e-2, 20,
                  np.full(2, np.nan), {}, {}, 1.0)
    table = GaitTable("Walk(medium)", tmp_path / "walk_0.4.csv", orbit, "0" * 16)
    assert "residual 3.2e-02" in table.failure and "controller.pairs" in table.failure
    assert write([table], ["a", "b", "c"]) == [] and not table.path.exists()
    assert compare([table], ["a", "b", "c"]) == [f"Walk(medium): {table.failure}"]
