"""specs/anymal, the second robot: ANYmal B from example-robot-data's URDF, written in the spec format
only. Its legs are named LF, RF, LH, RH and pinocchio orders their joints LF, LH, RF, RH (by the
tree), so every leg's joints must come from the tree; its gait tables must be fresh and stable."""
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from mpgspec import api
from mpgspec.robots.quadruped.setup import gait_header
from mpgspec.robots.quadruped.trot import gains_of
from mpgspec.spec.loader import load_project

PROJECT = Path(__file__).parents[1] / "specs" / "anymal"
LEGS = ("LF", "RF", "LH", "RH")


@pytest.fixture(scope="module")
def anymal():
    spec = load_project(PROJECT / "project.yaml")
    return spec, api.compile_project(spec)


def test_project_compiles_with_its_primitives(anymal):
    spec, prims = anymal
    assert sorted(prims) == ["Lie", "Stand", "Walk(in_place)", "Walk(slow)"]
    sys = prims["Stand"].system
    assert sys.model.nu == 12 and sys.model.floating_base
    assert float(sys.u_hi.max()) == float(sys.u_hi.min()) == 80.0
    # the stance the setpoints name: base about 0.47 m high, the lying base about 0.21 m
    names = sys.state_names
    assert prims["Stand"].x_star(0.0)[names.index("base_z")] == pytest.approx(0.4686, abs=1e-3)
    assert prims["Lie"].x_star(0.0)[names.index("base_z")] == pytest.approx(0.206, abs=1e-3)


def test_every_leg_has_the_joints_on_its_tree_path(anymal):
    _, prims = anymal
    sys = prims["Walk(slow)"].system
    pm = sys.model.pin_model
    legs = {leg.name: leg for leg in sys.legs}
    assert tuple(legs) == LEGS
    for name, leg in legs.items():
        assert leg.foot == f"{name}_FOOT"
        assert leg.joints == tuple(f"{name}_{j}" for j in ("HAA", "HFE", "KFE"))
        ids = [pm.getJointId(j) for j in leg.joints]
        assert leg.q == tuple(pm.joints[i].idx_q for i in ids)
        assert leg.v == tuple(pm.joints[i].idx_v for i in ids)
        assert [sys.input_names[k] for k in leg.u] == [f"tau_{j}" for j in leg.joints]
        assert [sys.state_names[k] for k in leg.q] == list(leg.joints)
        # the tree's path from the base: each joint is the parent of the next
        assert [pm.parents[b] for b in ids[1:]] == ids[:-1]
    # the URDF orders the legs LF, LH, RF, RH: the contact order is not the joint order
    assert [legs[n].u[0] for n in LEGS] == [0, 6, 3, 9]


def test_trot_pairs_and_robot_defaults(anymal):
    spec, prims = anymal
    sys = prims["Walk(slow)"].system
    inst = next(i for i in spec.primitives if i.name == "Walk(slow)")
    g = gains_of(inst.spec.controller, 0.2, sys)
    assert g.pair_a == ("LF_FOOT", "RH_FOOT") and g.pair_b == ("RF_FOOT", "LH_FOOT")
    weight = float(sys.model.total_mass) * 9.81
    assert g.f_min == pytest.approx(0.075 * weight, rel=1e-3)  # 7.5 % of the weight, about 22 N
    assert g.height == pytest.approx(0.4496, abs=1e-3)  # the CoM height of the trot's pose
    assert g.period == pytest.approx(prims["Walk(slow)"].period)


@pytest.mark.parametrize("speed", ["0", "0.2"])
def test_gait_tables_hold_stable_orbits(speed):
    head = gait_header(PROJECT / "gaits" / f"walk_{speed}.csv")
    assert head["status"] == "converged" and float(head["residual"]) < 1e-9
    assert float(head["spectral_radius"]) < 0.1
    assert float(head["mean_speed"]) == pytest.approx(float(speed), abs=1e-6)
    assert float(head["peak_torque"]) < 80 and float(head["least_cone_margin"]) > 0


def test_gait_tables_match_their_regeneration():
    run = api.gait(PROJECT / "gaits.yaml", check=True)
    assert run.unstable == [] and run.stale == []
    assert [t.node for t in run.tables] == ["Walk(in_place)", "Walk(slow)"]


@pytest.mark.slow
def test_project_verifies():
    """Lie <-> Stand, Stand -> Walk, the walks both ways and the sequence: every assertion holds
    (about 2 minutes cold, 10 s with the oracle cache)."""
    p = api.verify([PROJECT], out_dir=None).projects[0]
    assert p.status == "pass", [a for a in p.report["assertions"] if a["status"] != "pass"]
    edges = {(e["from"], e["to"]) for e in p.report["edges"]}
    assert {("Lie", "Stand"), ("Stand", "Lie"), ("Stand", "Walk(in_place)"), ("Stand", "Walk(slow)")} <= edges
    radii = {q["name"]: q["roa_radius"] for q in p.report["primitives"]}
    assert min(radii["Walk(in_place)"], radii["Walk(slow)"]) > 1e-3  # E of the walks is not collapsed
    assert np.isfinite(list(radii.values())).all()
