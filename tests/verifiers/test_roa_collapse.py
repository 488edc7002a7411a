"""An empty or collapsed region of attraction never leaves the project PASS silently.

An empty E (the setpoint sits on the boundary of C, so no level set fits inside it) is a FAIL of
the `roa_size` assumption check and exit 1; an E far below the radius the spec requests is a WARN
naming the option to change. The hybrid tube sizing (verifiers/floquet_hybrid.py) doubles its
number of periods when the transient outlasts the first count; the gait of the A1 takes minutes
to compile, so a linear stand-in with the same multipliers (0.4) and a non-normal transient plays
it: over the first count (6 periods) no start has converged, so the old sizing returned r = 0.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from mpgspec.compile.closed_loop import narrowing
from mpgspec.api import verify
from mpgspec.check.region_size import COLLAPSE
from verifiers import floquet_hybrid

SYSTEM = """
project: {name}
system:
  name: integrator
  kind: analytic
  states: [x]
  inputs: [u]
  dynamics: {{f: [0], g: [[1]]}}
  input_bounds: {{u: [-5, 5]}}
primitives:
  - name: Home
    class: fixed
    setpoint: {{expr: [0]}}
    controller: {{type: expression, u: ["-2*x"]}}
    safe_set:
      - {{name: wall, h: "{wall} - x"}}
      - {{name: floor, h: "x + 1"}}
    roa: {roa}
  - name: Away
    class: fixed
    setpoint: {{expr: [0.5]}}
    controller: {{type: expression, u: ["-2*(x - 0.5)"]}}
    roa: {{radius: 0.05}}
oracle: {{horizon: 3.0, dt: 0.02, accuracy: low}}
"""


def _project(tmp_path, name: str, wall: str, roa: str):
    d = tmp_path / name
    d.mkdir()
    (d / "project.yaml").write_text(SYSTEM.format(name=name, wall=wall, roa=roa))
    return verify(d, tmp_path / "out")


def _size_check(res):
    rep = res.projects[0].report
    return [c for c in rep["assumptions"] if c["name"] == "roa_size"], rep


def test_empty_region_fails_the_project(tmp_path):
    """x* = 0 on the wall h = -x: no level set of V lies inside C, so E is empty (r = 0)."""
    res = _project(tmp_path, "empty", "0", "{method: lyapunov}")
    checks, rep = _size_check(res)
    assert [c["status"] for c in checks] == ["fail"] and checks[0]["primitive"] == "Home"
    assert "E is empty" in checks[0]["message"] and "roa.options" in checks[0]["message"]
    assert rep["status"] == "fail" and res.exit_code == 1


def test_collapsed_region_warns(tmp_path):
    """The spec requests r = 1 but the wall at 0.05 lets the verifier size r ~ 0.05 < COLLAPSE * 1."""
    res = _project(tmp_path, "collapsed", "0.05", "{method: lyapunov, radius: 1.0}")
    checks, rep = _size_check(res)
    assert [c["status"] for c in checks] == ["warn"]
    c = checks[0]
    assert c["numbers"]["radius"] < COLLAPSE * c["numbers"]["typical"] and c["numbers"]["typical"] == 1.0
    assert "roa.radius" in c["message"] and "roa.options.degree" in c["message"]
    assert rep["status"] == "pass" and res.exit_code == 0


def test_sized_region_is_silent(tmp_path):
    """A region the wall does not squeeze gives no roa_size check at all."""
    res = _project(tmp_path, "fine", "0.5", "{method: lyapunov}")
    checks, rep = _size_check(res)
    assert checks == [] and rep["status"] == "pass"


class _LinearFlow:
    """A stand-in for HybridFlow: x -> M x once per period (orbit x* = 0), unsafe where |x|_inf >= 1."""

    def __init__(self, M: np.ndarray, steps: int = 10):
        self.M, self.steps, self.dt = M, steps, 1.0 / steps
        self.prim = SimpleNamespace(system=None, contacts=None)

    def least_h(self, X, t):
        return 1 - np.abs(X).max(0)

    def first_exit(self, x0, t0):
        """Where a start leaves C within its first period: x -> M x happens at the period's end."""
        for x in (x0, self.M @ x0):
            if np.abs(x).max() >= 1:
                return {"t": t0 + self.steps * self.dt, "h": "box", "value": float(1 - np.abs(x).max())}
        return None

    def run(self, X0, t0, periods):
        return self.run_until(X0, t0, periods)[:2]

    def run_until(self, X0, t0, periods, stop=None):
        X, hmin = X0.copy(), 1 - np.abs(X0).max(0)
        for k in range(periods):
            X = self.M @ X
            hmin = np.minimum(hmin, 1 - np.abs(X).max(0))
            if stop is not None and k + 1 < periods and stop(X, hmin):
                return X, hmin, k + 1
        return X, hmin, periods


