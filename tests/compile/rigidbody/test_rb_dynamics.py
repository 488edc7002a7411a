"""Symbolic A1 kinematics and dynamics against pinocchio at random states."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from a1_model import A1_FEET

from mpgspec.compile.rigidbody import RigidBodyModel, find_urdf
from mpgspec.compile.rigidbody.linalg import dense_ldl_solve, dof_parents, tree_solve

TOL = 1e-8
N_STATES = 10


def close(actual, expected, tol: float = TOL) -> None:
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    scale = max(1.0, float(np.abs(expected).max(initial=0.0)))
    assert actual.shape == expected.shape
    assert np.abs(actual - expected).max(initial=0.0) <= tol * scale


@pytest.fixture(scope="module")
def states(model):
    rng = np.random.default_rng(42)
    return [(model.random_configuration(rng), rng.normal(size=model.nv),
             rng.normal(size=model.nv)) for _ in range(N_STATES)]


def np_(x) -> np.ndarray:
    return np.array(x, dtype=float)


def test_model_metadata(model):
    pm = model.pin_model
    assert (model.nq, model.nv, model.nu) == (19, 18, 12)
    assert model.contact_frames == A1_FEET
    assert model.joint_names[0] == "FL_hip_joint" and len(model.joint_names) == 12
    assert model.total_mass == pytest.approx(pin.computeTotalMass(pm))
    lo, hi = model.position_limits
    assert lo.shape == hi.shape == (12,) and np.all(lo < hi)
    assert np.allclose(model.velocity_limits, 21.0) and np.allclose(model.effort_limits, 33.5)
    assert np.array_equal(model.actuation_matrix[6:], np.eye(12))
    assert not model.actuation_matrix[:6].any()


def test_find_urdf_and_bad_frames():
    with pytest.raises(FileNotFoundError):
        find_urdf("no-such-package/robot.urdf")
    with pytest.raises(KeyError):
        RigidBodyModel(find_urdf("example-robot-data/robots/a1_description/urdf/a1.urdf"),
                       ["FL_toe"])


def test_mass_matrix_and_bias(model, dyn, states):
    pm, pd = model.pin_model, model.pin_model.createData()
    for q, v, a in states:
        M = pin.crba(pm, pd, q)
        M = np.triu(M) + np.triu(M, 1).T
        close(dyn.M(q), M)
        close(np_(dyn.nle(q, v)).ravel(), pin.nonLinearEffects(pm, pd, q, v))
        close(np_(dyn.rnea(q, v, a)).ravel(), pin.rnea(pm, pd, q, v, a))


def test_frame_placements_and_jacobians(model, dyn, states):
    pm, pd = model.pin_model, model.pin_model.createData()
    names = [f.name for f in model.frames]
    placements = {n: dyn.frame_placement(n) for n in names}
    jacobians = {n: dyn.frame_jacobian(n) for n in ("trunk", "FL_thigh", "RR_foot", "imu_link")}
    for q, _, _ in states:
        pin.framesForwardKinematics(pm, pd, q)
        pin.computeJointJacobians(pm, pd, q)
        for n in names:
            R, p = placements[n](q)
            oMf = pd.oMf[pm.getFrameId(n)]
            close(R, oMf.rotation)
            close(np_(p).ravel(), oMf.translation)
        feet = np.array([pd.oMf[pm.getFrameId(n)].translation for n in A1_FEET]).T
        close(dyn.fk_frames(q), feet)
        J = np.vstack([pin.getFrameJacobian(pm, pd, pm.getFrameId(n),
                                            pin.LOCAL_WORLD_ALIGNED)[:3] for n in A1_FEET])
        close(dyn.J_contacts(q), J)
        for n, f in jacobians.items():
            close(f(q), pin.getFrameJacobian(pm, pd, pm.getFrameId(n), pin.LOCAL_WORLD_ALIGNED))


def test_contact_drift_is_classical_acceleration(model, dyn, states):
    pm, pd = model.pin_model, model.pin_model.createData()
    for q, v, _ in states:
        pin.forwardKinematics(pm, pd, q, v, 0 * v)
        pin.updateFramePlacements(pm, pd)
        drift = np.concatenate([pin.getFrameClassicalAcceleration(
            pm, pd, pm.getFrameId(n), pin.LOCAL_WORLD_ALIGNED).linear for n in A1_FEET])
        close(np_(dyn.Jdot_v(q, v)).ravel(), drift)


def test_center_of_mass(model, dyn, states):
    pm, pd = model.pin_model, model.pin_model.createData()
    for q, _, _ in states:
        close(np_(dyn.com(q)).ravel(), pin.centerOfMass(pm, pd, q))
        close(dyn.J_com(q), pin.jacobianCenterOfMass(pm, pd, q))


@pytest.mark.parametrize("dt", [1e-3, 0.1, 1.0])
def test_integrate_matches_pinocchio(model, dyn, states, dt):
    for q, v, _ in states:
        close(np_(dyn.integrate(q, v, dt)).ravel(), pin.integrate(model.pin_model, q, v * dt))


@pytest.mark.parametrize("omega_scale", [0.0, 1e-6])
def test_integrate_small_rotation(model, dyn, states, omega_scale):
    q, v, _ = states[0]
    v = v.copy()
    v[3:6] *= omega_scale
    close(np_(dyn.integrate(q, v, 0.5)).ravel(), pin.integrate(model.pin_model, q, 0.5 * v),
          1e-12)


def test_qdot_is_derivative_of_integrate(model, dyn, states):
    dt = ca.SX.sym("dt")
    step = dyn.integrate(dyn.q, dyn.v, dt)
    ddt = ca.Function("ddt", [dyn.q, dyn.v, dt], [ca.jacobian(step, dt)])
    h = 1e-5
    for q, v, _ in states:
        qd = np_(dyn.qdot(q, v)).ravel()
        close(np_(ddt(q, v, 0.0)).ravel(), qd, 1e-12)
        fd = (pin.integrate(model.pin_model, q, h * v) - pin.integrate(model.pin_model, q, -h * v))
        close(fd / (2 * h), qd, 1e-7)


def test_normalize_quaternion(model, dyn, states):
    q = states[0][0].copy()
    q[3:7] *= 1.7
    out = np_(dyn.normalize(q)).ravel()
    assert np.linalg.norm(out[3:7]) == pytest.approx(1.0)
    close(out, states[0][0], 1e-14)


def test_tree_and_dense_solves(model, dyn, states):
    q = states[0][0]
    M = np_(dyn.M(q))
    b = np.random.default_rng(3).normal(size=(model.nv, 2))
    B = ca.SX.sym("b", model.nv, 2)
    f = ca.Function("s", [dyn.q, B], [tree_solve(dyn.M_expr, dof_parents(model), B)])
    close(f(q, b), np.linalg.solve(M, b), 1e-10)
    A = ca.SX.sym("A", 5, 5)
    g = ca.Function("d", [A], [dense_ldl_solve(A, ca.DM.ones(5, 1))])
    X = np.random.default_rng(4).normal(size=(5, 5))
    S = X @ X.T + 5 * np.eye(5)
    close(np_(g(S)).ravel(), np.linalg.solve(S, np.ones(5)), 1e-12)
