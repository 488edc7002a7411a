"""Empirical radius by rollouts: between the certified Lyapunov ball and the true boundary."""
from __future__ import annotations

import casadi as ca
import numpy as np

from mpgspec.api import compile_project
from mpgspec.spec.loader import load_project
from mpgspec.certify.problem import RoAProblem, from_primitive
from verifiers import lyapunov, sampling

x = ca.SX.sym("x", 2)
VDP = RoAProblem(ca.Function("f", [x], [ca.vertcat(-x[1], x[0] + (x[0] ** 2 - 1) * x[1])]), np.zeros(2))
LC_DISTANCE = 1.5317  # distance from the origin to the limit cycle of Van der Pol (mu = 1)


def test_van_der_pol_radius_between_certificate_and_limit_cycle():
    emp = sampling.verifier.estimate(VDP, {})
    cert = lyapunov.verifier.estimate(VDP, {})
    assert emp.level == "empirical"
    assert cert.radius <= emp.radius <= LC_DISTANCE


def test_half_space_limits_the_radius():
    A = ca.DM([[0.0, 1.0], [-2.0, -3.0]])
    prob = RoAProblem(ca.Function("f", [x], [ca.mtimes(A, x)]), np.zeros(2), ca.Function("h", [x], [1 - x[0]]))
    res = sampling.verifier.estimate(prob, {})
    assert 0.87 <= res.radius <= 1.0  # Lyapunov certifies 0.874; (1 + eps, 0) starts outside C
    assert res.evidence["bisection"][-1]["unsafe"] >= 0


def test_pendulum_fixed_primitives_lyapunov_inside_sampling():
    prims = compile_project(load_project("specs/pendulum/project.yaml"))
    for name in ("Hang", "Balance"):
        prob = from_primitive(prims[name])
        lyap = lyapunov.verifier.estimate(prob, {})
        emp = sampling.verifier.estimate(prob, {"samples": 128})
        assert lyap.level == "empirical", lyap.message  # saturation and |omega| are not polynomial
        assert 0 < lyap.radius <= emp.radius