class _NoStop(_LinearFlow):
    """The same flow, every rollout run for all its periods."""

    def run_until(self, X0, t0, periods, stop=None):
        return super().run_until(X0, t0, periods)


def _size(M, o=None, flow_type=None):
    flow = (flow_type or _LinearFlow)(M)
    rho = float(np.abs(np.linalg.eigvals(M)).max())
    return floquet_hybrid._size(flow, None, np.zeros((2, flow.steps)), np.eye(2), rho, dict(o or {}))


SLOW = np.array([[0.4, 10.0], [0.0, 0.4]])  # multipliers 0.4, transient n 10 0.4^(n-1): 0.61 at n = 6


def test_slow_transient_gets_more_periods():
    r, tube = _size(SLOW)
    assert tube["periods_tried"][0] == {"periods": 6, "radius": 0.0}  # the first count: rho^n < conv/4
    assert tube["periods"] > 6 and r >= COLLAPSE * 0.05
    assert r == pytest.approx(0.1, rel=0.1)  # the transient's peak (10 r at n = 1) reaches |x| = 1


def test_stopping_a_failed_radius_early_changes_no_radius():
    """A radius whose starts already left C after some periods fails whatever follows: stopping its
    rollouts there gives the same radius and period count as running every period."""
    for M in (SLOW, np.diag([0.4, 0.3]), np.array([[0.5, 3.0], [0.0, 0.6]])):
        r, tube = _size(M)
        r_all, tube_all = _size(M, flow_type=_NoStop)
        assert r == r_all and tube["periods"] == tube_all["periods"]
    stopped = [e for e in tube["bisection"] if "stopped_after_periods" in e]
    assert stopped and all(e["unsafe"] > 0 and e["stopped_after_periods"] < tube["periods"] for e in stopped)


def test_given_periods_are_kept():
    r, tube = _size(SLOW, {"periods": 6})
    assert r == 0.0 and tube["periods"] == 6 and "periods_tried" not in tube


def test_fast_loop_keeps_the_first_count():
    r, tube = _size(np.diag([0.4, 0.3]))
    assert tube["periods"] == 6 and "periods_tried" not in tube and r > 0.5


def test_smooth_floquet_adapts_its_periods_too():
    """x' = A x, A = [[-0.92, 10], [0, -0.92]], T = 1: multipliers 0.4, but after the first count
    (7 periods at conv 0.02) the transient 70 e^-6.4 = 0.11 has not decayed: r = 0; 14 periods pass."""
    import casadi as ca

    from mpgspec.certify.problem import PeriodicProblem
    from verifiers import floquet

    x, t = ca.SX.sym("x", 2), ca.SX.sym("t")
    A = ca.DM([[-0.92, 10.0], [0.0, -0.92]])
    prob = PeriodicProblem(ca.Function("f", [x, t], [ca.mtimes(A, x)]), ca.Function("xs", [t], [ca.DM.zeros(2)]), 1.0)
    res = floquet.verifier.estimate(prob, {"samples": 16, "steps_per_period": 50, "r_max": 1.0})
    tube = res.evidence["tube"]
    assert tube["periods_tried"][0] == {"periods": 7, "radius": 0.0}
    assert res.evidence["periods"] == 14 and res.level == "empirical" and res.radius == 1.0


def test_unverified_spec_radius_warns(tmp_path):
    """The verifier fails (x* on the wall) and the spec's radius is kept: a WARN says it is unverified."""
    res = _project(tmp_path, "fallback", "0", "{method: lyapunov, radius: 0.01}")
    checks, _ = _size_check(res)
    assert [c["status"] for c in checks] == ["warn"] and "not verified" in checks[0]["message"]


