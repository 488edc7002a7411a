"""Contact, aerial and impact dynamics of the A1 against pinocchio's constraint solvers."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from a1_model import A1_FEET

from mpgspec.compile.rigidbody import Baumgarte, ContactDynamics

TOL = 1e-8
CONTACT_SETS = [A1_FEET, ("FL_foot", "RR_foot"), ("RL_foot",), ("FL_foot", "FR_foot", "RR_foot")]
PROX = pin.ProximalSettings(1e-14, 1e-14, 0.0, 1)  # mu = 0: exact KKT solve


def close(actual, expected, tol: float = TOL) -> None:
    actual = np.asarray(actual, dtype=float).ravel()
    expected = np.asarray(expected, dtype=float).ravel()
    scale = max(1.0, float(np.abs(expected).max(initial=0.0)))
    assert actual.shape == expected.shape
    assert np.abs(actual - expected).max(initial=0.0) <= tol * scale


@pytest.fixture(scope="module")
def states(model):
    rng = np.random.default_rng(7)
    return [(model.random_configuration(rng), rng.normal(size=model.nv),
             rng.normal(scale=10.0, size=model.nu)) for _ in range(10)]


def pin_contacts(model, names, q=None, gains=None):
    """CONTACT_3D constraints at the feet; with gains, anchored at the foot's ground projection."""
    pm = model.pin_model
    cms = pin.StdVec_RigidConstraintModel()
    pd = pm.createData()
    if q is not None:
        pin.framesForwardKinematics(pm, pd, q)
    for n in names:
        fid = pm.getFrameId(n)
        frame = pm.frames[fid]
        if gains is None:
            cm = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, pm, frame.parentJoint,
                                          frame.placement, pin.LOCAL_WORLD_ALIGNED)
        else:
            oMf = pd.oMf[fid]
            anchor = pin.SE3(oMf.rotation, np.r_[oMf.translation[:2], gains.ground_height])
            cm = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, pm, frame.parentJoint,
                                          frame.placement, 0, anchor, pin.LOCAL_WORLD_ALIGNED)
            cm.setBaumgarteCorrectorParameters(
                pin.BaumgarteCorrectorParameters(gains.beta ** 2, 2 * gains.alpha))
        cms.append(cm)
    cds = pin.StdVec_RigidConstraintData()
    for cm in cms:
        cds.append(cm.createData())
    return cms, cds


@pytest.mark.parametrize("names", CONTACT_SETS)
def test_contact_dynamics_matches_pinocchio(model, dyn, states, names):
    cd = ContactDynamics(dyn, names)
    pm, pd = model.pin_model, model.pin_model.createData()
    cms, cds = pin_contacts(model, names)
    pin.initConstraintDynamics(pm, pd, cms, cds)
    for q, v, u in states:
        a, lam = cd.forward(q, v, u)
        tau = model.actuation_matrix @ u
        close(a, pin.constraintDynamics(pm, pd, q, v, tau, cms, cds, PROX))
        close(lam, pd.lambda_c)
        xdot = np.array(cd.rhs(np.r_[q, v], u)).ravel()
        close(xdot, np.r_[np.array(dyn.qdot(q, v)).ravel(), np.array(a).ravel()], 1e-12)


def test_lambda_sign_is_ground_reaction(model, dyn):
    """Standing still with zero torque: the ground pushes the feet up with total weight."""
    cd = ContactDynamics(dyn, A1_FEET)
    q = model.neutral()
    q[2] = 0.4
    _, lam = cd.forward(q, np.zeros(model.nv), np.zeros(model.nu))
    lam = np.array(lam).reshape(4, 3)
    assert lam[:, 2].sum() > 0


def test_baumgarte_matches_pinocchio_corrector(model, dyn, states):
    gains = Baumgarte(alpha=3.0, beta=7.0, ground_height=0.05)
    cd = ContactDynamics(dyn, A1_FEET, gains)
    pm, pd = model.pin_model, model.pin_model.createData()
    for q, v, u in states:
        cms, cds = pin_contacts(model, A1_FEET, q, gains)
        pin.initConstraintDynamics(pm, pd, cms, cds)
        a, lam = cd.forward(q, v, u)
        close(a, pin.constraintDynamics(pm, pd, q, v, model.actuation_matrix @ u, cms, cds,
                                        PROX))
        close(lam, pd.lambda_c)


def test_aerial_dynamics_matches_aba(model, dyn, states):
    cd = ContactDynamics(dyn, ())
    pm, pd = model.pin_model, model.pin_model.createData()
    for q, v, u in states:
        a, lam = cd.forward(q, v, u)
        assert np.array(lam).size == 0
        close(a, pin.aba(pm, pd, q, v, model.actuation_matrix @ u))


@pytest.mark.parametrize("names", CONTACT_SETS)
def test_impact_map(model, dyn, states, names):
    cd = ContactDynamics(dyn, names)
    pm, pd = model.pin_model, model.pin_model.createData()
    cms, cds = pin_contacts(model, names)
    pin.initConstraintDynamics(pm, pd, cms, cds)
    for q, v, _ in states:
        v_plus, impulse = (np.array(x).ravel() for x in cd.impact(q, v))
        J_all = np.array(dyn.J_contacts(q))
        Jn = np.vstack([J_all[3 * A1_FEET.index(n):3 * A1_FEET.index(n) + 3] for n in names])
        M = np.array(dyn.M(q))
        assert np.abs(Jn @ v_plus).max() <= 1e-10 * max(1.0, np.abs(v).max())
        assert 0.5 * v_plus @ M @ v_plus <= 0.5 * v @ M @ v + 1e-12
        close(M @ (v_plus - v), Jn.T @ impulse)
        close(v_plus, pin.impulseDynamics(pm, pd, q, v, cms, cds, 0.0, PROX))
        close(impulse, np.concatenate([cdata.contact_force.linear for cdata in cds]))


def test_unknown_contact_rejected(dyn):
    with pytest.raises(KeyError):
        ContactDynamics(dyn, ("trunk",))
