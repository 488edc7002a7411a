"""Shortest safe transition sequences, and the all-pairs next-primitive table run on the robot.

A transient primitive cannot be left early: once switched in, it hands over to its `next`
primitive, so in the graph used for planning its only out-edge is the one to `next`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import networkx as nx

if TYPE_CHECKING:  # the planner itself needs only networkx, so that planning from a report stays light
    from ..graph.transition import MotionPrimitiveGraph

WEIGHTS = ("duration", "peak_input", "hops", "margin")
MARGIN_FLOOR = 1e-6
"""The least margin the margin weight divides by (an edge that touches a boundary costs 1e6)."""


def cost(weight: str):
    """What Dijkstra minimises for a weight: the edge attribute of that name, summed along the path;
    for `margin` (an edge's least normalised safety margin, 0 to about 1) its reciprocal, so that a
    path avoids thin edges (one edge of margin 0.01 costs as much as fifty of 0.5); an edge without
    a margin (none computed, or a robust edge) is not taken."""
    if weight != "margin":
        return weight
    return lambda _a, _b, d: 1.0 / max(d["margin"], MARGIN_FLOOR) if d.get("margin") is not None else None


@dataclass
class Plan:
    """A sequence of primitives from source to goal and its total cost under one weight."""

    source: str
    goal: str
    weight: str
    path: list[str] | None
    cost: float | None

    @property
    def found(self) -> bool:
        return self.path is not None

    def to_dict(self) -> dict:
        return {"from": self.source, "to": self.goal, "weight": self.weight, "path": self.path, "cost": self.cost}


def plan_graph(g: MotionPrimitiveGraph) -> nx.DiGraph:
    """The graph restricted to executable moves.

    A transient hands over to its `next` at the end of its domain, so its only usable out-edge is
    the one to `next`, and only when the oracle verified it from t_A = t_f. Any other edge is usable
    while some verified row was not refused by the check from E_A's boundary (robust/from_roa.py).
    """
    G = g.G.copy()
    for n, d in g.G.nodes(data=True):
        for _, b in list(G.out_edges(n)):
            tr = g.edge(n, b)
            if d.get("cls") == "transient":
                if b != d.get("next") or tr is None or tr.switch_clock(d["domain"][1]) is None:
                    G.remove_edge(n, b)
            elif tr is not None and getattr(tr, "row_from_roa", None) and not _executable(tr):
                G.remove_edge(n, b)
    return G


def _executable(tr) -> bool:
    """Whether some verified row of the edge survived the check from E_A's boundary."""
    from ..graph.transition import from_roa_ok  # imported when a report or graph carries the check

    return any(t_b is not None and ok for t_b, ok in zip(tr.best_t_B, from_roa_ok(tr)))


def shortest_path(G: nx.DiGraph, source: str, goal: str,
                  weight: str = "duration") -> tuple[list[str] | None, float | None]:
    """Dijkstra on the chosen weight (transition duration, peak input, hop count or margin) over a planner's
    graph; (None, None) when the goal cannot be reached."""
    if weight not in WEIGHTS:
        raise ValueError(f"unknown weight {weight!r}; expected one of {', '.join(WEIGHTS)}")
    if source == goal:
        return [source], 0.0
    try:
        total, path = nx.single_source_dijkstra(G, source, goal, weight=cost(weight))
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return None, None
    return path, float(total)


def shortest_plan(g: MotionPrimitiveGraph, source: str, goal: str, weight: str = "duration",
                  G: nx.DiGraph | None = None) -> Plan:
    """The shortest safe sequence in g's planner graph (or in G when given)."""
    if weight not in WEIGHTS:
        raise ValueError(f"unknown weight {weight!r}; expected one of {', '.join(WEIGHTS)}")
    path, cost = shortest_path(plan_graph(g) if G is None else G, source, goal, weight)
    return Plan(source, goal, weight, path, cost)


def hops(edge, path: list[str] | None) -> list[dict]:
    """Each hop of a path: from, to, class, duration and the t_A windows to wait for (Class 2).
    edge(a, b) returns an object with cls, windows and weights (a Transition or a report's)."""
    out = []
    for a, b in zip(path or [], (path or [])[1:]):
        tr = edge(a, b)
        cls = int(tr.cls) if tr is not None else None
        out.append({"from": a, "to": b, "class": cls,
                    "duration": (tr.weights or {}).get("duration") if tr is not None else None,
                    "windows": [list(w) for w in tr.windows] if tr is not None and cls == 2 else []})
    return out


def lookup_table(g: MotionPrimitiveGraph, weight: str = "duration") -> dict[str, dict[str, str | None]]:
    """table[current][goal] = next primitive to switch to (None when the goal is unreachable)."""
    return next_table(plan_graph(g), weight)


def next_table(G: nx.DiGraph, weight: str = "duration") -> dict[str, dict[str, str | None]]:
    """table[current][goal] = the next primitive on the shortest path of a planner's graph G."""
    table: dict[str, dict[str, str | None]] = {}
    for a in G.nodes:
        paths = nx.single_source_dijkstra_path(G, a, weight=cost(weight))
        table[a] = {b: (paths[b][1] if len(paths[b]) > 1 else a) if b in paths else None for b in G.nodes}
    return table


def takeable(G: nx.DiGraph, weight: str) -> nx.DiGraph:
    """G without the edges a weight cannot take (for margin: those without a margin)."""
    w = cost(weight)
    return G if isinstance(w, str) else G.edge_subgraph([(a, b) for a, b, d in G.edges(data=True)
                                                          if w(a, b, d) is not None])
