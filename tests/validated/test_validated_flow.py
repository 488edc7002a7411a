"""The validated flow (mpgspec.validated) against exact answers.

Linear loops have their exact flow in closed form (the matrix exponential): it must lie inside
every enclosure, which must not grow by more than a stated factor over 10 s (no wrapping effect).
The tape's ball rules must enclose the CasADi Function's own values; a non-smooth law's switch
must be replayed along the branch decided over the step, and a step over an undecided switch
must still enclose the exact flow (first-order hull and Clarke steps).
"""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from flint import arb
from scipy.linalg import expm

from mpgspec.validated.flow import Loop, Options, run
from mpgspec.validated.lohner import LohnerSet
from mpgspec.validated.tape import Tape, TapeError

NEVER = -1.0  # E's margin of a run that must reach the horizon


def _loop(xdot, h=None, roa=None, x=None, boundaries=(), period=None) -> Loop:
    """A Loop of SX expressions in x (and t)."""
    t, s = ca.SX.sym("t"), ca.SX.sym("s")
    sw = ca.SX.sym("x_sw", x.shape[0])
    h = ca.vertcat(*(h if h is not None else [ca.SX(1.0)]))
    roa = roa if roa is not None else ca.SX(NEVER)
    f = Tape.of(ca.Function("f", [x, t, s, sw], [ca.vertcat(*xdot)]))
    H = Tape.of(ca.Function("h", [x, t, s, sw], [h]))
    R = Tape.of(ca.Function("roa", [x, t], [roa])).of_psd()
    names = [f"h{i}" for i in range(h.shape[0])]
    return Loop(f, H, R, names, [None] * len(names), tuple(boundaries), period)


def _inside(end: LohnerSet, exact: np.ndarray) -> bool:
    return all(v.contains(arb(float(e))) for v, e in zip(end.hull(), exact))


@pytest.mark.parametrize("T", [1.0, 3.7, 10.0])
def test_oscillator_exact_flow_inside_the_enclosure(T):
    x = ca.SX.sym("x", 2)
    loop = _loop([x[1], -x[0]], x=x)
    x0 = np.array([1.0, 0.25])
    enc = run(loop, LohnerSet.box(x0, 0.0), 0.0, T, [arb(v) for v in x0])
    assert enc.status == "unsafe" and enc.reason == "horizon_reached"  # E is empty: never entered
    c, s = arb(T).cos(), arb(T).sin()
    exact = [x0[0] * c + x0[1] * s, -x0[0] * s + x0[1] * c]  # in ball arithmetic: exact to 1e-16
    assert all(v.overlaps(e) for v, e in zip(enc.end.hull(), exact))
    assert enc.width < 1e-10


def test_a_box_keeps_its_size_under_a_rotation():
    """A 1e-3 box rotated for 10 s: its hull is the rotated box's hull (at most sqrt(2) wider),
    not the box around a box around a box (the wrapping effect)."""
    x = ca.SX.sym("x", 2)
    loop = _loop([x[1], -x[0]], x=x)
    enc = run(loop, LohnerSet.box([1.0, 0.0], 5e-4), 0.0, 10.0, [arb(1.0, 5e-4), arb(0.0, 5e-4)])
    assert enc.width < 1e-3 * math.sqrt(2) * 1.001
    for corner in ([1.0005, 5e-4], [0.9995, -5e-4], [1.0005, -5e-4]):
        assert _inside(enc.end, expm(np.array([[0, 1], [-1, 0]]) * 10.0) @ np.array(corner))


