"""Lyapunov level sets: exact answer for a linear loop in a half-space, soundness on Van der Pol."""
from __future__ import annotations

import json

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mpgspec.certify.problem import RoAProblem
from verifiers import lyapunov, sos
from verifiers.roa_common import ball_radius

x = ca.SX.sym("x", 2)
A = np.array([[0.0, 1.0], [-2.0, -3.0]])
LINEAR = RoAProblem(ca.Function("f", [x], [ca.mtimes(ca.DM(A), x)]), np.zeros(2),
                    ca.Function("h", [x], [1 - x[0]]), name="linear")
VDP = RoAProblem(ca.Function("f", [x], [ca.vertcat(-x[1], x[0] + (x[0] ** 2 - 1) * x[1])]), np.zeros(2),
                 name="reversed Van der Pol")


def test_linear_half_space_matches_analytic_level():
    res = lyapunov.verifier.estimate(LINEAR, {})
    assert res.level == "certified", res.message
    P = np.array(res.evidence["P"])
    c = np.array([1.0, 0.0])
    rho_star = 1.0 / (c @ np.linalg.solve(P, c))  # min of V on {c'x = 1}
    rho = res.evidence["rho"]
    assert rho <= rho_star and rho >= 0.99 * rho_star
    assert res.radius == pytest.approx(np.sqrt(rho / np.linalg.eigvalsh(P).max()))
    json.dumps(res.to_dict())


def test_weights_shape_the_ball():
    W = np.diag([4.0, 1.0])
    res = lyapunov.verifier.estimate(RoAProblem(LINEAR.f, LINEAR.x_star, LINEAR.h, W), {})
    P = np.array(res.evidence["P"])
    assert res.radius == pytest.approx(ball_radius(P, res.evidence["rho"], W))


def _limit_cycle() -> np.ndarray:
    """The unstable limit cycle of the reversed system: the attractor of forward-time Van der Pol."""
    fwd = lambda t, z: [z[1], -z[0] + (1 - z[0] ** 2) * z[1]]  # noqa: E731
    z = solve_ivp(fwd, (0, 60), [2.0, 0.0], rtol=1e-10, atol=1e-12).y[:, -1]
    return solve_ivp(fwd, (0, 7), z, rtol=1e-10, atol=1e-12, max_step=0.01).y.T


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd rule for points against a closed polygon."""
    a, b = poly, np.roll(poly, -1, axis=0)
    px, py = pts[:, :1], pts[:, 1:]
    cross = (a[:, 1] > py) != (b[:, 1] > py)
    xint = a[:, 0] + (py - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1] + 1e-300)
    return ((cross & (px < xint)).sum(axis=1) % 2) == 1


def test_van_der_pol_level_set_is_inside_the_true_region_of_attraction():
    res = lyapunov.verifier.estimate(VDP, {})
    assert res.level == "certified", res.message
    P, rho = np.array(res.evidence["P"]), res.evidence["rho"]
    assert rho > 2.0 and res.radius >= 0.5
    # the exact largest level with Vdot < 0 (dense grid) bounds any sound certificate
    g = np.linspace(-3, 3, 1201)
    X, Y = np.meshgrid(g, g)
    pts = np.c_[X.ravel(), Y.ravel()]
    f = np.c_[-pts[:, 1], pts[:, 0] + (pts[:, 0] ** 2 - 1) * pts[:, 1]]
    V = np.einsum("ij,jk,ik->i", pts, P, pts)
    Vdot = 2 * np.einsum("ij,jk,ik->i", pts, P, f)
    assert rho <= V[(Vdot >= 0) & (V > 1e-9)].min()
    # boundary points: inside the limit cycle, and they converge to the origin
    th = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    L = np.linalg.cholesky(P)
    bnd = np.sqrt(rho) * np.linalg.solve(L.T, np.vstack([np.cos(th), np.sin(th)])).T
    assert np.allclose(np.einsum("ij,jk,ik->i", bnd, P, bnd), rho)
    assert _inside(_limit_cycle(), bnd).all()
    z = bnd.T.copy()
    dt = 0.01
    f2 = lambda z: np.vstack([-z[1], z[0] + (z[0] ** 2 - 1) * z[1]])  # noqa: E731
    for _ in range(3000):
        k1 = f2(z)
        k2 = f2(z + dt / 2 * k1)
        k3 = f2(z + dt / 2 * k2)
        k4 = f2(z + dt * k3)
        z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert np.abs(z).max() < 1e-3


def test_sos_verifier_agrees_and_non_polynomial_is_empirical():
    cert = sos.verifier.estimate(VDP, {})
    assert cert.level == "certified" and cert.method == "sos"
    emp = lyapunov.verifier.estimate(VDP, {"polynomial": False})
    assert emp.level == "empirical"
    assert emp.evidence["rho"] == pytest.approx(cert.evidence["rho"], rel=0.03)
    sin_loop = RoAProblem(ca.Function("f", [x], [ca.vertcat(x[1], -ca.sin(x[0]) - x[1])]), np.zeros(2))
    assert lyapunov.verifier.estimate(sin_loop, {}).level == "empirical"
    refused = sos.verifier.estimate(sin_loop, {})
    assert refused.level == "failed" and "not polynomial" in refused.message


def test_loose_solver_answer_is_rejected_not_certified():
    """At rho = 2.6 (beyond the true maximum ~2.31) SCS with eps 1e-1 returns 'optimal'."""
    res = lyapunov.verifier.estimate(VDP, {"rho": 2.6, "solver": "SCS",
                                           "solver_opts": {"eps_abs": 1e-1, "eps_rel": 1e-1, "max_iters": 100}})
    assert res.level == "failed" and res.radius == 0.0
    rejected = res.evidence["parts"][-1]["last_rejected"]
    assert rejected["status"] in ("optimal", "optimal_inaccurate")
    assert "Gram eigenvalue check failed" in res.message


def test_unstable_or_unsafe_setpoints_fail():
    unstable = RoAProblem(ca.Function("f", [x], [ca.vertcat(x[1], x[0] - x[1])]), np.zeros(2))
    res = lyapunov.verifier.estimate(unstable, {})
    assert res.level == "failed" and "not Hurwitz" in res.message
    outside = RoAProblem(LINEAR.f, LINEAR.x_star, ca.Function("h", [x], [x[0] - 1]))
    assert lyapunov.verifier.estimate(outside, {}).level == "failed"
