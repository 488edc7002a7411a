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
