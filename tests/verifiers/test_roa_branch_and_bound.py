"""Certified Lyapunov levels of non-polynomial loops by interval branch-and-bound: known answers,
levels that must not be certified, and the pendulum's Balance."""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from flint import arb

from mpgspec.api import compile_project
from mpgspec.certify.problem import RoAProblem, from_primitive
from mpgspec.certify.roa import _options, _sized
from mpgspec.spec.loader import load_project
from verifiers import lyapunov, lyapunov_bnb as bnb, sos

PENDULUM = Path(__file__).resolve().parents[2] / "specs" / "pendulum"
x1 = ca.SX.sym("x", 1)
x2 = ca.SX.sym("x", 2)
SIN = RoAProblem(ca.Function("f", [x1], [-ca.sin(x1)]), np.zeros(1), name="xdot = -sin x")
RHO_SIN = 0.5 * np.pi ** 2  # V = x^2 / 2; the region of attraction is |x| < pi, where Vdot = -x sin x = 0


def _prover(problem: RoAProblem, P) -> bnb.LevelProver:
    f, h = bnb.tapes(problem.f, problem.h)
    return bnb.LevelProver(f, h, problem.x_star, np.atleast_2d(P))


def test_one_dimensional_known_boundary_is_respected():
    prover = _prover(SIN, 0.5)
    below = prover.prove(RHO_SIN * 0.98 ** 2)
    assert below.ok and below.inner >= 1 and below.eps == 0.0
    for scale in (1 + 1e-9, 1.02):  # beyond |x| = pi, Vdot > 0: however thin the slice, no proof
        res = prover.prove(RHO_SIN * scale ** 2, budget=2000)
        assert not res.ok
    beyond = prover.prove(RHO_SIN * 1.02 ** 2)
    assert beyond.counterexample is not None and abs(beyond.counterexample[0]) > np.pi


def test_verifier_certifies_just_below_the_known_boundary():
    res = lyapunov.verifier.estimate(SIN, {"require_certified": True})
    assert res.level == "certified", res.message
    rho = res.evidence["rho"]
    assert 0.95 * RHO_SIN <= rho < RHO_SIN
    assert res.radius <= np.sqrt(2 * rho) and res.radius == pytest.approx(np.sqrt(2 * rho), rel=1e-6)
    assert "branch-and-bound" in res.message and "boxes" in res.message
    json.dumps(res.to_dict())
    assert lyapunov.verifier.estimate(SIN, {}).level == "empirical"  # without the requirement: sampled
    assert sos.verifier.estimate(SIN, {}).level == "failed"  # sos stays SOS only


def test_linear_loop_in_a_kinked_safe_set_matches_the_exact_level():
    """Linear loop (Vdot by SOS) in |x_0| < 1 (by branch-and-bound): the largest level is 1 / (P^-1)_00."""
    A = np.array([[0.0, 1.0], [-2.0, -3.0]])
    prob = RoAProblem(ca.Function("f", [x2], [ca.mtimes(ca.DM(A), x2)]), np.zeros(2),
                      ca.Function("h", [x2], [1 - ca.fabs(x2[0])]))
    res = lyapunov.verifier.estimate(prob, {"require_certified": True})
    assert res.level == "certified", res.message
    P = np.array(res.evidence["P"])
    rho_star = 1.0 / np.linalg.inv(P)[0, 0]
    assert 0.95 * rho_star <= res.evidence["rho"] < rho_star
    parts = {pt["part"]: pt for pt in res.evidence["parts"]}
    assert parts["h[0]"]["certified_by"] == "branch_and_bound" and "certified_by" not in parts["Vdot"]
    assert res.evidence["branch_and_bound"][-1]["parts"] == ["h"]
    assert "Vdot by SOS" in res.message
    over = lyapunov.verifier.estimate(prob, {"require_certified": True, "rho": 1.01 * rho_star})
    assert over.level == "failed" and over.radius == 0.0


def test_level_with_increasing_v_inside_is_not_certified():
    """Reversed Van der Pol read as non-polynomial: Vdot > 0 inside {V <= 2.6} (the true level is ~2.31)."""
    vdp = RoAProblem(ca.Function("f", [x2], [ca.vertcat(-x2[1], x2[0] + (x2[0] ** 2 - 1) * x2[1])]), np.zeros(2))
    res = lyapunov.verifier.estimate(vdp, {"require_certified": True, "polynomial": False, "rho": 2.6})
    assert res.level == "failed" and res.radius == 0.0
    attempt, = res.evidence["branch_and_bound"]
    assert not attempt["ok"] and "Vdot >= 0" in attempt["reason"]
    y = np.array(attempt["counterexample_y"])
    P = np.array(res.evidence["P"])
    f = np.array([-y[1], y[0] + (y[0] ** 2 - 1) * y[1]])
    assert y @ P @ y <= 2.6 and 2 * y @ P @ f >= 0
    ok = lyapunov.verifier.estimate(vdp, {"require_certified": True, "polynomial": False})
    assert ok.level == "certified" and 2.0 < ok.evidence["rho"] < 2.32


def test_ball_checks_are_sound():
    assert bnb.certainly_pd([[arb(2), arb(1)], [arb(1), arb(2)]])
    assert not bnb.certainly_pd([[arb(1), arb(1)], [arb(1), arb(1)]])  # singular
    assert not bnb.certainly_pd([[arb(1), arb(0)], [arb(0), arb(0, 1e-12)]])  # may be singular
    P, W = np.array([[2.0, 0.3], [0.3, 0.5]]), np.diag([1.0, 4.0])
    r = bnb.inscribed_radius(P, 1.0, W)
    assert 0 < r <= 1.0
    th = np.linspace(0, 2 * np.pi, 2000)
    Y = r * np.c_[np.cos(th), np.sin(th) / 2]  # the W-sphere of radius r
    assert np.einsum("ij,jk,ik->i", Y, P, Y).max() <= 1.0
    assert (bnb.cover(P, 1.0) ** 2 >= np.diag(np.linalg.inv(P))).all()


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    """The pendulum project with Balance's `require: certified`, loaded and compiled."""
    d = tmp_path_factory.mktemp("pend") / "pendulum"
    shutil.copytree(PENDULUM, d)
    p = d / "primitives" / "balance.yaml"
    p.write_text(re.sub(r"require: \w+", "require: certified", p.read_text()))
    spec = load_project(d / "project.yaml")
    return spec, compile_project(spec)


def test_pendulum_balance_is_certified(pendulum):
    spec, prims = pendulum
    inst = next(i for i in spec.primitives if i.name == "Balance")
    opts = _options(inst)
    assert opts == {"require_certified": True}
    level, r, msg, ev, _ = _sized(prims, ("Balance", "lyapunov", opts))
    assert level == "certified", msg
    assert r >= 0.2 and ev["rho"] >= 0.05  # E = {|x - x*| < 0.2} lies in the certified {V <= rho}
    assert all(pt["certified_by"] == "branch_and_bound" for pt in ev["parts"])
    assert ev["branch_and_bound"][-1] == {**ev["branch_and_bound"][-1], "ok": True, "parts": ["Vdot", "h"]}
    assert "branch-and-bound" in msg and "W-ball" in msg
    hang = next(i for i in spec.primitives if i.name == "Hang")
    assert _options(hang) == {}  # no requirement: the sampled route, labelled empirical
    assert lyapunov.verifier.estimate(from_primitive(prims["Hang"]), _options(hang)).level == "empirical"
