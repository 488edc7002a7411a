"""Executing a goal sequence naively and through the graph (the paper's Table II experiment) on the
line_graph fixture, where the safe and unsafe switches are known by hand.

Home (x* = 0) cannot switch to Right (needs x >= 1): naive switching violates `right_floor` at
once; through the graph the run goes Home -> Ramp (x* = 1.5 t) -> Right, leaving Ramp at the first
clock where Ramp -> Right was verified (t_A = 0.75, x* = 1.125) once its flow is inside its E.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.execute.sequence import simulate_sequence
from mpgspec.graph import build_graph
from mpgspec.plan.planner import lookup_table, shortest_plan
from mpgspec.spec.loader import load_project
from mpgspec.spec.models import GoalCommand, Sequence

FIXTURE = Path(__file__).parents[1] / "fixtures" / "line_graph" / "project.yaml"
DT = 0.01


@pytest.fixture(scope="module")
def world():
    spec = load_project(FIXTURE)
    settings = settings_for(spec).replace(jit=False)
    prims = compile_project(spec)
    g = build_graph(prims, settings)
    return prims, g, lookup_table(g), settings


def run(world, mode: str, start: str, commands: list[tuple[float, str]], duration: float):
    prims, g, table, settings = world
    seq = Sequence(start=start, duration=duration, commands=[GoalCommand(t=t, goal=n) for t, n in commands])
    return simulate_sequence(prims, g, table, seq, settings, mode)


def hops(r) -> list[tuple[str, str]]:
    return [(s["to"], s["reason"]) for s in r.switches]


def x_at(r, t: float) -> float:
    i = min(range(len(r.t)), key=lambda k: abs(r.t[k] - t))
    return r.x[i][0]


def test_naive_switch_violates_safety(world):
    r = run(world, "naive", "Home", [(0.5, "Right")], 3.0)
    assert not r.safe
    assert hops(r) == [("Home", "start"), ("Right", "commanded")]
    assert r.switches[1]["t"] == pytest.approx(0.5) and r.switches[1]["clock"] == 0.0
    v = r.violations[0]
    assert (v["primitive"], v["h"]) == ("Right", "right_floor")
    assert v["t"] == pytest.approx(0.5) and v["value"] == pytest.approx(-1.0)  # h = x - 1 at x = 0
    assert r.final_primitive == "Right" and r.failed == ""


def test_graph_execution_is_safe_and_follows_the_plan(world):
    prims, g, table, _ = world
    r = run(world, "graph", "Home", [(0.5, "Right")], 3.0)
    assert r.safe and r.violations == []
    assert hops(r) == [("Home", "start"), ("Ramp", "towards Right"), ("Right", "end of domain")]
    assert [s["to"] for s in r.switches] == shortest_plan(g, "Home", "Right").path
    to_ramp, to_right = r.switches[1], r.switches[2]
    assert to_ramp["t"] == pytest.approx(0.5)  # Home sits in its E from the start: no wait
    assert to_ramp["clock"] == g.edge("Home", "Ramp").best_t_B[0] == 0.0
    # Ramp -> Right is verified from t_A = 0.75 on, but a transient is not left early: Ramp tracks
    # x* = 1.5 t to the end of its domain and hands over to its next there
    assert g.edge("Ramp", "Right").windows == [(0.75, 1.0)]
    assert to_right["t"] == pytest.approx(0.5 + 1.0, abs=DT + 1e-9)
    assert to_right["clock"] == g.edge("Ramp", "Right").switch_clock(1.0)
    assert x_at(r, to_right["t"]) == pytest.approx(1.5, abs=2e-2)
    assert r.final_primitive == "Right"
    assert abs(r.x[-1][0] - 1.5) < 0.1  # settled in Right's E
    assert all(h is None or h >= 0 for h in r.min_h)


def test_graph_mode_waits_for_the_periodic_window(world):
    """From Osc the switch to Right is verified only at t_A in {0.5, 1.0, 1.5}; naive switches at 0."""
    naive = run(world, "naive", "Osc", [(0.0, "Right")], 2.0)
    assert not naive.safe and naive.violations[0]["t"] == 0.0
    r = run(world, "graph", "Osc", [(0.0, "Right")], 2.0)
    assert r.safe
    assert hops(r) == [("Osc", "start"), ("Right", "towards Right")]
    assert r.switches[1]["t"] == pytest.approx(0.5)
    assert x_at(r, 0.5) == pytest.approx(math.sqrt(2), abs=1e-3)


def test_graph_mode_leaves_only_after_entering_E(world):
    """Right -> Home at t = 0; the new goal Right at t = 0.01 must wait until Home's flow from x = 1.5
    is inside E (|x| < 0.1 after ln(15)/2 = 1.35 s), then go on through Ramp."""
    r = run(world, "graph", "Right", [(0.0, "Home"), (0.01, "Right")], 4.0)
    assert hops(r) == [("Right", "start"), ("Home", "towards Home"), ("Ramp", "towards Right"),
                       ("Right", "end of domain")]
    assert r.switches[1]["t"] == 0.0
    t_leave = r.switches[2]["t"]
    assert math.log(15) / 2 - 1e-9 <= t_leave <= math.log(15) / 2 + DT + 1e-9
    assert abs(x_at(r, t_leave)) < 0.1
    assert r.safe and r.final_primitive == "Right"


def test_transient_hands_over_to_next_at_the_end_of_its_domain(world):
    naive = run(world, "naive", "Ramp", [(0.0, "Ramp")], 2.0)
    assert hops(naive) == [("Ramp", "start"), ("Right", "end of domain")]
    assert naive.switches[1]["t"] == pytest.approx(1.0, abs=DT + 1e-9)
    assert naive.switches[1]["clock"] == 0.0
    assert naive.safe  # tracking x = 1.5 t exactly, it arrives at x = 1.5 >= 1


def test_graph_mode_hands_over_at_the_end_when_not_yet_converged(world):
    """Right -> Ramp switches in at the verified clock 0.6 (x* = 0.9, x = 1.5): the error 0.6 needs
    ln(6)/5 = 0.36 s to fall inside E, too late for the window point 0.75, so Ramp runs to its end
    (0.4 s later) and hands over to Right at Ramp -> Right's verified clock for t_A = t_f."""
    _, g, _, _ = world
    r = run(world, "graph", "Right", [(0.0, "Ramp"), (0.05, "Right")], 2.0)
    assert hops(r) == [("Right", "start"), ("Ramp", "towards Ramp"), ("Right", "end of domain")]
    assert r.switches[1]["clock"] == g.edge("Right", "Ramp").best_t_B[0] == pytest.approx(0.6)
    assert r.switches[2]["t"] == pytest.approx(0.4, abs=DT + 1e-9)
    assert r.switches[2]["clock"] == g.edge("Ramp", "Right").switch_clock(1.0) == 0.0
    assert r.safe and r.final_primitive == "Right"


