"""E(t)'s radius ratio before scheduled touchdowns: the compiled and the numpy form agree for any number of
narrowed stretches (a window that wraps past the period's start splits in two), and a schedule's touchdowns
are the phases that add a foot."""
import casadi as ca
import numpy as np

from mpgspec.compile.closed_loop import narrowing
from mpgspec.compile.contacts import Schedule


def test_compiled_and_numeric_ratios_agree_over_three_stretches():
    narrow = ((0.0, 0.01), (0.15, 0.18), (0.35, 0.36))  # a touchdown at 0.01 whose 20 ms wrap, and one at 0.18
    t = ca.SX.sym("t")
    f = ca.Function("ratio", [t], [narrowing(t, narrow, 0.25, 0.36)])
    ts = np.r_[np.linspace(-0.4, 0.8, 241), [0.0, 0.01, 0.15, 0.18, 0.35, 0.36, 0.71]]
    want = narrowing(ts, narrow, 0.25, 0.36)
    got = np.array([float(f(x)) for x in ts])
    assert np.array_equal(got, want)
    assert float(f(0.005)) == 0.25 and float(f(0.355)) == 0.25 and float(f(0.16)) == 0.25
    assert float(f(0.01)) == 1.0 and float(f(0.1)) == 1.0 and float(f(0.36 + 0.16)) == 0.25


def test_a_schedules_touchdowns_are_the_phases_that_add_a_foot():
    both, a, b = ("FL", "FR", "RL", "RR"), ("FL", "RR"), ("FR", "RL")
    trot = Schedule(((0.02, both), (0.18, a), (0.2, both), (0.36, b)), 0.36, both)
    assert trot.touchdowns == [0.0, 0.18]  # 0.36 wraps to 0
    assert Schedule(((0.1, both),), 0.2, both).touchdowns == []
    assert Schedule(((0.1, a), (0.2, both)), 0.2, both).touchdowns == [0.1]  # a -> both; both -> a lifts off
