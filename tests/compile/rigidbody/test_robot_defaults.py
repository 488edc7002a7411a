"""Defaults from the robot, not from the A1: the trot's height and least normal force, its named
pairs, touchdown windows from the contact schedule, and a WARN on placeholder limits."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from mpgspec.check.assumptions import robot_limits
from mpgspec.compile.rigidbody.system import touchdown_gaps
from mpgspec.compile.system import compile_system
from mpgspec.robots.quadruped.trot import TrotGains, gains_of, stance_height
from mpgspec.spec.loader import load_project

A1 = Path(__file__).parents[3] / "specs" / "a1" / "project.yaml"
FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


@pytest.fixture(scope="module")
def a1():
    spec = load_project(A1)
    return spec, compile_system(spec)


def test_trot_defaults_come_from_the_robot(a1):
    spec, sys = a1
    walk = next(i for i in spec.primitives if i.base == "Walk").spec.controller
    g = gains_of(walk, 0.2, sys)
    assert (g.height, g.f_min) == (0.2586, 20.0)  # the A1's specs write today's values
    assert (g.pair_a, g.pair_b) == (("FL_foot", "RR_foot"), ("FR_foot", "RL_foot"))
    bare = walk.model_copy(update={"height": None, "f_min": None})
    g = gains_of(bare, 0.2, sys)
    assert g.height == pytest.approx(stance_height(sys, dict(walk.pose)))
    assert abs(g.height - 0.2586) < 1e-3  # the A1's stance: its CoM at 0.25855 m
    assert g.f_min == pytest.approx(0.075 * sys.model.total_mass * 9.81, rel=1e-3)
    named = walk.model_copy(update={"pairs": [["FR", "RL"], ["RR", "FL"]]})
    g = gains_of(named, 0.2, sys)
    assert (g.pair_a, g.pair_b) == (("FR_foot", "RL_foot"), ("RR_foot", "FL_foot"))


def test_touchdown_windows_follow_the_schedule():
    """The block's rows are the A1's hand-written touchdown_gap rows: each foot that joins the held
    set at a switch T is checked on [T - 1 ms, T]."""
    g = TrotGains(pair_a=("FL_foot", "RR_foot"), pair_b=("FR_foot", "RL_foot"))
    env = {f"{f}_z": ca.SX.sym(f"{f}_z") for f in FEET}
    rows = touchdown_gaps(g.schedule(FEET), env)
    assert [r[0] for r in rows] == [f"touchdown_gap[{f}]" for f in ("FR_foot", "RL_foot", "FL_foot", "RR_foot")]
    np.testing.assert_allclose([r[2] for r in rows], [(0.179, 0.18)] * 2 + [(0.359, 0.36)] * 2, atol=1e-12)
    h = ca.Function("h", [env["FR_foot_z"]], [rows[0][1]])
    assert float(h(0.001)) == pytest.approx(0.002)
    with pytest.raises(KeyError):
        touchdown_gaps(SimpleNamespace(by_clock=False, phases=None), env)


def test_placeholder_limits_warn(a1):
    _, sys = a1
    prim = SimpleNamespace(name="P", system=sys, h_names=["qdot_max[FL_hip_joint]"])
    assert robot_limits(prim) is None  # the A1's limits are real ones (33.5 N m, 21 rad/s)
    fake = SimpleNamespace(is_rigid_body=True, u_hi=np.full(12, 1000.0), model=SimpleNamespace(
        joint_names=sys.model.joint_names, velocity_limits=np.full(12, 1000.0),
        position_limits=(np.full(12, -10.0), np.full(12, 10.0))))
    check = robot_limits(SimpleNamespace(name="P", system=fake, h_names=["qdot_max[FL_hip_joint]"]))
    assert check.status == "warn" and set(check.numbers["placeholders"]) == {"torque", "velocity", "position"}
    assert "system.torque_limit" in check.message
    check = robot_limits(SimpleNamespace(name="P", system=fake, h_names=[]))  # no joint_limits block
    assert set(check.numbers["placeholders"]) == {"torque"}


@pytest.mark.slow
def test_the_touchdown_gap_block_compiles_to_the_hand_written_rows(tmp_path):
    """specs/a1's Walk with `use: touchdown_gap` in place of its four rows: the same safety functions."""
    import shutil

    from mpgspec.compile.primitive import compile_primitive

    shutil.copytree(A1.parent, tmp_path / "a1")
    walk = tmp_path / "a1" / "primitives" / "walk.yaml"
    text = walk.read_text()
    walk.write_text(text[:text.index("  - name: touchdown_gap[FR_foot]")] + "  - use: touchdown_gap\n"
                    + text[text.index("\nroa:") + 1:])
    prims = []
    for project in (A1, tmp_path / "a1" / "project.yaml"):
        spec = load_project(project)
        inst = next(i for i in spec.primitives if i.name == "Walk(slow)")
        prims.append(compile_primitive(inst, compile_system(spec)))
    a, b = prims
    assert (a.h_names, a.windows, a.boundaries) == (b.h_names, b.windows, b.boundaries)
    assert a.h.serialize() == b.h.serialize()
