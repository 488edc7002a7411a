"""The rk4 safety oracle on the ladder project (specs/ladder) against its closed form (ladder_truth.py).

The closed loops are first shown to be the linear error dynamics the truth assumes, and the truth
to give the known answers of a critically damped step. Then every cell of Algorithm 1's grids that
the oracle decided must have the exact verdict; a safe cell must be entered in E within one oracle
step after the exact entry, with every error-aware lower bound below the exact least value of its
safety function; an unsafe cell must stop within one step after the exact violation of the same
function. Finally the graph's edges, classes and t_A windows are those the exact verdicts give.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

from mpgspec import api
from mpgspec.graph.transition import TransitionClass

sys.path.insert(0, str(Path(__file__).parent))
from ladder_truth import Ladder, closed_loop_matrix, expm2  # noqa: E402

SPECS = Path(__file__).parents[2] / "specs"
SLACK = 1e-9  # what an exact time (s) or least value of h may be off by
SAMPLED = 1e-3  # the least sampled value of h against its least value over the same time
EXPECTED = {  # (A, B) -> class, as the closed form gives it on the project's grids
    ("Hold(0)", "Hold(1)"): 1, ("Hold(1)", "Hold(0)"): 1, ("Hold(1)", "Hold(2)"): 1, ("Hold(2)", "Hold(1)"): 1,
    ("Hold(0)", "Hold(2)"): 0, ("Hold(2)", "Hold(0)"): 0,
    ("Hold(0)", "Sway"): 1, ("Hold(1)", "Sway"): 1, ("Hold(2)", "Sway"): 1,
    ("Sway", "Hold(0)"): 2, ("Sway", "Hold(1)"): 1, ("Sway", "Hold(2)"): 2,
}


@pytest.fixture(scope="module")
def project():
    """specs/ladder verified in this process by the rk4 backend, whatever method the spec names:
    every assertion holds but those demanding certified evidence, which a simulation cannot give."""
    p = api.verify([SPECS / "ladder"], out_dir=None, overrides={"method": "rk4"}).projects[0]
    failed = [a for a in p.report["assertions"] if a["status"] != "pass"]
    assert failed and all(a["description"].endswith("certified") and "simulated, not certified" in a["message"]
                          for a in failed), failed
    return p


@pytest.fixture(scope="module")
def truth(project):
    return Ladder(project.compiled.spec, project.compiled.prims)


@pytest.fixture(scope="module")
def cells(project, truth):
    """(A, B) -> [(i_A, i_B, the oracle's evidence, the exact answer)] over the graph's grids."""
    out = {}
    for (a, b), tr in project.mpg.transitions.items():
        out[(a, b)] = [(i, j, tr.evidence[i][j], truth.cell(a, ta, b, tb, _horizon(project, b, tb)))
                       for i, ta in enumerate(tr.t_A) for j, tb in enumerate(tr.t_B)]
    return out


def _horizon(project, b: str, t_b: float) -> float:
    """The oracle's horizon for a switch into B at t_B."""
    return float(project.compiled.prims[b].horizons(project.compiled.settings.horizon, t_b)[0])


@pytest.mark.parametrize("kp, kd", [(4, 4), (9, 6), (4, 3), (4, 5), (1e-3, 0), (0, 0)])
def test_closed_form_exponential(kp, kd):
    A = closed_loop_matrix(kp, kd)
    s = np.array([0.0, 1e-6, 0.3, 1.7, 6.0])
    got = expm2(A, s)
    for k, sk in enumerate(s):
        assert np.allclose(got[k], expm(A * sk), rtol=1e-13, atol=1e-14), (kp, kd, sk)


def test_closed_loops_are_the_linear_error_dynamics(truth):
    rng = np.random.default_rng(7)
    for name, prim in truth.prims.items():
        for _ in range(20):
            t = rng.uniform(0.0, 10.0)
            xs = prim.x_star(t)
            x = xs + rng.normal(scale=2.0, size=2)
            args = (t, 0.0, x)
            rate = np.array(prim.f_cl(x, *args)).ravel() - np.array(prim.f_cl(xs, *args)).ravel()
            assert np.allclose(rate, truth.A[name] @ (x - xs), rtol=0, atol=1e-12), name
            d = 1e-5
            assert np.allclose(np.array(prim.f_cl(xs, *args)).ravel(),
                               (prim.x_star(t + d) - prim.x_star(t - d)) / (2 * d), atol=1e-8), name


def test_known_answers_of_a_critically_damped_step(truth):
    """kp = 4, kd = 4: a step of d gives e(t) = -d (1 + 2t) e^(-2t), v(t) = 4 d t e^(-2t), whose
    speed peaks at 2 d / e when t = 1/2."""
    one = truth.cell("Hold(0)", 0.0, "Hold(1)", 0.0, 6.0)
    t_in = brentq(lambda t: math.hypot((1 + 2 * t), 4 * t) * math.exp(-2 * t) - 0.3, 1.0, 3.0, xtol=1e-14)
    assert one.verdict == 1 and abs(one.t_enter - t_in) < 1e-10
    assert abs(one.margins["speed_limit"] - (1 - 4 / math.e ** 2)) < 1e-10
    assert one.margins["low_wall"] == pytest.approx(0.5, abs=1e-12)
    two = truth.cell("Hold(0)", 0.0, "Hold(2)", 0.0, 6.0)
    t_v = brentq(lambda t: 8 * t * math.exp(-2 * t) - 1.0, 0.0, 0.5, xtol=1e-14)
    assert two.verdict == 0 and two.violated == "speed_limit" and abs(two.t_violation - t_v) < 1e-10
    assert abs(two.margins["speed_limit"] - (1 - 16 / math.e ** 2)) < 1e-10
    back = truth.cell("Sway", 0.0, "Hold(1)", 0.0, 6.0)  # from (1, 0.6): the speed only falls
    assert back.verdict == 1 and abs(back.margins["speed_limit"] - 0.64) < 1e-10


def test_rk4_decided_cells_have_the_exact_answer(project, truth, cells):
    dt = project.compiled.settings.dt
    decided = safe = 0
    for (a, b), rows in cells.items():
        names = project.compiled.prims[b].h_names
        for i, j, ev, tt in rows:
            if ev.status == "inconclusive":
                continue
            decided += 1
            where = f"{a} -> {b} cell ({i}, {j})"
            assert ev.verdict == tt.verdict, (where, ev.reason, tt)
            if tt.verdict:
                safe += 1
                assert tt.t_enter - SLACK <= ev.t_enter <= tt.t_enter + dt + SLACK, (where, ev.t_enter, tt)
                tr = project.mpg.transitions[(a, b)]
                fl = truth.flow(a, tr.t_A[i], b, tr.t_B[j], _horizon(project, b, tr.t_B[j]))
                for k, n in enumerate(names):
                    least = fl.least(k, ev.t_stop)
                    assert ev.lower_bounds[n] <= least + SLACK, (where, n, ev.lower_bounds[n], least)
                    assert abs(ev.min_margins[n] - least) < SAMPLED, (where, n, ev.min_margins[n], least)
            elif ev.reason.value == "left_C":
                assert ev.violated == tt.violated, (where, ev.violated, tt.violated)
                assert tt.t_violation - SLACK <= ev.t_stop <= tt.t_violation + dt + SLACK, (where, tt)
            else:
                assert tt.t_enter is None, (where, ev.reason, tt)
    assert decided == sum(len(r) for r in cells.values()) and 0 < safe < decided


def test_edges_are_those_of_the_closed_form(project, cells):
    for (a, b), rows in cells.items():
        tr = project.mpg.transitions[(a, b)]
        V = np.zeros((len(tr.t_A), len(tr.t_B)), bool)
        for i, j, _ev, tt in rows:
            V[i, j] = tt.verdict == 1
        avail = V.any(axis=1)
        cls = 1 if avail.all() else 2 if avail.any() else 0
        assert cls == EXPECTED[(a, b)] == int(tr.cls), (a, b, cls, tr.cls)
        assert np.array_equal(avail, tr.available), (a, b)
        assert (project.mpg.edge(a, b) is not None) == (cls != TransitionClass.NONE)
