"""Legs from the kinematic tree: every leg's joints are the actuated joints on the path from the
floating base to its foot (checked against pinocchio's own tree for three robots), and a URDF whose
joints come in another order gives the same trot, joint by joint."""
from __future__ import annotations

import re
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from mpgspec.compile.rigidbody.legs import leg_name, resolve_legs
from a1_model import A1_URDF

from mpgspec.compile.rigidbody.model import RigidBodyModel, find_urdf
from mpgspec.compile.system import compile_system
from mpgspec.robots.quadruped.stance import nominal_geometry
from mpgspec.robots.quadruped.trot import gains_of, trot_torque
from mpgspec.spec.loader import load_project

ROBOTS = {
    "a1": (A1_URDF, ("FL_foot", "FR_foot", "RL_foot", "RR_foot"), ("FL", "FR", "RL", "RR")),
    "anymal_b": ("example-robot-data/robots/anymal_b_simple_description/robots/anymal.urdf",
                 ("LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"), ("LF", "RF", "LH", "RH")),
    "solo12": ("example-robot-data/robots/solo_description/robots/solo12.urdf",
               ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"), ("FL", "FR", "HL", "HR")),
}


def _tree_path(pm: pin.Model, frame: str) -> list[int]:
    """Joint ids from the root to `frame`'s parent joint, by pinocchio's `parents`, without the
    universe and the free flyer."""
    j = pm.frames[pm.getFrameId(frame)].parentJoint
    path = []
    while j > 0:
        if pm.joints[j].shortname() != "JointModelFreeFlyer":
            path.append(j)
        j = pm.parents[j]
    return path[::-1]


@pytest.mark.parametrize("robot", list(ROBOTS))
def test_leg_indices_are_the_kinematic_tree_paths(robot):
    urdf, feet, names = ROBOTS[robot]
    model = RigidBodyModel(find_urdf(urdf), feet)
    legs = resolve_legs(SimpleNamespace(legs=None), model, None)
    pm = model.pin_model
    assert tuple(g.name for g in legs) == names
    assert tuple(g.foot for g in legs) == feet
    for g in legs:
        path = _tree_path(pm, g.foot)
        assert g.joints == tuple(pm.names[j] for j in path)
        assert g.q == tuple(pm.joints[j].idx_q for j in path)
        assert g.v == tuple(pm.joints[j].idx_v for j in path)
        assert g.u == tuple(pm.joints[j].idx_v - 6 for j in path)
        assert len(g.joints) == 3
    assert sorted(k for g in legs for k in g.u) == list(range(model.nu))  # the legs hold every joint


def test_anymal_legs_are_not_the_contact_order_slices():
    """ANYmal's tree orders its legs LF, LH, RF, RH while its feet are listed LF, RF, LH, RH: the
    slice 3 i : 3 i + 3 of the old laws took RF's torques to LH's joints."""
    urdf, feet, _ = ROBOTS["anymal_b"]
    legs = resolve_legs(SimpleNamespace(legs=None), RigidBodyModel(find_urdf(urdf), feet), None)
    assert [g.u for g in legs] == [(0, 1, 2), (6, 7, 8), (3, 4, 5), (9, 10, 11)]


def test_leg_names_derived_from_the_foot_frames():
    assert [leg_name(f) for f in ("FL_foot", "LF_FOOT", "foot", "hand")] == ["FL", "LF", "foot", "hand"]


RENAMED = {"RR_hip_joint": "A_RR_hip_joint", "FR_hip_joint": "B_FR_hip_joint"}
"""Pinocchio orders sibling joints by name: these names put the legs in the order RR, FR, FL, RL."""

PROJECT = """project: legs
system:
  kind: rigid_body
  name: a1
  urdf: {urdf}
  contacts: [FL_foot, FR_foot, RL_foot, RR_foot]
  torque_limit: 33.5
primitives:
  - name: Walk
    class: periodic
    period: 0.36
    setpoint: {{named: {{base_z: 0.26}}}}
    controller:
      type: trot
      speed: 0.3
      pose: {{FL_thigh_joint: 0.8, FR_thigh_joint: 0.8, RL_thigh_joint: 0.8, RR_thigh_joint: 0.8,
             FL_calf_joint: -1.6, FR_calf_joint: -1.6, RL_calf_joint: -1.6, RR_calf_joint: -1.6}}
    roa: {{radius: 0.01}}
"""


def _trot(tmp_path, name: str, urdf_text: str):
    """The trot's u(x, t) on the robot of `urdf_text`, with its system."""
    (tmp_path / f"{name}.urdf").write_text(urdf_text)
    (tmp_path / f"{name}.yaml").write_text(PROJECT.format(urdf=f"{name}.urdf"))
    spec = load_project(tmp_path / f"{name}.yaml")
    sys = compile_system(spec)
    c = spec.primitives[0].spec.controller
    g = gains_of(c, 0.3, sys)
    t = ca.SX.sym("t")
    feet = tuple(sys.model.contact_frames)
    inertia, offsets = nominal_geometry(sys, dict(c.pose))
    u = trot_torque(sys, g, t, g.schedule(feet).mode(feet, t), inertia, offsets)
    return sys, ca.Function("u", [sys.x, t], [u])


def test_a_urdf_with_its_joints_in_another_order_gives_the_same_trot(tmp_path):
    text = find_urdf(A1_URDF).read_text()
    permuted = text
    for old, new in RENAMED.items():
        permuted = re.sub(rf'"{old}"', f'"{new}"', permuted)
    sys_a, u_a = _trot(tmp_path, "a1", text)
    sys_b, u_b = _trot(tmp_path, "permuted", permuted)
    back = {v: k for k, v in RENAMED.items()}
    rename = lambda n: next((n.replace(v, k) for v, k in back.items() if v in n), n)  # noqa: E731
    joints_b = [rename(j) for j in sys_b.model.joint_names]
    assert joints_b[:3] == ["RR_hip_joint", "RR_thigh_joint", "RR_calf_joint"]  # the order did change
    assert sorted(joints_b) == sorted(sys_a.model.joint_names)
    x_index = [sys_a.state_names.index(rename(n)) for n in sys_b.state_names]
    u_index = [sys_a.input_names.index(rename(n)) for n in sys_b.input_names]
    rng = np.random.default_rng(26)
    for _ in range(3):
        x = sys_a.default_state()
        x[2] = 0.27
        quat = np.array([0.05, -0.04, 0.1, 1.0]) + 0.02 * rng.normal(size=4)
        x[3:7] = quat / np.linalg.norm(quat)
        nq = sys_a.model.nq
        x[7:nq] = np.tile([0.0, 0.8, -1.6], 4) + 0.2 * rng.normal(size=nq - 7)
        x[nq:nq + sys_a.model.nv] = 0.3 * rng.normal(size=sys_a.model.nv)
        t = float(rng.uniform(0, 0.36))
        ua = np.array(u_a(x, t), float).ravel()
        ub = np.array(u_b(x[x_index], t), float).ravel()
        np.testing.assert_allclose(ub, ua[u_index], rtol=1e-9, atol=1e-9)
