"""Safety oracle (Definition 4) on a scalar integrator xdot = u, where every verdict is known by hand.

With u = -k (x - x*) the error decays as |x0 - x*| e^(-k s), so the flow enters the ball E of
radius r at s* = ln(|x0 - x*| / r) / k and crosses a level c between x0 and x* at
s = ln(|x0 - x*| / |c - x*|) / k. The fixed-step oracle decides at the samples s = k dt, so its
t_enter / t_stop is the first sample at or after the exact time: in [s*, s* + dt].
"""
from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.compile.primitive import CompiledPrimitive
from mpgspec.errors import UsageError
from mpgspec.oracle import OracleEvidence, Reason, SafetyOracle
from mpgspec.oracle.flow import RAMP_STEPS
from mpgspec.settings import OracleSettings
from mpgspec.spec.loader import load_project

DT = 0.01
FAST = OracleSettings(horizon=5.0, dt=DT, refinements=0, jit=False)

HEADER = """\
project: unit
system:
  name: line
  kind: analytic
  states: [x]
  inputs: [u]
  dynamics: {f: ["%(f)s"], g: [[1]]}
  input_bounds: {u: [%(lo)s, %(hi)s]}
primitives:
"""


def compile_prims(tmp_path: Path, primitives: str, bounds=(-10, 10), f: str = "0") -> dict[str, CompiledPrimitive]:
    text = HEADER % {"lo": bounds[0], "hi": bounds[1], "f": f} + textwrap.indent(textwrap.dedent(primitives), "  ")
    path = tmp_path / "project.yaml"
    path.write_text(text)
    return compile_project(load_project(path))


def one(tmp_path: Path, primitive: str, bounds=(-10, 10), f: str = "0") -> CompiledPrimitive:
    (p,) = compile_prims(tmp_path, primitive, bounds, f).values()
    return p


def in_step_after(value: float, exact: float, dt: float = DT) -> bool:
    """value is the first sample at or after the exact time (float slack of 1e-9)."""
    return exact - 1e-9 <= value <= exact + dt + 1e-9


GOAL = """\
- name: Goal
  class: fixed
  setpoint: {expr: [1]}
  controller: {type: expression, u: ["-2*(x - 1)"]}
  roa: {radius: 0.1}
"""


# ----------------------------------------------------------------------------- entered_E
def test_entered_E_with_the_right_time(tmp_path):
    oracle = SafetyOracle(one(tmp_path, GOAL), FAST)
    e = oracle(np.array([0.0]), 0.0)
    exact = math.log(1 / 0.1) / 2
    assert (e.verdict, e.reason) == (1, Reason.ENTERED_E)
    assert in_step_after(e.t_enter, exact)
    assert e.t_stop == e.t_enter
    assert e.steps == round(e.t_enter / DT) + RAMP_STEPS  # the first dt after switch-in in 1 + RAMP_STEPS steps
    assert e.violated is None and e.min_margins == {}
    assert 0 < e.best_roa_margin < 0.1
    assert e.peak_input == [pytest.approx(2.0)]  # |u| is largest at the start: 2 |0 - 1|
    assert not e.saturated


def test_start_inside_E_enters_at_once(tmp_path):
    e = SafetyOracle(one(tmp_path, GOAL), FAST)(np.array([1.05]), 0.0)
    assert (e.verdict, e.reason, e.t_enter, e.steps) == (1, Reason.ENTERED_E, 0.0, 0)


def test_many_start_points_keep_their_order_and_times(tmp_path):
    """More start points than one batch holds: slots are refilled and results stay in input order."""
    x0 = np.linspace(-3.0, 5.0, 301)  # |x0 - 1| <= 4, so |u| <= 8 stays inside the bounds
    ev = SafetyOracle(one(tmp_path, GOAL), FAST).evaluate(x0[:, None], np.zeros_like(x0))
    assert len(ev) == len(x0)
    for x, e in zip(x0, ev):
        d = abs(x - 1)
        exact = math.log(d / 0.1) / 2 if d >= 0.1 else 0.0
        assert e.verdict == 1 and in_step_after(e.t_enter, exact), (x, e)


def test_saturated_approach(tmp_path):
    """|u| <= 1 with u = -5 (x - 1) from x0 = -1: full input until x = 0.8 (s = 1.8), then e^(-5 s)."""
    prim = one(tmp_path, GOAL.replace("-2*(x - 1)", "-5*(x - 1)"), bounds=(-1, 1))
    e = SafetyOracle(prim, FAST)(np.array([-1.0]), 0.0)
    exact = 1.8 + math.log(0.2 / 0.1) / 5
    assert e.verdict == 1 and in_step_after(e.t_enter, exact)
    assert e.saturated
    assert e.peak_input == [pytest.approx(1.0)]  # the input applied, after saturation
    assert e.peak_demand == [pytest.approx(10.0)]  # what the law asked for at the start


