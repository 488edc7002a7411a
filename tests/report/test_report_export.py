"""DOT and GraphML exports of the motion primitive graph, from the report dict alone."""
from __future__ import annotations

import io
import json
import re
from pathlib import Path

import networkx as nx
import pytest

from mpgspec.report.export import to_dot, to_graphml

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"


@pytest.fixture
def sample() -> dict:
    return json.loads(SAMPLE.read_text(encoding="utf-8"))


def test_dot_uses_paper_notation(sample):
    dot = to_dot(sample)
    assert dot.startswith("digraph ") and dot.rstrip().endswith("}")
    assert '"Hang" [shape=box' in dot
    assert '"SwingUp" [shape=diamond' in dot
    assert '"Swing(1)" [shape=circle' in dot
    for e in sample["edges"]:
        line = next(ln for ln in dot.splitlines() if ln.strip().startswith(f'"{e["from"]}" -> "{e["to"]}"'))
        assert ("style=dashed" in line) == (e["class"] == 2)
        assert ("style=solid" in line) == (e["class"] == 1)
        assert re.search(r'label="[0-9.e+-]+ s"', line)
    assert dot.count(" -> ") == len(sample["edges"])


def test_dot_quotes_names(sample):
    sample["primitives"][0]["name"] = 'odd "name" \\ here'
    assert '"odd \\"name\\" \\\\ here" [shape=box' in to_dot(sample)


def test_graphml_round_trip(sample):
    G = nx.read_graphml(io.StringIO(to_graphml(sample)))
    assert G.is_directed()
    assert G.number_of_nodes() == len(sample["primitives"])
    assert G.number_of_edges() == len(sample["edges"])
    e = sample["edges"][0]
    attrs = G.edges[e["from"], e["to"]]
    assert attrs["class"] == e["class"] and attrs["duration"] == pytest.approx(e["duration"])
    assert attrs["method"] == "simulated"
    assert G.nodes["SwingUp"]["class"] == "transient" and G.nodes["SwingUp"]["next"] == "Balance"


def test_nominal_only_edges_in_dot_and_graphml(sample):
    dot = to_dot(sample)
    lost = next(ln for ln in dot.splitlines() if ln.strip().startswith('"Balance" -> "SwingUp"'))
    assert 'color="#D55E00"' in lost and "nominal only" in lost and "style=solid" in lost
    assert dot.count("nominal only") == 1
    G = nx.read_graphml(io.StringIO(to_graphml(sample)))
    assert G.edges["Balance", "SwingUp"]["robust"] is False and G.edges["Hang", "Swing(1)"]["robust"] is True
    G = nx.read_graphml(io.StringIO(to_graphml({**sample, "robust": None})))
    assert "robust" not in G.edges["Balance", "SwingUp"]