def test_safe_set_scale_is_the_typical_size_without_a_spec_radius(tmp_path):
    """Without roa.radius the typical size is the W-distance from x* = 0 to the nearer wall (0.5);
    a verified r = 0.01 is below COLLAPSE of it: WARN; r = 0.2 is not."""
    from mpgspec.api import compile_project
    from mpgspec.certify.roa import RoARecord
    from mpgspec.check.region_size import region_size, safe_set_scale
    from mpgspec.spec.loader import load_project

    d = tmp_path / "scale"
    d.mkdir()
    (d / "project.yaml").write_text(SYSTEM.format(name="scale", wall="0.5", roa="{method: lyapunov}"))
    home = compile_project(load_project(d / "project.yaml"))["Home"]
    assert safe_set_scale(home) == pytest.approx(0.5)
    small = region_size(home.with_radius(0.01), RoARecord("Home", "lyapunov", "empirical", 0.01))
    assert small.status == "warn" and small.numbers["typical"] == pytest.approx(0.5) and "safe set" in small.message
    assert region_size(home.with_radius(0.2), RoARecord("Home", "lyapunov", "empirical", 0.2)) is None


class _HalfPlane(_LinearFlow):
    """The fast flow with C also bounded by x_0 >= -0.3 (h = x_0 + 0.3): the flow contracts towards 0,
    so a start inside C stays inside; every start handed to the rollouts is recorded."""

    def __init__(self, M):
        super().__init__(M)
        self.starts = []

    def least_h(self, X, t):
        return np.minimum(1 - np.abs(X).max(0), X[0] + 0.3)

    def run_until(self, X0, t0, periods, stop=None):
        self.starts.append(X0.copy())
        X, hmin = X0.copy(), self.least_h(X0, t0)
        for k in range(periods):
            X = self.M @ X
            hmin = np.minimum(hmin, self.least_h(X, t0))
            if stop is not None and k + 1 < periods and stop(X, hmin):
                return X, hmin, k + 1
        return X, hmin, periods


def test_starts_outside_c_are_left_out():
    """E is entered only where the oracle judged every h >= 0 (-tol): a tube start outside C at its radius
    is left out there, so the radius is set by the flow, not by the part of the ball that lies outside C."""
    M = np.diag([0.4, 0.3])
    flow = _HalfPlane(M)
    r, tube = floquet_hybrid._size(flow, None, np.zeros((2, flow.steps)), np.eye(2), 0.4, {})
    assert max(e["outside_c"] for e in tube["bisection"]) > 0 and "inside C" in tube["starts"]
    radius = lambda X: float(np.linalg.norm(X, axis=0).max())  # noqa: E731 (half the starts lie on the sphere)
    assert all((flow.least_h(X, None) >= 0).all() for X in flow.starts if radius(X) <= 0.9)
    assert r > 0.6  # the ball reaches x_0 = -0.3 from r = 0.3 on: drawn as they fall, starts there would fail
    # with the oracle's tolerance the starts may lie down to -tol
    tol_flow = _HalfPlane(M)
    floquet_hybrid._size(tol_flow, None, np.zeros((2, tol_flow.steps)), np.eye(2), 0.4, {"oracle_h_tolerance": 0.05})
    lows = [float(tol_flow.least_h(X, None).min()) for X in tol_flow.starts if radius(X) <= 0.9]
    assert min(lows) >= -0.05 and min(lows) < 0


class _ThinBeforeTouchdown(_LinearFlow):
    """The fast flow with a touchdown at step 50 of 100: a start in the last step before it leaves C when it
    lies more than 0.2 from the orbit (a swing foot a little low or late), anywhere else only at |x|_inf >= 1.
    The true tube radius is 0.2; starts spread over the period meet the thin phase 1 time in 100."""

    def __init__(self, M):
        super().__init__(M, steps=100)

    def _thin(self, X0, t0):
        k = np.round(np.asarray(t0) / self.dt).astype(int) % self.steps
        return (k == 49) & (np.linalg.norm(X0, axis=0) > 0.2)

    def run_stretch(self, X0, t0):
        return X0.copy(), np.where(self._thin(X0, t0), -1.0, 1 - np.abs(X0).max(0))

    def first_exit(self, x0, t0):
        if self._thin(x0[:, None], np.array([t0]))[0]:  # at the end of its step, 49 -> 50: the touchdown
            return {"t": 50 * self.dt, "h": "touchdown_gap", "value": -1.0}
        return super().first_exit(x0, t0)

    def run_until(self, X0, t0, periods, stop=None):
        X, hmin = super().run_until(X0, t0, periods, stop)[:2]
        return X, np.where(self._thin(X0, t0), -1.0, hmin), periods


