"""Algorithm 1 (BuildMotionPrimitiveGraph) and Definitions 2-3 on hand-solvable scalar primitives.

The fixture tests/fixtures/line_graph/project.yaml describes the primitives; all expected classes,
windows, switch-in clocks and durations below follow from x(s) = x* + (x0 - x*) e^(-k s).
"""
from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.graph import MotionPrimitiveGraph, Transition, TransitionClass, build_graph
from mpgspec.oracle import OracleEvidence, Reason
from mpgspec.spec.loader import load_project

FIXTURE = Path(__file__).parents[1] / "fixtures" / "line_graph" / "project.yaml"
DT = 0.01


@pytest.fixture(scope="module")
def built():
    spec = load_project(FIXTURE)
    prims = compile_project(spec)
    settings = settings_for(spec).replace(jit=False)
    assert (settings.dt, settings.horizon, settings.refinements) == (DT, 4.0, 0)
    return prims, build_graph(prims, settings, n_A=12, n_B=12)


def near(value: float, exact: float) -> bool:
    """A fixed-step time: the first sample at or after the exact time."""
    return exact - 1e-9 <= value <= exact + DT + 1e-9


# ----------------------------------------------------------------------------- grids
def test_clock_grids_by_class(built):
    prims, g = built
    np.testing.assert_allclose(g.transitions[("Home", "Right")].t_A, [0.0])  # fixed: one point
    osc = g.transitions[("Osc", "Home")]
    np.testing.assert_allclose(osc.t_A, np.arange(8) * 0.5)  # one period, the primitive's own grid of 8
    np.testing.assert_allclose(g.transitions[("Home", "Osc")].t_B, np.arange(8) * 0.5)
    # a transient source ends its grid at t_f, where it hands over; as a target it stops short of t_f
    np.testing.assert_allclose(g.transitions[("Ramp", "Home")].t_A, [0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(g.transitions[("Home", "Ramp")].t_B, [0, 0.2, 0.4, 0.6, 0.8])


def test_every_ordered_pair_is_evaluated(built):
    prims, g = built
    names = list(prims)
    assert set(g.transitions) == {(a, b) for a in names for b in names if a != b}
    for tr in g.transitions.values():
        assert len(tr.evidence) == len(tr.t_A)
        assert all(len(row) == len(tr.t_B) and all(isinstance(e, OracleEvidence) for e in row)
                   for row in tr.evidence)
    assert g.nodes == names
    assert g.G.nodes["Ramp"] == {"cls": "transient", "period": None, "domain": (0.0, 1.0), "next": "Right"}
    assert g.G.nodes["Osc"]["period"] == 4.0


# ----------------------------------------------------------------------------- classes
def test_no_transition_when_the_target_starts_outside_its_safe_set(built):
    _, g = built
    tr = g.transitions[("Home", "Right")]
    assert tr.cls is TransitionClass.NONE
    assert g.edge("Home", "Right") is None and not g.G.has_edge("Home", "Right")
    (e,), = tr.evidence
    assert (e.verdict, e.reason, e.violated, e.t_stop) == (0, Reason.LEFT_C, "right_floor", 0.0)
    assert tr.windows == [] and tr.best_t_B == [None] and tr.weights == {}


def test_periodic_source_gives_class_2_with_the_right_window(built):
    """2 sin(pi t_A / 2) >= 1 for t_A in [1/3, 5/3]: grid points 0.5, 1.0, 1.5."""
    _, g = built
    tr = g.edge("Osc", "Right")
    assert tr is not None and tr.cls is TransitionClass.CLASS_2
    np.testing.assert_array_equal(tr.available, [False, True, True, True, False, False, False, False])
    assert tr.windows == [(0.5, 1.5)]
    assert tr.best_t_B == [None, 0.0, 0.0, 0.0, None, None, None, None]
    # slowest verified start: x0 = 2 at t_A = 1, |2 - 1.5| e^(-2 s) < 0.1 after ln(5)/2
    assert near(tr.weights["duration"], math.log(5) / 2)
    assert tr.weights["hops"] == 1.0
    assert tr.weights["peak_input"] == pytest.approx(1.0)  # 2 |2 - 1.5|
    assert g.G.edges["Osc", "Right"]["cls"] == 2
    assert tr.switch_clock(1.0) == 0.0
    assert tr.switch_clock(0.0) is None  # on the grid, not verified
    assert tr.switch_clock(0.75) is None  # off the grid


def test_transient_source_window(built):
    """1.5 t_A >= 1 for t_A >= 2/3: grid points 0.75 and 1.0."""
    _, g = built
    tr = g.edge("Ramp", "Right")
    assert tr.cls is TransitionClass.CLASS_2
    assert tr.windows == [(0.75, 1.0)]
    assert near(tr.weights["duration"], math.log(0.375 / 0.1) / 2)


@pytest.mark.parametrize("a, b, duration", [
    ("Osc", "Home", math.log(2 / 0.1) / 2),  # worst start x0 = +-2
    ("Right", "Home", math.log(1.5 / 0.1) / 2),
    ("Ramp", "Home", math.log(1.5 / 0.1) / 2),
    ("Home", "Osc", 0.0),  # switch in at t_B = 0 where x*(0) = 0: already in E
])
def test_class_1_edges_and_their_durations(built, a, b, duration):
    _, g = built
    tr = g.edge(a, b)
    assert tr is not None and tr.cls is TransitionClass.CLASS_1
    assert tr.available.all()
    assert near(tr.weights["duration"], duration)
    assert g.G.edges[a, b]["duration"] == tr.weights["duration"]


def test_periodic_target_switch_in_clock(built):
    """From x0 = 0 every t_B of Osc works (tracking error <= 2 decays in 0.6 s); the best is t_B = 0."""
    _, g = built
    tr = g.edge("Home", "Osc")
    np.testing.assert_array_equal(tr.verdicts, np.ones((1, 8), int))
    assert tr.best_t_B == [0.0]
    t_enter = [e.t_enter for e in tr.evidence[0]]
    assert t_enter[0] == t_enter[4] == 0.0  # x*(0) = x*(2) = 0
    assert near(t_enter[2], math.log(2 / 0.1) / 5)  # x*(1) = 2
    # from x0 = 1.5 the closest phase is x*(0.5) = sqrt(2): inside E at once
    assert g.edge("Right", "Osc").best_t_B == [0.5]


def test_transient_target_runs_out_of_time(built):
    """Ramp as target from x0 = 0: error 1.5 t_B must fall below 0.1 within 1 - t_B."""
    _, g = built
    tr = g.edge("Home", "Ramp")
    np.testing.assert_array_equal(tr.verdicts, [[1, 1, 1, 0, 0]])
    late = tr.evidence[0][3]  # t_B = 0.6: needs ln(9)/5 = 0.44 s, has 0.4 s
    assert late.reason is Reason.HORIZON and late.t_stop == pytest.approx(0.4)


# ----------------------------------------------------------------------------- failures do not stop the build
NAN_PROJECT = """\
project: nan_graph
system:
  name: line
  kind: analytic
  states: [x]
  inputs: [u]
  dynamics: {f: ["1e-9*sqrt((x - 0.4)*(x - 0.5))"], g: [[1]]}   # NaN for 0.4 < x < 0.5
primitives:
  - {name: Home, class: fixed, setpoint: {expr: [0]}, controller: {type: expression, u: ["-2*x"]}, roa: {radius: 0.1}}
  - {name: Mid, class: fixed, setpoint: {expr: [1]}, controller: {type: expression, u: ["-2*(x - 1)"]}, roa: {radius: 0.1}}
  - {name: Far, class: fixed, setpoint: {expr: [2]}, controller: {type: expression, u: ["-2*(x - 2)"]}, roa: {radius: 0.1}}
"""


def test_integration_failures_become_evidence_and_the_build_goes_on(tmp_path):
    path = tmp_path / "project.yaml"
    path.write_text(textwrap.dedent(NAN_PROJECT))
    spec = load_project(path)
    prims = compile_project(spec)
    g = build_graph(prims, settings_for(spec).replace(jit=False, refinements=0, horizon=4.0))
    crossing = {("Home", "Mid"), ("Home", "Far"), ("Mid", "Home"), ("Far", "Home")}  # pass through the band
    for (a, b), tr in g.transitions.items():
        (e,), = tr.evidence
        if (a, b) in crossing:
            assert (e.verdict, e.reason) == (0, Reason.INTEGRATION_FAILED), (a, b)
        else:
            assert e.verdict == 1 and near(e.t_enter, math.log(1 / 0.1) / 2), (a, b)
    assert set(g.G.edges) == {("Mid", "Far"), ("Far", "Mid")}


# ----------------------------------------------------------------------------- Definition 2 on hand-made evidence
def ev(verdict: int, t_enter: float | None = None, peak: float = 1.0) -> OracleEvidence:
    if verdict:
        return OracleEvidence(1, Reason.ENTERED_E, t_enter, t_enter=t_enter, peak_input=[peak])
    return OracleEvidence(0, Reason.LEFT_C, 0.1, violated="h")


def test_classify_hand_made_grid():
    t_A = np.array([0.0, 1.0, 2.0, 3.0])
    t_B = np.array([0.0, 0.5])
    cells = [[ev(1, 0.7, 2.0), ev(1, 0.3, 5.0)],  # both t_B work: the faster one (t_B = 0.5) is used
             [ev(0), ev(0)],
             [ev(0), ev(1, 0.9, 1.0)],
             [ev(1, 0.2, 3.0), ev(0)]]
    tr = Transition("A", "B", t_A, t_B, cells)
    tr.classify()
    assert tr.cls is TransitionClass.CLASS_2
    assert tr.best_t_B == [0.5, None, 0.5, 0.0]
    assert tr.windows == [(0.0, 0.0), (2.0, 3.0)]
    assert tr.weights == {"duration": 0.9, "peak_input": 5.0, "hops": 1.0}
    assert tr.switch_clock(3.0) == 0.0 and tr.switch_clock(1.0) is None


@pytest.mark.parametrize("rows, cls", [
    ([[1, 0], [0, 1]], TransitionClass.CLASS_1),  # each t_A has some t_B (a different one is fine)
    ([[1, 1], [0, 0]], TransitionClass.CLASS_2),
    ([[0, 0], [0, 0]], TransitionClass.NONE),
])
def test_algorithm_1_classes(rows, cls):
    cells = [[ev(v, 0.5) for v in row] for row in rows]
    tr = Transition("A", "B", np.array([0.0, 1.0]), np.array([0.0, 1.0]), cells)
    tr.classify()
    assert tr.cls is cls
    g = MotionPrimitiveGraph({"A": {"cls": "periodic"}, "B": {"cls": "fixed"}}, {("A", "B"): tr})
    assert g.G.has_edge("A", "B") == (cls is not TransitionClass.NONE)
    assert (g.edge("A", "B") is tr) == (cls is not TransitionClass.NONE)


def test_inconclusive_cells_give_no_edge_and_are_counted_by_the_assertion():
    from mpgspec.check.assertions import evaluate_assertions
    from mpgspec.spec.models import RequireConclusive

    doubt = OracleEvidence(0, Reason.INCONCLUSIVE, 0.3, status="inconclusive", violated="h", margin=1e-3,
                           error_bound=2e-3)
    tr = Transition("A", "B", np.array([0.0, 1.0]), np.array([0.0]), [[doubt], [doubt]])
    tr.classify()
    assert tr.cls is TransitionClass.NONE  # never safe, so never an edge
    g = MotionPrimitiveGraph({"A": {"cls": "fixed"}, "B": {"cls": "fixed"}}, {("A", "B"): tr})
    zero, two = evaluate_assertions([RequireConclusive(max_inconclusive=0), RequireConclusive(max_inconclusive=2)], g, {})
    assert (zero.status, two.status) == ("fail", "pass")
    assert zero.message == "2 inconclusive (A -> B: 2)"