# ----------------------------------------------------------------------------- left_C
DOWN = """\
- name: Down
  class: fixed
  setpoint: {expr: [-1]}
  controller: {type: expression, u: ["-2*(x + 1)"]}
  safe_set:
    - {name: ceiling, h: "3 - x"}
    - {name: floor, h: "x + 0.5"}
  roa: {radius: 0.1}
"""


def test_left_C_names_the_violated_function(tmp_path):
    """From 0.5 towards -1 the flow crosses the floor x = -0.5 at ln(3)/2, before E (x < -0.9)."""
    e = SafetyOracle(one(tmp_path, DOWN), FAST)(np.array([0.5]), 0.0)
    assert (e.verdict, e.reason, e.violated) == (0, Reason.LEFT_C, "floor")
    assert in_step_after(e.t_stop, math.log(3) / 2)
    assert e.t_enter is None
    assert e.min_margins["floor"] < 0
    assert e.min_margins["ceiling"] == pytest.approx(2.5)  # 3 - x is smallest at the start
    assert e.best_roa_margin < 0


def test_start_outside_C_fails_at_once(tmp_path):
    e = SafetyOracle(one(tmp_path, DOWN), FAST)(np.array([3.5]), 0.0)
    assert (e.verdict, e.reason, e.violated, e.t_stop) == (0, Reason.LEFT_C, "ceiling", 0.0)


def test_h_tolerance_accepts_small_violations(tmp_path):
    prim = one(tmp_path, DOWN.replace('"x + 0.5"', '"x + 1.02"'))  # floor just above E's lower edge
    strict = SafetyOracle(prim, FAST)(np.array([-1.01]), 0.0)
    assert strict.verdict == 1  # starts inside E, on the safe side
    x0 = np.array([-1.03])  # inside E, but 0.01 below the floor
    assert SafetyOracle(prim, FAST)(x0, 0.0).reason is Reason.LEFT_C
    assert SafetyOracle(prim, FAST.replace(h_tolerance=0.02))(x0, 0.0).reason is Reason.ENTERED_E


def test_safety_function_only_binds_inside_its_window(tmp_path):
    """h = x - 5 is violated everywhere, but only active for clock t in [0.3, 10)."""
    prim = one(tmp_path, GOAL + "  safe_set:\n    - {name: late, h: \"x - 5\", when: [0.3, 10]}\n")
    oracle = SafetyOracle(prim, FAST)
    e = oracle(np.array([0.0]), 0.0)  # E is only reached at 1.15 s
    assert (e.reason, e.violated) == (Reason.LEFT_C, "late")
    assert in_step_after(e.t_stop, 0.3)
    quick = oracle(np.array([0.85]), 0.0)  # enters E at ln(1.5)/2 = 0.2 s, before the window opens
    assert quick.verdict == 1 and in_step_after(quick.t_enter, math.log(1.5) / 2)


# ----------------------------------------------------------------------------- horizon
SLOW = GOAL.replace("-2*(x - 1)", "-0.1*(x - 1)")


def test_horizon_reached(tmp_path):
    e = SafetyOracle(one(tmp_path, SLOW), FAST.replace(horizon=2.0))(np.array([0.0]), 0.0)
    assert (e.verdict, e.reason, e.t_enter) == (0, Reason.HORIZON, None)
    assert e.t_stop == pytest.approx(2.0)
    assert e.best_roa_margin == pytest.approx(0.1 - math.exp(-0.2), abs=1e-6)  # closest at s = T


def test_primitive_horizon_overrides_the_project_horizon(tmp_path):
    prim = one(tmp_path, SLOW + "  horizon: 30\n")
    oracle = SafetyOracle(prim, FAST.replace(horizon=2.0))
    assert oracle.horizon == 30
    e = oracle(np.array([0.0]), 0.0)
    assert e.verdict == 1 and in_step_after(e.t_enter, math.log(10) / 0.1)


RAMP = """\
- name: Ramp
  class: transient
  domain: [0, 1]
  next: Goal
  setpoint: {expr: [t]}
  controller: {type: expression, u: ["1 - 0.5*(x - t)"]}
  roa: {radius: 0.05}
"""