def test_a_gaits_tube_finds_the_thin_phases_before_a_touchdown(monkeypatch):
    """Known answer: the tube is 0.2 wide in the step before a touchdown and 1 elsewhere. The sizing puts
    `window_samples` starts in the last `window` seconds before each touchdown and finds at most 0.2; the
    same flow sized with no starts there (window_samples 0: 48 phases over the whole period only, as the
    sizing used to draw them; none falls on the thin step with this seed) reports a radius from which starts
    before the touchdown leave C."""
    monkeypatch.setattr(floquet_hybrid, "contact_changes", lambda prim, dt, steps: np.array([50]))
    M = np.diag([0.4, 0.3])
    o = {"window": 0.05, "rtol": 0.02}
    r, tube = floquet_hybrid._size(_ThinBeforeTouchdown(M), None, np.zeros((2, 100)), np.eye(2), 0.4, o)
    assert 0.18 <= r <= 0.2 and tube["before_changes"] == 512
    assert tube["confirm"][-1]["r"] == r and tube["confirm"][-1]["failed"] == 0  # fresh starts at r pass
    assert any(e.get("failed_before_changes") for e in tube["bisection"])  # what set the radius
    # and the evidence says so: the least radius that failed, its starts leaving C at the touchdown step
    b = tube["bounded_by"]
    assert 0.2 - 1e-9 <= b["r"] <= 0.22 and b["located"] >= 1 and set(b["functions"]) == {"touchdown_gap"}
    assert all(e["from_change_s"] == 0 for e in b["exits"]) and "at a scheduled contact change" in b["text"]
    blind, _ = floquet_hybrid._size(_ThinBeforeTouchdown(M), None, np.zeros((2, 100)), np.eye(2), 0.4,
                                    {**o, "window_samples": 0})
    assert blind > 0.3  # 48 starts over the period: the thin phases missed


class _NarrowBeforeTouchdown(_ThinBeforeTouchdown):
    """The flow above whose E(t) the spec narrows to a tenth of r in the 5 steps before the touchdown
    (roa.before_touchdown: CompiledPrimitive.narrow and radius_scale)."""

    def __init__(self, M):
        super().__init__(M)
        narrow = ((0.45, 0.5),)
        self.prim = SimpleNamespace(system=None, contacts=None, narrow=narrow,
                                    radius_scale=lambda t: narrowing(t, narrow, 0.1, 1.0))


def test_a_tube_narrowed_before_its_touchdown_is_as_wide_as_the_rest_allows(monkeypatch):
    """Known answer: with E(t) a tenth as wide in the steps before the touchdown, the thin step (0.2 wide)
    bounds r at 2 (a tenth of it there is 0.2; elsewhere the contracting flow keeps every start that lies in C
    inside it), where the same flow with one radius for every phase gets at most 0.2. Starts also go just
    before the narrowed stretch, where the full radius meets it."""
    monkeypatch.setattr(floquet_hybrid, "contact_changes", lambda prim, dt, steps: np.array([50]))
    M = np.diag([0.4, 0.3])
    o = {"window": 0.05, "rtol": 0.02}
    r, tube = floquet_hybrid._size(_NarrowBeforeTouchdown(M), None, np.zeros((2, 100)), np.eye(2), 0.4, o)
    assert 1.8 <= r <= 2.0 and tube["bounded_by"]["functions"] == {"touchdown_gap": tube["bounded_by"]["located"]}
    one, _ = floquet_hybrid._size(_ThinBeforeTouchdown(M), None, np.zeros((2, 100)), np.eye(2), 0.4, o)
    assert one <= 0.2
    k = floquet_hybrid.before_changes(_NarrowBeforeTouchdown(M).prim, 0.01, 100, 2000, 0.05,
                                      np.random.default_rng(0))
    assert set(k) == set(range(40, 50))  # before the narrowed stretch (45) and before the touchdown (50)
