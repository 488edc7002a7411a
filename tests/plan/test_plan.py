"""Planning on the motion primitive graph: transients only continue to `next`, Dijkstra on the three
weights, and the all-pairs next-hop lookup table.

Hand-made graphs give exact costs; the line_graph fixture checks the same rules on a built graph.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.graph import MotionPrimitiveGraph, Transition, build_graph
from mpgspec.oracle import OracleEvidence, Reason
from mpgspec.plan.planner import Plan, lookup_table, plan_graph, shortest_plan
from mpgspec.spec.loader import load_project

FIXTURE = Path(__file__).parents[1] / "fixtures" / "line_graph" / "project.yaml"


def edge(a: str, b: str, duration: float, peak: float = 1.0) -> Transition:
    """A Class 1 transition whose single cell enters E after `duration` with input peak `peak`."""
    e = OracleEvidence(1, Reason.ENTERED_E, duration, t_enter=duration, peak_input=[peak])
    tr = Transition(a, b, np.zeros(1), np.zeros(1), [[e]])
    tr.classify()
    return tr


def graph(nodes: dict[str, dict], edges: list[tuple[str, str, float, float]]) -> MotionPrimitiveGraph:
    return MotionPrimitiveGraph(nodes, {(a, b): edge(a, b, d, p) for a, b, d, p in edges})


FIXED = {"cls": "fixed"}


@pytest.fixture()
def g() -> MotionPrimitiveGraph:
    """Stand -> Walk -> Run costs 1 + 1, Stand -> Run costs 5 (but a low input peak);
    Jump is transient and must hand over to Land, though an edge Jump -> Stand was verified."""
    nodes = {"Stand": FIXED, "Walk": FIXED, "Run": FIXED, "Land": FIXED, "Lie": FIXED,
             "Jump": {"cls": "transient", "next": "Land", "domain": (-1.0, 0.0)}}
    return graph(nodes, [
        ("Stand", "Walk", 1.0, 4.0), ("Walk", "Run", 1.0, 4.0), ("Stand", "Run", 5.0, 1.0),
        ("Run", "Jump", 0.5, 2.0), ("Jump", "Stand", 0.1, 1.0), ("Jump", "Land", 0.2, 1.0),
        ("Land", "Stand", 0.3, 1.0), ("Walk", "Stand", 1.0, 1.0), ("Run", "Walk", 1.0, 1.0),
    ])


def test_a_transient_hand_over_needs_a_verified_end(g):
    """Jump -> Land verified only from interior clock times: the hand-over at t_f is not, so no plan uses it."""
    ok = OracleEvidence(1, Reason.ENTERED_E, 0.2, t_enter=0.2, peak_input=[1.0])
    bad = OracleEvidence(0, Reason.LEFT_C, 0.0, violated="floor")
    tr = Transition("Jump", "Land", np.array([-1.0, -0.5, 0.0]), np.zeros(1), [[ok], [ok], [bad]])
    tr.classify()
    g.transitions[("Jump", "Land")] = tr
    assert tr.cls == 2 and tr.switch_clock(0.0) is None
    G = plan_graph(g)
    assert list(G.successors("Jump")) == []
    assert not shortest_plan(g, "Run", "Land").found or "Jump" not in shortest_plan(g, "Run", "Land").path


def test_transients_only_leave_to_next(g):
    G = plan_graph(g)
    assert g.G.has_edge("Jump", "Stand")  # verified by the oracle ...
    assert not G.has_edge("Jump", "Stand")  # ... but a transient cannot be left early
    assert list(G.successors("Jump")) == ["Land"]
    assert G.number_of_edges() == g.G.number_of_edges() - 1
    assert g.G.has_edge("Jump", "Stand")  # the oracle graph itself is not modified


@pytest.mark.parametrize("weight, path, cost", [
    ("duration", ["Stand", "Walk", "Run"], 2.0),
    ("hops", ["Stand", "Run"], 1.0),
    ("peak_input", ["Stand", "Run"], 1.0),
])
def test_shortest_plan_by_weight(g, weight, path, cost):
    plan = shortest_plan(g, "Stand", "Run", weight)
    assert plan.found
    assert (plan.path, plan.cost) == (path, pytest.approx(cost))
    assert plan.to_dict() == {"from": "Stand", "to": "Run", "weight": weight, "path": path, "cost": plan.cost}


def test_plan_through_a_transient_follows_next(g):
    plan = shortest_plan(g, "Run", "Stand")
    assert plan.path == ["Run", "Jump", "Land", "Stand"] and plan.cost == pytest.approx(1.0)
    # without the transient rule the verified Jump -> Stand edge would give a cheaper, unexecutable plan
    unrestricted = shortest_plan(g, "Run", "Stand", G=g.G)
    assert unrestricted.path == ["Run", "Jump", "Stand"]


def test_unreachable_and_trivial_plans(g):
    lost = shortest_plan(g, "Stand", "Lie")
    assert not lost.found and lost.path is None and lost.cost is None
    assert shortest_plan(g, "Lie", "Lie") == Plan("Lie", "Lie", "duration", ["Lie"], 0.0)
    with pytest.raises(ValueError, match="unknown weight"):
        shortest_plan(g, "Stand", "Run", "fun")


def test_lookup_table_next_hops(g):
    table = lookup_table(g)
    assert set(table) == set(g.nodes)
    assert all(set(row) == set(g.nodes) for row in table.values())
    assert table["Stand"]["Run"] == "Walk"
    assert table["Stand"]["Land"] == "Walk"  # Stand -> Walk -> Run -> Jump -> Land
    assert table["Run"]["Stand"] == "Jump"
    assert table["Jump"]["Stand"] == "Land"  # never the verified but forbidden Jump -> Stand
    assert table["Stand"]["Stand"] == "Stand"
    assert table["Stand"]["Lie"] is None and table["Lie"]["Stand"] is None
    assert lookup_table(g, "hops")["Stand"]["Run"] == "Run"
    # following the table always reaches the goal along a shortest plan
    for a in g.nodes:
        for b in g.nodes:
            plan = shortest_plan(g, a, b)
            if not plan.found:
                assert table[a][b] is None
                continue
            hops, cur = [a], a
            while cur != b:
                cur = table[cur][b]
                hops.append(cur)
                assert len(hops) <= len(g.nodes)
            assert hops == plan.path


def test_built_graph_plans(tmp_path):
    """line_graph: Ramp -> Home is verified, yet Ramp must go on to Right first."""
    spec = load_project(FIXTURE)
    g = build_graph(compile_project(spec), settings_for(spec).replace(jit=False))
    assert g.edge("Ramp", "Home") is not None
    assert list(plan_graph(g).successors("Ramp")) == ["Right"]
    plan = shortest_plan(g, "Ramp", "Home")
    assert plan.path == ["Ramp", "Right", "Home"]
    table = lookup_table(g)
    assert table["Ramp"] == {"Home": "Right", "Right": "Right", "Osc": "Right", "Ramp": "Ramp"}
    # Home cannot go to Right directly; Ramp (0 + 0.67 s) beats Osc (0 + 0.81 s)
    assert table["Home"]["Right"] == "Ramp"
    assert shortest_plan(g, "Home", "Right").path == ["Home", "Ramp", "Right"]
    assert shortest_plan(g, "Home", "Right", "hops").cost == 2.0


def test_no_plan_says_why():
    """Without a path the plan names what the start reaches and where the goal is entered from."""
    import networkx as nx

    from mpgspec.pipeline.plan import unreachable

    G = nx.DiGraph([("A", "B"), ("B", "A"), ("C", "D")])
    G.add_node("E")
    assert unreachable(G, "A", "D", "duration", False) == "A reaches B through edges; D is entered only from C"
    assert unreachable(G, "E", "A", "duration", True) == "E has no robust edge out; A is entered only from B"
    G.add_node("F")
    assert unreachable(G, "A", "F", "duration", False).endswith("no edge enters F")
    G.edges["A", "B"]["margin"] = 0.5
    why = unreachable(G, "A", "B", "margin", False)  # B -> A has no margin: A reaches B only
    assert why.startswith("A reaches B through edges") and "without a margin" in why