def test_damped_linear_loop_contracts_and_enters_E():
    """A stable PD loop: the enclosure shrinks with the flow, E = {|x| < 0.1} is certainly entered,
    no later than the exact entry plus one step, and the speed bound is a certified lower bound."""
    x = ca.SX.sym("x", 2)
    A = np.array([[0.0, 1.0], [-4.0, -4.0]])
    loop = _loop([x[1], -4 * x[0] - 4 * x[1]], h=[1 - x[1] ** 2], roa=0.1 - ca.sqrt(x[0] ** 2 + x[1] ** 2), x=x)
    x0 = np.array([1.0, 0.0])
    enc = run(loop, LohnerSet.box(x0, 1e-3), 0.0, 6.0, [arb(1.0, 1e-3), arb(0.0, 1e-3)])
    assert enc.status == "safe"
    ts = np.linspace(0, 6, 60001)
    norms = [np.linalg.norm(expm(A * t) @ x0) for t in ts]
    exact_entry = ts[np.argmax(np.array(norms) < 0.1)]
    assert exact_entry - 1e-9 <= enc.s_enter <= exact_entry + 0.15  # a step (0.1) and the box's own spread
    v_peak = max(abs((expm(A * t) @ x0)[1]) for t in ts[ts <= enc.s_enter])
    assert enc.lower["h0"] <= 1 - v_peak ** 2 + 1e-9


@pytest.mark.parametrize("half", [1e-6, 1e-3])
def test_keep_out_band_narrower_than_any_step_is_seen(half):
    """x' = 1 through a band h = |x - 0.5| - half (2 microseconds or 2 ms wide), the rest of the way
    to E safe: never safe; proved unsafe where a bisected piece of the step fits in the band."""
    x = ca.SX.sym("x", 1)
    loop = _loop([ca.SX(1.0)], h=[ca.fabs(x[0] - 0.5) - half], roa=0.01 - ca.fabs(x[0] - 2.0), x=x)
    enc = run(loop, LohnerSet.box([0.0], 0.0), 0.0, 5.0, [arb(0.0)])
    assert enc.status != "safe" and enc.violated == "h0"
    assert enc.lower["h0"] < 0
    if half > Options().max_step / 2 ** Options().depth:
        assert enc.status == "unsafe" and 0.5 - half <= enc.s_stop <= 0.5 + half


@pytest.mark.parametrize("bound", [0.5, 0.9])
def test_saturated_law_encloses_the_exact_flow(bound):
    """x' = -sat(x) from x0 = 2: x(t) = 2 - b t until |x| = b, then b e^{-(t - t1)}; the switch of
    the saturation falls inside a step."""
    x = ca.SX.sym("x", 1)
    loop = _loop([-ca.fmin(ca.fmax(x[0], -bound), bound)], x=x)
    t1 = (2 - bound) / bound
    for T in (t1 - 0.3, t1 + 0.05, t1 + 2.0):
        enc = run(loop, LohnerSet.box([2.0], 1e-9), 0.0, T, [arb(2.0, 1e-9)])
        exact = 2 - bound * T if T <= t1 else bound * math.exp(-(T - t1))
        assert _inside(enc.end, [exact]), (T, enc.end.hull(), exact)
        assert enc.width < 1e-5


def test_tape_balls_enclose_the_function_values():
    x, t = ca.SX.sym("x", 2), ca.SX.sym("t")
    e = ca.vertcat(ca.sin(x[0]) * ca.exp(-x[1]) / (2 + ca.cos(t)), ca.fmin(x[0] ** 3, ca.fabs(x[1]) - 1),
                   ca.if_else(t < 1, ca.sqrt(1 + x[0] ** 2), ca.floor(t) * x[1]), ca.atan(x[0] * x[1]))
    fn = ca.Function("e", [x, t], [e])
    tape = Tape.of(fn)
    rng = np.random.default_rng(3)
    for _ in range(200):
        c, r = rng.normal(size=2), 10 ** rng.uniform(-8, -1)
        tc = rng.uniform(0, 3)
        (out, *_), _ = tape([[arb(c[0], r), arb(c[1], r)], [arb(tc, r)]])
        for _ in range(5):
            p = c + rng.uniform(-r, r, size=2)
            tp = tc + rng.uniform(-r, r)
            exact = np.array(fn(p, tp)).ravel()
            assert all(o.contains(arb(float(v))) for o, v in zip(out, exact))


def test_tape_refuses_what_is_no_expression_graph():
    x = ca.MX.sym("x", 2)
    with pytest.raises(TapeError, match="not an expression graph"):
        Tape.of(ca.Function("f", [x], [ca.sin(x)]))


def test_options_are_the_documented_defaults():
    o = Options()
    assert (o.order, o.max_step, o.min_step) == (10, 0.1, 1e-4)
