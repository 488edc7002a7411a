"""The graph executor on a simulator's state (execute/crosscheck/executor.py): it switches only once
the state is in E of the active primitive, at a verified t_A (within half a control period), to the
verified t_B; a transient hands over at the end of its domain; goals count when reached in time."""
from types import SimpleNamespace

import numpy as np

from mpgspec.execute.crosscheck.executor import ExecutorPlan, StateExecutor
from mpgspec.spec.models import PrimitiveClass


def _prim(cls, margin, period=None, domain=None, nxt=None):
    return SimpleNamespace(cls=cls, period=period, domain=domain, next=nxt, radius=1.0, radius_at=lambda t: 1.0,
                           roa_margin=lambda x, t: np.array([[margin(x, t)]]))


def _setup():
    prims = {"Stand": _prim(PrimitiveClass.FIXED, lambda x, t: x[0]),
             "Walk": _prim(PrimitiveClass.PERIODIC, lambda x, t: x[0], period=0.4),
             "Jump": _prim(PrimitiveClass.TRANSIENT, lambda x, t: 1.0, domain=(0.0, 0.25), nxt="Stand")}
    table = {"Stand": {"Walk": "Walk", "Jump": "Jump", "Stand": None},
             "Walk": {"Stand": "Stand", "Jump": "Stand", "Walk": None},
             "Jump": {"Stand": "Stand", "Walk": "Stand", "Jump": None}}
    edges = {("Stand", "Walk"): ([0.0], [0.1], [1.0]),
             ("Walk", "Stand"): ([0.0, 0.1, 0.2, 0.3], [0.0, None, 0.0, None], [1.0] * 4),
             ("Stand", "Jump"): ([0.0], [0.0], [1.0]), ("Jump", "Stand"): ([0.25], [0.0], [1.0])}
    plan = ExecutorPlan("Stand", ((0.0, "Stand"), (1.0, "Walk"), (3.0, "Jump")), table, edges)
    return plan, prims


def test_it_waits_for_e_then_switches_at_a_verified_clock():
    plan, prims = _setup()
    ex = StateExecutor(plan, prims, 1000.0)
    assert ex.decide(0.5, np.array([1.0]), 0.5) is None  # the goal is Stand itself
    assert ex.decide(1.0, np.array([-0.01]), 1.0) is None  # Walk commanded, but the state is outside E
    assert ex.best["Stand"] == -0.01
    s = ex.decide(1.001, np.array([0.02]), 1.001)  # in E: a fixed primitive switches at once, to t_B = 0.1
    assert s == {"t": 1.001, "to": "Walk", "clock": 0.1}
    assert ex.cur == "Walk" and not ex.converged


def test_a_periodic_primitive_is_left_only_at_a_verified_t_a():
    plan, prims = _setup()
    ex = StateExecutor(plan, prims, 1000.0)
    ex.decide(1.0, np.array([1.0]), 1.0)
    ex.decide(3.0, np.array([1.0]), 0.15)  # Jump commanded: via Stand; Walk's clock 0.15 is no grid time
    assert ex.cur == "Walk"
    assert ex.decide(3.01, np.array([1.0]), 0.1) is None  # t_A = 0.1 has no verified t_B
    assert ex.decide(3.05, np.array([1.0]), 0.2006) is None  # 0.6 ms off 0.2: more than half a period
    s = ex.decide(3.1, np.array([1.0]), 0.4 + 0.2 + 0.0004)  # next period, within 0.5 ms of t_A = 0.2
    assert s["to"] == "Stand" and s["clock"] == 0.0


def test_a_transient_hands_over_at_the_end_of_its_domain_and_goals_are_timed():
    plan, prims = _setup()
    ex = StateExecutor(plan, prims, 1000.0)
    ex.decide(3.0, np.array([1.0]), 3.0)  # from Stand straight to Jump
    assert ex.cur == "Jump"
    assert ex.decide(3.2, np.array([1.0]), 0.2) is None
    s = ex.decide(3.25, np.array([1.0]), 0.25)
    assert s["to"] == "Stand" and s["clock"] == 0.0 and not ex.unverified
    goals = ex.goals([{"t": 0.0, "to": "Stand"}, {"t": 1.2, "to": "Walk"}])
    assert [g["goal"] for g in goals] == ["Stand", "Walk", "Jump"]
    assert goals[0]["arrived"] == 0.0 and goals[1]["arrived"] is None and goals[2]["arrived"] == 3.0
    assert goals[1]["arrived_mpgspec"] == 1.2 and goals[2]["arrived_mpgspec"] is None


def test_it_switches_only_within_the_share_of_e_the_switch_was_checked_from():
    """Stand -> Walk checked from half of E_Stand only (radius 1: margin >= 0.5); a state that entered E
    and left it again does not switch either (share 1 needs the state in E at the switch)."""
    plan, prims = _setup()
    plan.edges[("Stand", "Walk")] = ([0.0], [0.1], [0.5])
    ex = StateExecutor(plan, prims, 1000.0)
    assert ex.decide(1.0, np.array([0.3]), 1.0) is None and ex.converged  # in E, but 0.7 from x*
    assert ex.decide(1.001, np.array([0.49]), 1.001) is None
    assert ex.decide(1.002, np.array([0.5]), 1.002)["to"] == "Walk"  # within half of r
    plan.edges[("Walk", "Stand")] = ([0.0, 0.1, 0.2, 0.3], [0.0, None, 0.0, None], [1.0] * 4)
    ex.decide(3.0, np.array([0.2]), 0.4)  # Jump commanded: via Stand, from Walk's t_A = 0 (0.4 wraps to 0)
    assert ex.cur == "Stand"
    ex2 = StateExecutor(plan, prims, 1000.0)
    ex2.cur, ex2.goal, ex2.converged, ex2.cmd_i = "Walk", "Stand", True, 2  # entered E_Walk before
    assert ex2.decide(1.5, np.array([-0.01]), 0.2) is None  # outside E now: no switch
    assert ex2.decide(1.6, np.array([0.01]), 0.2)["to"] == "Stand"
