"""Floquet multipliers against closed forms, and the pendulum's Swing primitive end to end."""
from __future__ import annotations

import json

import casadi as ca
import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.spec.loader import load_project
from mpgspec.certify.problem import PeriodicProblem, from_primitive
from verifiers import floquet

x, t = ca.SX.sym("x", 2), ca.SX.sym("t")
ZERO = ca.Function("xs", [t], [ca.DM.zeros(2)])
FAST = {"samples": 32, "steps_per_period": 100}


def test_decoupled_scalar_multipliers_are_exp_of_integral():
    """x_i' = a_i(t) x_i has multiplier exp(int_0^T a_i)."""
    a = ca.vertcat(-0.3 + ca.sin(t), -0.1 + 2 * ca.cos(t))
    prob = PeriodicProblem(ca.Function("f", [x, t], [a * x]), ZERO, 2 * np.pi)
    res = floquet.verifier.estimate(prob, FAST)
    mods = sorted(res.evidence["multiplier_moduli"])
    assert mods == pytest.approx(sorted(np.exp([-0.3 * 2 * np.pi, -0.1 * 2 * np.pi])), rel=1e-8)
    assert res.evidence["verdict"] == "locally exponentially stable"
    assert res.level == "empirical" and res.radius > 1.0  # linear: every tested radius converges
    json.dumps(res.to_dict())


def test_commuting_periodic_matrix():
    """x' = (A + cos(t) I) x with A = [[-0.1, 1], [-1, -0.1]]: Phi(2 pi) = exp(2 pi A), |mu| = exp(-0.2 pi)."""
    A = ca.DM([[-0.1, 1.0], [-1.0, -0.1]])
    prob = PeriodicProblem(ca.Function("f", [x, t], [ca.mtimes(A, x) + ca.cos(t) * x]), ZERO, 2 * np.pi)
    m = floquet.monodromy(prob)
    from scipy.linalg import expm
    assert m["Phi"] == pytest.approx(expm(2 * np.pi * np.array(A)), abs=1e-9)


def test_unstable_periodic_system_fails():
    prob = PeriodicProblem(ca.Function("f", [x, t], [(0.05 + ca.sin(t)) * x]), ZERO, 2 * np.pi)
    res = floquet.verifier.estimate(prob, FAST)
    assert res.level == "failed" and res.radius == 0.0
    assert res.evidence["spectral_radius"] == pytest.approx(np.exp(0.1 * np.pi), rel=1e-8)


def test_autonomous_orbit_sets_the_trivial_multiplier_aside():
    """Hopf normal form: unit-circle orbit, radial rate -2, so multipliers 1 and exp(-4 pi)."""
    r2 = x[0] ** 2 + x[1] ** 2
    f = ca.Function("f", [x, t], [ca.vertcat(x[0] - x[1] - x[0] * r2, x[0] + x[1] - x[1] * r2)])
    orbit = ca.Function("xs", [t], [ca.vertcat(ca.cos(t), ca.sin(t))])
    res = floquet.verifier.estimate(PeriodicProblem(f, orbit, 2 * np.pi), FAST)
    mu = np.array(res.evidence["multiplier_moduli"])
    assert res.evidence["autonomous"] and mu[res.evidence["trivial_multiplier"]] == pytest.approx(1, abs=1e-8)
    assert res.evidence["spectral_radius"] == pytest.approx(np.exp(-4 * np.pi), rel=1e-4)
    assert res.evidence["verdict"] == "orbitally exponentially stable"
    # Definition 1 asks for convergence to x*(t): tangential offsets keep their phase shift
    assert res.level == "failed" and "phase" in res.message


def test_pendulum_swing_matches_computed_torque_error_dynamics():
    """Computed torque leaves e'' + 6 e' + 16 e = 0 (unsaturated): both |mu| = exp(-3 T)."""
    prims = compile_project(load_project("specs/pendulum/project.yaml"))
    swing = prims["Swing(1)"]
    prob = from_primitive(swing)
    assert isinstance(prob, PeriodicProblem) and prob.period == swing.period
    res = floquet.verifier.estimate(prob, {})
    assert res.evidence["multiplier_moduli"] == pytest.approx([np.exp(-3 * swing.period)] * 2, rel=1e-6)
    assert res.evidence["orbit_defect"] < 1e-8
    assert res.level == "empirical"
    # the tube covers the hand-picked 0.15 and is no wider than the tracking band |theta - theta*| <= 1.2
    # (up to the 1% resolution of the bisection: sampled starts rarely hit the band's corner exactly)
    assert swing.radius <= res.radius <= 1.2 * 1.01


def test_a_small_loops_period_map_ends_where_its_steps_end():
    """The pendulum's Swing loops are inlined (no loop library): HybridFlow's period map, which takes
    f, the law and h at each state once, gives the last column of its step-by-step period bit for bit
    (states, clock and least h) from starts inside and outside C."""
    from mpgspec.certify.hybrid_orbit import HybridFlow
    from mpgspec.oracle.looplib import attach

    prims = compile_project(load_project("specs/pendulum/project.yaml"))
    rng = np.random.default_rng(5)
    for name in ("Swing(1)", "Swing(2.6)"):
        p = prims[name]
        assert attach(p) is None  # the inlined path of hybrid_orbit._parts
        flow = HybridFlow(p, p.period / 100)
        xs = np.array(p.setpoint(0.0), float).ravel()
        X0 = xs[:, None] + np.c_[np.zeros(xs.size), 0.5 * rng.standard_normal((xs.size, 5))]
        t0 = np.round(rng.random(6) * flow.steps) * flow.dt
        Z = np.vstack([X0, t0[None, :], np.full((1, 6), np.inf)])
        end = np.array(flow.period_end.map(6)(Z), float)
        last = np.stack([flow.states(X0[:, j], t0[j])[:, -1] for j in range(6)], 1)
        assert np.array_equal(end, last), name
