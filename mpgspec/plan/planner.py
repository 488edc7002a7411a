"""Shortest safe transition sequences, and the all-pairs next-primitive table run on the robot.

A transient primitive cannot be left early: once switched in, it hands over to its `next`
primitive, so in the graph used for planning its only out-edge is the one to `next`.
"""
from __future__ import annotations

from dataclasses import dataclass

import networkx as nx

from ..graph.transition import MotionPrimitiveGraph

WEIGHTS = ("duration", "peak_input", "hops")


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
    the one to `next`, and only when the oracle verified it from t_A = t_f.
    """
    G = g.G.copy()
    for n, d in g.G.nodes(data=True):
        if d.get("cls") == "transient":
            for _, b in list(G.out_edges(n)):
                tr = g.edge(n, b)
                if b != d.get("next") or tr is None or tr.switch_clock(d["domain"][1]) is None:
                    G.remove_edge(n, b)
    return G


def shortest_plan(g: MotionPrimitiveGraph, source: str, goal: str, weight: str = "duration",
                  G: nx.DiGraph | None = None) -> Plan:
    """Dijkstra on the chosen weight (transition duration, peak input or hop count)."""
    if weight not in WEIGHTS:
        raise ValueError(f"unknown weight {weight!r}; expected one of {', '.join(WEIGHTS)}")
    G = plan_graph(g) if G is None else G
    if source == goal:
        return Plan(source, goal, weight, [source], 0.0)
    try:
        cost, path = nx.single_source_dijkstra(G, source, goal, weight=weight)
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return Plan(source, goal, weight, None, None)
    return Plan(source, goal, weight, path, float(cost))


def lookup_table(g: MotionPrimitiveGraph, weight: str = "duration") -> dict[str, dict[str, str | None]]:
    """table[current][goal] = next primitive to switch to (None when the goal is unreachable)."""
    G = plan_graph(g)
    table: dict[str, dict[str, str | None]] = {}
    for a in G.nodes:
        paths = nx.single_source_dijkstra_path(G, a, weight=weight)
        table[a] = {b: (paths[b][1] if len(paths[b]) > 1 else a) if b in paths else None for b in G.nodes}
    return table