def test_transient_is_never_run_past_its_domain(tmp_path):
    prims = compile_prims(tmp_path, RAMP + GOAL)
    oracle = SafetyOracle(prims["Ramp"], FAST)
    np.testing.assert_allclose(oracle.horizons(np.array([0.0, 0.4, 1.0, 1.2])), [1.0, 0.6, 0.0, 0.0])
    # error 0.1 decays as e^(-s/2): E after 2 ln 2 = 1.39 s, but only 0.6 s are left
    e = oracle(np.array([0.5]), 0.4)
    assert e.reason is Reason.HORIZON and e.t_stop == pytest.approx(0.6)
    # with the error 0.06 E is reached after 2 ln(1.2) = 0.36 s
    ok = oracle(np.array([0.46]), 0.4)
    assert ok.verdict == 1 and in_step_after(ok.t_enter, 2 * math.log(0.06 / 0.05))


OSC = """\
- name: Osc
  class: periodic
  period: 2
  setpoint: {expr: ["sin(pi*t)"]}
  controller: {type: expression, u: ["x_star_dot - 5*(x - x_star)"]}
  roa: {radius: 0.1}
"""


def test_periodic_clock_wraps(tmp_path):
    oracle = SafetyOracle(one(tmp_path, OSC), FAST)
    ev = oracle.evaluate(np.array([[0.5], [0.5], [0.5]]), np.array([0.0, 2.0, 4.0]))
    exact = math.log(0.5 / 0.1) / 5  # the tracking error obeys edot = -5 e
    for e in ev:
        assert e.verdict == 1 and in_step_after(e.t_enter, exact)
    assert len({e.t_enter for e in ev}) == 1


# ----------------------------------------------------------------------------- integration failures
# sqrt of a negative number is NaN: the drift is not finite for 0.4 < x < 0.5
NAN_BAND = "1e-9*sqrt((x - 0.4)*(x - 0.5))"
CROSSING = math.log(1 / 0.6)  # with u = -(x - 1) from 0, x = 1 - e^(-s) reaches 0.4
GOAL_1 = GOAL.replace("-2*(x - 1)", "-(x - 1)")


def test_nan_gives_integration_failed_and_the_batch_goes_on(tmp_path):
    oracle = SafetyOracle(one(tmp_path, GOAL_1, f=NAN_BAND), FAST)
    ev = oracle.evaluate(np.array([[0.0], [2.0], [0.45], [1.02]]), np.zeros(4))
    assert (ev[0].verdict, ev[0].reason) == (0, Reason.INTEGRATION_FAILED)
    assert CROSSING - DT <= ev[0].t_stop <= CROSSING + DT  # dated at the step where it happened
    assert "non-finite" in ev[0].message
    assert ev[1].verdict == 1 and in_step_after(ev[1].t_enter, math.log(10))  # from above: never in the band
    assert ev[2].reason is Reason.INTEGRATION_FAILED and ev[2].t_stop <= DT  # the first step is NaN
    assert ev[3].verdict == 1 and ev[3].t_enter == 0.0


def test_nan_in_the_control_law_gives_integration_failed(tmp_path):
    """Same band in u instead of f: the raw input is NaN for 0.4 < x < 0.5."""
    prim = one(tmp_path, GOAL.replace("-2*(x - 1)", "-(x - 1) + " + NAN_BAND), bounds=(-1e6, 1e6))
    e = SafetyOracle(prim, FAST)(np.array([0.0]), 0.0)
    assert (e.verdict, e.reason) == (0, Reason.INTEGRATION_FAILED)
    assert CROSSING - DT <= e.t_stop <= CROSSING + DT


def test_entry_before_a_later_nan_counts(tmp_path):
    """Definition 4: the flow enters E at ln(10) = 2.30 s; it reaches the NaN band x > 0.92 only at 2.53 s,
    inside the same compiled chunk of 64 steps."""
    prim = one(tmp_path, GOAL_1, f="1e-9*sqrt((x - 0.92)*(x - 0.95))")
    e = SafetyOracle(prim, FAST)(np.array([0.0]), 0.0)
    assert e.verdict == 1 and in_step_after(e.t_enter, math.log(10))


def test_scipy_backend_reports_nan_as_integration_failed(tmp_path):
    oracle = SafetyOracle(one(tmp_path, GOAL_1, f=NAN_BAND), FAST.replace(method="scipy"))
    assert oracle(np.array([0.45]), 0.0).reason is Reason.INTEGRATION_FAILED


# ----------------------------------------------------------------------------- the step-halving check
# moving right at unit speed through a thin unsafe band 0.53 < x < 0.57 towards E = (0.9, 1.1)
THIN = """\
- name: Pass
  class: fixed
  setpoint: {expr: [1]}
  controller: {type: expression, u: ["1"]}
  safe_set:
    - {name: thin_wall, h: "abs(x - 0.55) - 0.02"}
  roa: {radius: 0.1}
"""


