"""Contact modes (a mask over the feet) against pinocchio, for each mode of a trot.

The scheduled loop of a compiled A1 holds the feet whose mode is 1 with the one masked
Schur-complement solver; its accelerations and forces must equal pinocchio's constraintDynamics
with the same feet (Baumgarte corrector anchored at the feet's ground projection), and the
masked impact must equal pinocchio's impulseDynamics.
"""
from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from mpgspec.compile.rigidbody.hybrid import masked_impact
from mpgspec.compile.system import compile_system
from mpgspec.spec.loader import load_project

from test_rb_constrained import PROX, close, pin_contacts  # noqa: E402 (rootdir-relative, as pytest imports it)

A1 = Path(__file__).parents[3] / "specs" / "a1" / "project.yaml"
FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")
TROT_MODES = [FEET, ("FL_foot", "RR_foot"), ("FR_foot", "RL_foot"), ()]


@pytest.fixture(scope="module")
def a1():
    return compile_system(load_project(A1))


@pytest.fixture(scope="module")
def states(a1):
    rng = np.random.default_rng(3)
    m = a1.model
    return [(m.random_configuration(rng), rng.normal(size=m.nv), rng.normal(scale=10.0, size=m.nu))
            for _ in range(6)]


def _mode(held):
    return {f: ca.SX(1.0 if f in held else 0.0) for f in FEET}


@pytest.mark.parametrize("held", TROT_MODES, ids=["four", "FL+RR", "FR+RL", "aerial"])
def test_masked_dynamics_match_pinocchio(a1, states, held):
    m = a1.model
    loop = a1.scheduled_loop(_mode(held))
    lam_all = ca.vertcat(*[loop.env[f"{f}_f{ax}"] for f in FEET for ax in "xyz"])
    fn = ca.Function("fn", [a1.x, a1.u], [loop.xdot[m.nq:m.nq + m.nv], lam_all])
    pm, pd = m.pin_model, m.pin_model.createData()
    for q, v, u in states:
        a, lam = (np.array(z).ravel() for z in fn(np.r_[q, v, np.zeros(a1.nx - q.size - v.size)], u))
        tau = m.actuation_matrix @ u
        if held:
            cms, cds = pin_contacts(m, held, q, a1.baumgarte)
            pin.initConstraintDynamics(pm, pd, cms, cds)
            close(a, pin.constraintDynamics(pm, pd, q, v, tau, cms, cds, PROX))
            rows = [3 * FEET.index(f) + k for f in held for k in range(3)]
            close(lam[rows], pd.lambda_c)
        else:
            close(a, pin.aba(pm, pd, q, v, tau))
        free = [3 * i + k for i, f in enumerate(FEET) if f not in held for k in range(3)]
        assert np.all(lam[free] == 0)  # a foot the mode does not hold gets no force


@pytest.mark.parametrize("held", TROT_MODES[:3], ids=["four", "FL+RR", "FR+RL"])
def test_masked_impact_matches_pinocchio(a1, states, held):
    m = a1.model
    q_s, v_s = ca.SX.sym("q", m.nq), ca.SX.sym("v", m.nv)
    c = ca.DM([1.0 if f in held else 0.0 for f in FEET])
    fn = ca.Function("imp", [q_s, v_s], [masked_impact(a1, q_s, v_s, c)])
    pm, pd = m.pin_model, m.pin_model.createData()
    cms, cds = pin_contacts(m, held)
    pin.initConstraintDynamics(pm, pd, cms, cds)
    for q, v, _ in states:
        close(np.array(fn(q, v)).ravel(), pin.impulseDynamics(pm, pd, q, v, cms, cds, 0.0, PROX))
