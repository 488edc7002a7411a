"""roa_invariant: flows from E's boundary must stay in C (fail) and end inside E (warn), checked
against a loop whose safe region of attraction is known in closed form.

x' = x + u with u = -2x clipped to [-1, 1]: for |x| < 1 the loop is x' = -x or x' = x - sign(x)
with |x| shrinking, so every |x| < 1 converges to 0; from |x| > 1, |x| - 1 grows as e^t. From
|x| = r < 1 the flow is at 1 - (1 - r) e^t until |x| = 0.5 (t1 = ln(0.5 / (1 - r))), then at
0.5 e^-(t - t1); from |x| = 1.5 it reaches |x| = 4 (h = 16 - x^2 = 0) at t = ln 6 = 1.79 s, inside
the check's 2.5 s; from |x| = 1.2 it is at 1 + 0.2 e^2.5 = 3.44 after 2.5 s (safe, outside E).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpgspec import api
from mpgspec.check.roa_flows import roa_invariant
from mpgspec.spec.loader import load_project
from mpgspec.pipeline.stages import compile_project

ORACLE = "oracle: {horizon: 3, dt: 0.01, accuracy: low, grid: {t_A: 2, t_B: 2}}\n"


def _spec(line_spec, r: float, h: str = "16 - x^2", extra: str = "") -> str:
    """Hold (u = -2x, E of radius r, C = {h >= 0}) and Other (E of radius 0.5) on x' = x + u, |u| <= 1."""
    return line_spec("unstable", 1, [("Hold", "-2*x", h, r), ("Other", "-2*x", "16 - x^2", 0.5)], ORACLE + extra)


def _hold(tmp_path: Path, line_spec, r: float, h: str = "16 - x^2"):
    path = tmp_path / "project.yaml"
    path.write_text(_spec(line_spec, r, h))
    return compile_project(load_project(path))["Hold"]


def _at_horizon(r: float, T: float = 2.5) -> float:
    t1 = np.log(0.5 / (1 - r))
    return 1 - (1 - r) * np.exp(T) if T <= t1 else 0.5 * np.exp(-(T - t1))


@pytest.mark.parametrize("r, status", [(0.5, "pass"), (0.9, "pass"), (0.99, "pass"), (1.5, "fail")])
def test_flows_from_the_boundary_of_e_are_judged_by_the_true_safe_region(tmp_path, r, status, line_spec):
    chk = roa_invariant(_hold(tmp_path, line_spec, r))
    assert chk.status == status and chk.level == "empirical", chk.message
    assert chk.numbers["samples"] == 16 and chk.numbers["start_radius_min"] == pytest.approx(1.0, abs=1e-6)
    if status == "fail":
        assert chk.numbers["unsafe"] == 16 and chk.numbers["least_h"] < 0
        assert chk.numbers["ran_s"] == pytest.approx(1.8)  # stopped at the chunk where the flows left C (t = ln 6)
    elif r == 0.5:  # x' = -x: within 0.05 r at t = ln 20 = 3.0 s, after the horizon
        assert chk.numbers["stopped"] == "horizon" and chk.numbers["ran_s"] == pytest.approx(2.5)
        assert chk.numbers["final_distance_max"] == pytest.approx(np.exp(-2.5), rel=1e-3)
    else:  # a slow flow near the edge of the true region is run to the horizon, not taken as settled
        assert chk.numbers["unsafe"] == 0 and chk.numbers["outside_at_end"] == 0
        assert chk.numbers["ran_s"] == pytest.approx(2.5) and "not converged" in chk.message
        assert chk.numbers["final_distance_max"] == pytest.approx(_at_horizon(r) / r, rel=1e-3)


def test_a_safe_flow_that_leaves_e_is_a_warning(tmp_path, line_spec):
    chk = roa_invariant(_hold(tmp_path, line_spec, 1.2, h="100 - x^2"))
    assert chk.status == "warn", chk.message
    assert chk.numbers["unsafe"] == 0 and chk.numbers["outside_at_end"] == 16
    assert chk.numbers["final_distance_max"] == pytest.approx((1 + 0.2 * np.exp(2.5)) / 1.2, rel=0.02)


def test_a_flow_whose_law_finds_no_input_fails_the_check_alone(tmp_path, line_spec, monkeypatch):
    """A compiled step that fails (a law that finds no input, say) from one start is that flow's evidence: the
    check fails with it counted, the other flows run on, and no error ends the check."""
    from mpgspec.certify.hybrid_orbit import HybridFlow

    run = HybridFlow.run

    def failing(self, X0, t0, periods=1):
        if (X0[0] > 0.45).any():  # the starts at +r (a 1-D E's boundary is +-r), until they have moved
            raise RuntimeError("Error in Function::call for 'hybrid_period_end': Evaluation failed")
        return run(self, X0, t0, periods)

    monkeypatch.setattr(HybridFlow, "run", failing)
    from mpgspec.check.roa_flows import boundary_starts

    p = _hold(tmp_path, line_spec, 0.5)
    plus = int((boundary_starts(p, 16, 0)[0] > 0).sum())
    assert 0 < plus < 16
    chk = roa_invariant(p)
    assert chk.status == "fail" and "found no input" in chk.message, chk.message
    assert chk.numbers["unsafe"] == plus and chk.numbers["ran_s"] == pytest.approx(0.1)


def _verify(tmp_path: Path, line_spec, extra: str = ""):
    """(exit code, report, Hold's roa_invariant) of a run with E = 1.5."""
    path = tmp_path / "project.yaml"
    path.write_text(_spec(line_spec, 1.5, extra=extra))
    res = api.verify([path], out_dir=None, overrides={"jit": False})
    (p,) = res.projects
    (chk,) = [a for a in p.report["assumptions"] if a["primitive"] == "Hold" and a["name"] == "roa_invariant"]
    return res.exit_code, p, chk


def test_the_check_is_in_the_report_and_a_failure_fails_the_run(tmp_path, line_spec):
    rc, p, chk = _verify(tmp_path, line_spec)
    assert rc == 1 and chk["status"] == "fail" and chk["level"] == "empirical"
    assert chk["location"]["line"] == 15  # the primitive's roa key
    (other,) = [a for a in p.report["assumptions"] if a["primitive"] == "Other" and a["name"] == "roa_invariant"]
    assert other["status"] == "pass"
    names = [a["name"] for a in p.report["assumptions"] if a["primitive"] == "Hold"]
    assert names.index("roa_invariant") == names.index("roa_in_safe_set") + 1


def test_the_project_may_report_it_as_a_warning(tmp_path, line_spec):
    rc, _, chk = _verify(tmp_path, line_spec, "assumptions: {roa_invariant: warn}\n")
    assert chk["status"] == "warn" and "reported as a warning" in chk["message"]
    assert rc == 0



def test_a_run_ends_once_every_flow_is_near_x_star(tmp_path, line_spec):
    """x' = -x from |x| = 0.5: within 0.05 r once e^-t <= 0.05, t = ln 20 = 3.0 s (the chunk ending at 3.0 s)."""
    chk = roa_invariant(_hold(tmp_path, line_spec, 0.5), horizon=4.0)
    assert chk.status == "pass" and chk.numbers["stopped"] == "converged", chk.message
    assert chk.numbers["ran_s"] == pytest.approx(3.0) and chk.numbers["horizon_s"] == 4.0
    assert "converging to x*" in chk.message
