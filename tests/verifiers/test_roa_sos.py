"""SOS toolkit: exact polynomial reading from CasADi, and float64 checks that reject bad certificates."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from verifiers import sos_certificates as sos
from verifiers.roa_common import ball_radius, validate_gram

x = ca.SX.sym("x", 2)
MOTZKIN = x[0] ** 4 * x[1] ** 2 + x[0] ** 2 * x[1] ** 4 - 3 * x[0] ** 2 * x[1] ** 2 + 1  # >= 0, not SOS


def test_reads_polynomial_coefficients_exactly():
    f = ca.Function("f", [x], [ca.vertcat(x[0] ** 3 / 2 - 3 * x[0] * x[1] + 7, (x[0] - x[1]) ** 2)])
    p, q = sos.from_casadi(f)
    assert p == {(3, 0): 0.5, (1, 1): -3.0, (0, 0): 7.0}
    assert q == {(2, 0): 1.0, (1, 1): -2.0, (0, 2): 1.0}
    shifted = sos.from_casadi(ca.Function("g", [x], [x[0] ** 2]), shift=np.array([1.0, 0.0]))[0]
    assert shifted == {(2, 0): 1.0, (1, 0): 2.0, (0, 0): 1.0}


@pytest.mark.parametrize("expr", [ca.sin(x[0]), ca.fmin(x[0], 1), 1 / (1 + x[1]), ca.fabs(x[0]), x[0] ** 0.5])
def test_non_polynomial_is_refused(expr):
    with pytest.raises(sos.NotPolynomial):
        sos.from_casadi(ca.Function("f", [x], [expr]))


def test_constant_subexpressions_are_folded():
    p = sos.from_casadi(ca.Function("f", [x], [ca.sin(ca.SX(0.5)) * x[0]]))[0]
    assert p == {(1, 0): pytest.approx(np.sin(0.5), rel=1e-15)}


def test_simple_sos_is_certified():
    p = sos.from_casadi(ca.Function("f", [x], [(x[0] - 2 * x[1]) ** 2 + x[1] ** 4 + 1]))[0]
    cert = sos.prove_sos(p, 2)
    assert cert.ok, cert.reason
    assert cert.gram_min_eig["sigma0_corrected"] > 0


def test_motzkin_loose_solver_claims_success_but_is_rejected():
    """Without Newton-polytope pruning, SCS at eps 1e-1 reports 'optimal' for the infeasible Motzkin
    SOS program; the float64 check rejects its Gram matrix."""
    p = sos.from_casadi(ca.Function("m", [x], [MOTZKIN]))[0]
    assert not sos.prove_sos(p, 2).ok  # accurate solver: infeasible
    cert = sos.prove_sos(p, 2, solver="SCS", solver_opts={"eps_abs": 1e-1, "eps_rel": 1e-1}, newton=False)
    assert cert.status in ("optimal", "optimal_inaccurate")
    assert not cert.ok
    assert "Gram eigenvalue check failed" in cert.reason
    assert cert.gram_min_eig["sigma0"] < -1e-3


def test_tampered_certificates_are_rejected():
    P = np.array([[1.5, -0.5], [-0.5, 1.0]])
    V = sos.quadratic(P)
    p = {(2, 0): 1.0, (0, 2): 1.0, (1, 1): 0.5, (0, 0): 2.0}  # > 0 everywhere
    prog = sos.LevelSetProgram(p, V, 2)
    good = prog.solve(1.0)
    assert good.ok, good.reason
    Q0, Q1 = good.grams["Q0"], good.grams["Q1"]
    assert not prog.check(1.0, Q0 + 1e-3, Q1).ok
    assert "residual check failed" in prog.check(1.0, Q0 + 1e-3, Q1).reason
    neg = prog.check(1.0, Q0, Q1 - 10 * np.eye(len(Q1)))
    assert not neg.ok and "multiplier" in neg.reason


def test_validate_gram_and_ball_radius():
    assert validate_gram(np.eye(3), 1e-9) == (True, 1.0)
    ok, e = validate_gram(np.diag([1.0, -1e-3]), 1e-6)
    assert not ok and e == pytest.approx(-1e-3)
    rng = np.random.default_rng(1)
    M, N = rng.standard_normal((2, 3, 3))
    P, W = M @ M.T + np.eye(3), N @ N.T + np.eye(3)
    r = ball_radius(P, 2.0, W)
    w, U = np.linalg.eigh(W)
    Wi = (U / np.sqrt(w)) @ U.T
    u = rng.standard_normal((20000, 3))
    y = r * (u / np.linalg.norm(u, axis=1, keepdims=True)) @ Wi  # on the W-sphere of radius r
    V = np.einsum("ij,jk,ik->i", y, P, y)
    assert V.max() <= 2.0 + 1e-9 and V.max() > 1.99
