"""Safe-set windows narrower than a step: every window edge is a step boundary, so each windowed
safety function is evaluated at both ends of its window; one never evaluated is an error.

Reference: x' = -2 (x - 1) from x0 = 0 gives x(s) = 1 - e^(-2 s); E (|x - 1| < 0.1) is entered at
s = ln(10) / 2 = 1.151. A window [a, b) on the clock with h = c - x is violated iff
x(a) > c (x grows, so its least value on the window is at a... and its largest at b).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mpgspec.oracle import Reason, SafetyOracle
from mpgspec.settings import OracleSettings

from test_oracle import GOAL, one

WINDOW = (0.5012, 0.5038)  # 2.6 ms, inside one 10 ms step of the default grid


def x_exact(s: float) -> float:
    return 1 - math.exp(-2 * s)


def windowed(tmp_path, level: float, window=WINDOW):
    return one(tmp_path, GOAL + f'  safe_set:\n    - {{name: brief, h: "{level} - x", when: [{window[0]}, {window[1]}]}}\n')


@pytest.mark.parametrize("method", ["rk4", "scipy"])
@pytest.mark.parametrize("accuracy", ["low", "medium", "high", "very_high"])
def test_a_window_narrower_than_a_step_is_judged_correctly(tmp_path, method, accuracy):
    settings = OracleSettings.with_accuracy(accuracy, horizon=3.0, dt=0.01, method=method, jit=False)
    violated = windowed(tmp_path, 0.6)  # x(0.5012) = 0.633 > 0.6: unsafe inside the window
    e = SafetyOracle(violated, settings)(np.array([0.0]), 0.0)
    assert (e.status, e.reason, e.violated) == ("unsafe", Reason.LEFT_C, "brief")
    assert e.t_stop == pytest.approx(WINDOW[0], abs=1e-9)  # at the window's first instant
    assert x_exact(WINDOW[1]) < 0.64
    held = windowed(tmp_path, 0.64)  # x <= 0.6354 on the window: safe, and E is reached later
    e = SafetyOracle(held, settings)(np.array([0.0]), 0.0)
    assert (e.status, e.verdict) == ("safe", 1) and e.checked
    end = 0.64 - x_exact(WINDOW[1])  # sampled from its start on, bounded over the window down to its end
    assert end < e.min_margins["brief"] <= 0.64 - x_exact(WINDOW[0]) + 1e-9
    assert end - 1e-5 < e.lower_bounds["brief"] <= end + 1e-9


def test_windows_at_random_offsets_on_a_periodic_clock(tmp_path):
    """The same window met at every offset within a step, on a clock that wraps every 0.7 s."""
    prim = one(tmp_path, GOAL.replace("class: fixed", "class: periodic\n  period: 0.7")
               + '  safe_set:\n    - {name: brief, h: "0.3 - x", when: [0.4012, 0.4031]}\n')
    rng = np.random.default_rng(3)
    t0 = rng.uniform(0, 0.7, 200)
    ev = SafetyOracle(prim, OracleSettings(horizon=3.0, dt=0.01, jit=False)).evaluate(np.zeros((200, 1)), t0)
    for t, e in zip(t0, ev):
        a = (0.4012 - t) % 0.7  # first time since switch-in at which the window opens
        truth_unsafe = a < math.log(10) / 2 and x_exact(a + 0.0019) > 0.3  # x is largest at the window's end
        assert not (truth_unsafe and e.status == "safe"), (t, e)
        if x_exact(a) > 0.3 + 1e-6 and a < math.log(10) / 2:
            assert e.status == "unsafe" and e.violated == "brief"


def test_a_function_never_evaluated_in_its_window_is_an_error(tmp_path):
    """Without step boundaries the 10 ms steps skip the window: that must not pass as safe."""
    prim = windowed(tmp_path, 0.6)
    blind = dataclasses.replace(prim, boundaries=(), cache={})
    e = SafetyOracle(blind, OracleSettings(horizon=3.0, dt=0.01, refinements=0, jit=False))(np.array([0.0]), 0.0)
    assert (e.status, e.reason, e.verdict) == ("inconclusive", Reason.ERROR, 0)
    assert e.violated == "brief" and "never evaluated" in e.message and not e.checked



def _switching(tmp_path, T: float, safe_set: str):
    law = f"if_else(t < {T}, -1, -2*(x - 1))"
    return one(tmp_path, GOAL.replace("-2*(x - 1)", law) + "  safe_set:\n" + safe_set)


@pytest.mark.parametrize("T", [0.5, 0.5037])  # a whole number of steps, and inside a step
@pytest.mark.parametrize("error", ["local", "doubling"])
@pytest.mark.parametrize("accuracy", ["low", "medium", "high", "very_high"])
def test_a_law_switching_where_a_window_ends_is_judged_on_its_own_side(tmp_path, T, error, accuracy):
    """u = -1 until the clock reaches T, then -2 (x - 1), and a window of C ends at T, so a step ends
    there. From x0 = 0.8, x is least at T: x(T) = 0.8 - T exactly (RK4 is exact on a constant rate),
    and h = x - c with c = x(T) + 3e-5 is violated there by 3e-5. A step that takes its last stage
    with the law of after T overshoots x(T) by about 0.4 h and misses it; taken inside the step, the
    answer is the exact one: unsafe, margin -3e-5 (3e-5 to spare: safe once refined). With h itself required only
    until T (its window [0, T)), h(T-) = -3e-5 shows as the bound over the window's last step."""
    settings = OracleSettings.with_accuracy(accuracy, horizon=3.0, dt=0.01, error=error, jit=False)
    c = 0.8 - T + 3e-5
    edge = f'    - {{name: until_T, h: "1", when: [0, {T}]}}\n'
    e = SafetyOracle(_switching(tmp_path, T, f'    - {{name: low, h: "x - {c!r}"}}\n' + edge), settings)(
        np.array([0.8]), 0.0)
    assert (e.status, e.violated) == ("unsafe", "low"), e
    assert e.margin == pytest.approx(-3e-5, abs=1e-9) and e.t_stop == pytest.approx(T, abs=1e-9)
    spare = _switching(tmp_path, T, f'    - {{name: low, h: "x - {c - 6e-5!r}"}}\n' + edge)
    held = SafetyOracle(spare, settings)(np.array([0.8]), 0.0)
    # low refines nothing: the bound over the step after T (h rising at 1.4 from 3e-5) dips below 0
    assert held.status == ("inconclusive" if accuracy == "low" else "safe"), held
    e = SafetyOracle(_switching(tmp_path, T, f'    - {{name: low, h: "x - {c!r}", when: [0, {T}]}}\n'), settings)(
        np.array([0.8]), 0.0)
    assert e.status != "safe" and e.violated == "low", e
    assert e.lower_bounds["low"] == pytest.approx(-3e-5, abs=1e-9)