def test_a_wall_between_samples_is_inconclusive_then_refined_to_unsafe(tmp_path):
    prim = one(tmp_path, THIN)
    coarse = OracleSettings(horizon=3.0, dt=0.1, refinements=0, jit=False)
    x0 = np.array([0.0])
    doubt = SafetyOracle(prim, coarse)(x0, 0.0)  # samples x = 0.5, 0.6: the band falls between them
    assert (doubt.status, doubt.verdict, doubt.reason) == ("inconclusive", 0, Reason.INCONCLUSIVE)
    assert doubt.violated == "thin_wall" and doubt.margin > 0 and doubt.margin - doubt.error_bound < 0
    fine = SafetyOracle(prim, coarse.replace(dt=0.01))(x0, 0.0)
    assert (fine.status, fine.violated) == ("unsafe", "thin_wall") and in_step_after(fine.t_stop, 0.53)
    refined = SafetyOracle(prim, coarse.replace(refinements=1))(x0, 0.0)  # run again at dt = 0.05
    assert (refined.status, refined.reason, refined.violated) == ("unsafe", Reason.LEFT_C, "thin_wall")
    assert refined.checked and refined.refined
    assert refined.t_stop == pytest.approx(0.55)


def test_clear_verdicts_are_not_refined(tmp_path):
    e = SafetyOracle(one(tmp_path, GOAL), FAST.replace(refinements=2))(np.array([0.0]), 0.0)
    assert e.status == "safe" and e.verdict == 1 and e.checked and not e.refined
    assert e.entry_margin > e.entry_error >= 0
    down = one(tmp_path, DOWN)
    e = SafetyOracle(down, FAST.replace(refinements=2))(np.array([0.5]), 0.0)
    assert e.status == "unsafe" and e.checked and not e.refined and e.violated == "floor"
    assert (e.steps - RAMP_STEPS) * DT == pytest.approx(e.t_stop)


# ----------------------------------------------------------------------------- backends
@pytest.mark.parametrize("case", ["enter", "left", "horizon"])
def test_scipy_backend_gives_the_exact_times(tmp_path, case):
    prim = one(tmp_path, {"enter": GOAL, "left": DOWN, "horizon": SLOW}[case])
    s = FAST.replace(method="scipy", horizon=2.0)
    x0 = np.array([0.5 if case == "left" else 0.0])
    e: OracleEvidence = SafetyOracle(prim, s)(x0, 0.0)
    r: OracleEvidence = SafetyOracle(prim, s.replace(method="rk4"))(x0, 0.0)
    assert (e.verdict, e.reason, e.violated) == (r.verdict, r.reason, r.violated)
    if case == "enter":
        assert e.t_enter == pytest.approx(math.log(10) / 2, abs=1e-6)
    elif case == "left":
        assert math.log(3) / 2 <= e.t_stop <= math.log(3) / 2 + s.dt / 4  # the first sample past the crossing
    else:
        assert e.t_stop == 2.0


def test_jit_and_virtual_machine_agree(tmp_path):
    prim = one(tmp_path, GOAL + "  safe_set:\n    - {name: cap, h: \"1.5 - x\"}\n")
    x0 = np.array([[0.0], [2.0], [1.4], [1.05]])
    a = SafetyOracle(prim, FAST).evaluate(x0, np.zeros(4))
    b = SafetyOracle(prim, FAST.replace(jit=True)).evaluate(x0, np.zeros(4))
    assert [(e.verdict, e.reason, e.t_stop, e.violated) for e in a] == \
           [(e.verdict, e.reason, e.t_stop, e.violated) for e in b]
    assert [e.reason for e in a] == [Reason.ENTERED_E, Reason.LEFT_C, Reason.ENTERED_E, Reason.ENTERED_E]
    assert in_step_after(a[2].t_enter, math.log(4) / 2)


def test_unknown_backend_is_a_usage_error(tmp_path):
    with pytest.raises(UsageError, match="unknown oracle method 'nope'"):
        SafetyOracle(one(tmp_path, GOAL), FAST.replace(method="nope"))


def test_a_numerical_blow_up_is_inconclusive_not_a_safety_violation(tmp_path):
    """p' = -1e6 p at dt 0.01 (dt / 16 at the first step after switch-in): RK4 is unstable and the state explodes; that is no evidence that the
    loop leaves C, so no `no_edge` assertion may pass on it."""
    stiff = GOAL.replace("-2*(x - 1)", "-1000000*(x - 1)") + '  safe_set:\n    - {name: band, h: "3 - abs(x)"}\n'
    e = SafetyOracle(one(tmp_path, stiff, bounds=(-1e9, 1e9)), FAST.replace(horizon=1.0))(np.array([0.0]), 0.0)
    assert (e.status, e.reason) == ("inconclusive", Reason.INCONCLUSIVE)
    assert "decrease dt" in e.message and e.error_bound > 1e3 * abs(e.margin)
