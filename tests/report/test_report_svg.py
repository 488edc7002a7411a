"""SVG builders: well-formed XML, escaped text, missing values and decimation."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from mpgspec.report.compact import expand_cells, run_rows
from mpgspec.report.svg import DASH, DOT, VERMILLION, graph_dot, graph_svg, grid_svg, series_svg, trajectory_svg

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"
NS = "{http://www.w3.org/2000/svg}"


@pytest.fixture
def sample() -> dict:
    return json.loads(SAMPLE.read_text(encoding="utf-8"))


def _parse(text: str) -> ET.Element:
    root = ET.fromstring(text)
    assert root.tag == NS + "svg"
    return root


def test_series_breaks_lines_at_none():
    root = _parse(series_svg([0.0, 1.0, 2.0, 3.0, 4.0], {"h1": [1.0, None, 0.5, -0.5, None], "h2": [None] * 5}))
    paths = [p.get("d") for p in root.iter(NS + "path")]
    assert len(paths) == 1 and paths[0].count("M") == 2  # h1 in two pieces, h2 has no line
    assert any(r.get("fill") == VERMILLION for r in root.iter(NS + "rect"))  # h < 0 is shaded


def test_series_all_missing_and_nan():
    root = _parse(series_svg([0.0, float("nan")], {"h": [None, float("inf")]}))
    assert "no data" in "".join(root.itertext())


def test_series_decimates():
    t = [i * 0.001 for i in range(20000)]
    text = series_svg(t, {"h": [1.0 - x for x in t]}, max_points=300)
    assert len(text) < 20000


def test_text_is_escaped(sample):
    sample["primitives"][0]["name"] = "<b>&x"
    for e in sample["edges"]:
        e["from"], e["to"] = ("<b>&x" if e[k] == "Hang" else e[k] for k in ("from", "to"))
    text = graph_svg(sample)
    assert "<b>&x" not in text and "&lt;b&gt;&amp;x" in text
    _parse(text)


def test_graph_shapes(sample):
    root = _parse(graph_svg(sample))
    lost = {tuple(x.split(" -> ")) for x in sample["robust"]["summary"]["nominal_only"]}
    dashed = [p for p in root.iter(NS + "path") if p.get("stroke-dasharray") == DASH and p.find(NS + "title") is not None]
    assert len(dashed) == sum(e["class"] == 2 and (e["from"], e["to"]) not in lost for e in sample["edges"])
    assert root.find(f".//{NS}polygon") is not None and root.find(f".//{NS}ellipse") is not None
    assert graph_svg(sample) == graph_svg(sample)


def test_grid_and_trajectory(sample):
    tr = next(t for t in sample["transitions"] if t["class"] == 2)
    tr["cells"]["refined"][0] = "1" + tr["cells"]["refined"][0][1:]
    root = _parse(grid_svg({**tr, "cells": expand_cells(tr)}))
    assert root.find(f".//{NS}circle") is not None
    seq = sample["sequence"]
    for run in seq["runs"].values():
        root = _parse(trajectory_svg(run_rows(run), seq["state_names"], seq["commands"]))
        labels = "".join(root.itertext())
        assert all(f"→ {s['to']}" in labels for s in run["switches"])
    run = {"t": [0.0, 1.0], "x": [[1.0, 2.0], [1.5, 2.5]], "min_h": [1.0, 1.0], "switches": [], "violations": []}
    names = ["a", "b", "c", "d"]  # the run kept its first two states
    labels = "".join(_parse(trajectory_svg(run, names)).itertext())
    assert "a" in labels and "b" in labels and "(2 more not drawn)" in labels and "c" not in labels.replace("(2 more not drawn)", "")


def _edge_paths(root: ET.Element) -> dict[tuple[str, str], ET.Element]:
    """Edge paths of the built-in graph by (from, to), read from their tooltips."""
    out = {}
    for p in root.iter(NS + "path"):
        t = p.find(NS + "title")
        if t is not None and " → " in t.text:
            a, rest = t.text.split(" → ", 1)
            out[(a, rest.split(":", 1)[0])] = p
    return out


def test_nominal_only_edges_are_vermillion_in_their_class_style_with_a_legend(sample):
    """Robustness is the colour, class the line style (solid 1, dashed 2): never one channel for both."""
    lost = {tuple(x.split(" -> ")) for x in sample["robust"]["summary"]["nominal_only"]}
    assert lost == {("Balance", "SwingUp")}
    root = _parse(graph_svg(sample))
    paths = _edge_paths(root)
    assert set(paths) == {(e["from"], e["to"]) for e in sample["edges"]}
    classes = {(e["from"], e["to"]): e["class"] for e in sample["edges"]}
    for pair, p in paths.items():
        assert (p.get("stroke-dasharray") == DASH) == (classes[pair] == 2), pair
        assert p.get("stroke-dasharray") != DOT
        assert (p.get("stroke") == VERMILLION) == (pair in lost and next(
            e for e in sample["edges"] if (e["from"], e["to"]) == pair).get("usable", True) is not False)
        assert ("nominal only" in p.find(NS + "title").text) == (pair in lost)
    assert "nominal only" in "".join(root.itertext())  # the legend entry
    assert "nominal only" not in graph_svg({**sample, "robust": None})


def test_nominal_only_edges_in_the_graphviz_layout(sample):
    lines = {ln.split(" [", 1)[0].strip(): ln for ln in graph_dot(sample).splitlines() if " -> " in ln}
    lost = lines.pop('"Balance" -> "SwingUp"')
    cls = next(e["class"] for e in sample["edges"] if (e["from"], e["to"]) == ("Balance", "SwingUp"))
    assert f"style={'dashed' if cls == 2 else 'solid'}" in lost and f'color="{VERMILLION}"' in lost
    assert "nominal only" in lost
    assert not any(VERMILLION in ln or "nominal only" in ln for ln in lines.values())
    assert "style=dotted" not in graph_dot(sample) and "nominal only" not in graph_dot({**sample, "robust": None})


def test_a_window_of_one_grid_point_is_a_point():
    from mpgspec.report.svg import windows_text
    assert windows_text([[0.0, 0.0], [0.12, 0.24]]) == "{0} ∪ [0.12, 0.24]"
    assert windows_text([[0.0, 0.0], [0.1, 0.1], [0.2, 0.3]], 1) == "{0} and 2 more"