def test_a_function_violated_for_long_hides_no_other(tmp_path):
    """Right with a second function that is always the more violated one (x - 2 < x - 1): every
    sample's worst is `far`, yet right_floor's first violation (t = 0.5, -1) is recorded too, once;
    the most violated function is kept for the first 50 violating samples only."""
    text = FIXTURE.read_text().replace('      - {name: right_floor, h: "x - 1"}\n',
                                       '      - {name: right_floor, h: "x - 1"}\n      - {name: far, h: "x - 2"}\n')
    path = tmp_path / "project.yaml"
    path.write_text(text)
    spec = load_project(path)
    prims = compile_project(spec)
    seq = Sequence(start="Home", duration=3.0, commands=[GoalCommand(t=0.5, goal="Right")])
    r = simulate_sequence(prims, None, None, seq, settings_for(spec).replace(jit=False), "naive")
    assert r.violations[0]["h"] == "far" and r.violations[0]["value"] == pytest.approx(-2.0)
    floor = [v for v in r.violations if v["h"] == "right_floor"]
    assert len(floor) == 1 and floor[0]["t"] == pytest.approx(0.5) and floor[0]["value"] == pytest.approx(-1.0)
    far = [v for v in r.violations if v["h"] == "far"]
    assert len(far) == 50 and len({v["t"] for v in r.violations}) == 50  # x < 2 for the whole run


def test_the_margin_weight_avoids_thin_edges(world):
    """Right's floor x >= 1 is 0.5 from its setpoint 1.5. Osc -> Right switches from x = 2 sin(pi/4)
    at the earliest (the flow then rises monotonically to 1.5): least margin (sqrt 2 - 1) / 0.5;
    Ramp -> Right from x = 1.5 * 0.75: (1.125 - 1) / 0.5 = 0.25; edges into a primitive without
    safety functions have margin 1. Home -> Right: the fastest plan goes through Ramp, the one that
    keeps the most margin through Osc (cost 1 + 1/0.83 against 1 + 1/0.25)."""
    _prims, g, _table, _settings = world
    m = {k: tr.weights.get("margin") for k, tr in g.transitions.items() if tr.weights}
    assert m[("Osc", "Right")] == pytest.approx(2 * (math.sqrt(2) - 1), abs=2e-3)
    assert m[("Ramp", "Right")] == pytest.approx(0.25, abs=2e-3)
    assert m[("Home", "Osc")] == m[("Home", "Ramp")] == 1.0
    fast, wide = shortest_plan(g, "Home", "Right", "duration"), shortest_plan(g, "Home", "Right", "margin")
    assert fast.path == ["Home", "Ramp", "Right"] and wide.path == ["Home", "Osc", "Right"]
    assert wide.cost == pytest.approx(1 + 1 / m[("Osc", "Right")])


def test_a_sequence_runs_in_its_own_step(world):
    """sequence.dt sets the runs' step (the oracle's by default): the samples lie that far apart
    and the run goes through the same switches at the same times."""
    prims, g, table, settings = world
    cmds = [GoalCommand(t=0.5, goal="Right")]
    own = simulate_sequence(prims, g, table, Sequence(start="Home", duration=3.0, commands=cmds, dt=DT / 4),
                            settings, "naive")
    default = run(world, "naive", "Home", [(0.5, "Right")], 3.0)
    assert own.t[1] - own.t[0] == pytest.approx(DT / 4) and default.t[1] - default.t[0] == pytest.approx(DT)
    assert hops(own) == hops(default) and own.switches[1]["t"] == pytest.approx(0.5)
    assert not own.safe and own.violations[0]["value"] == pytest.approx(-1.0)
