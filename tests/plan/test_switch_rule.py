"""`sequence.switch`: where in a periodic primitive's cycle the graph run leaves it. 'first' takes
the first verified t_A the run meets; 'margin' only the t_A whose least normalised safety margin
(the report's row_margins) is at least MARGIN_SHARE of the edge's best."""
from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from mpgspec import api
from mpgspec.compile.contacts import grid_clock
from mpgspec.execute.crosscheck.executor import ExecutorPlan
from mpgspec.graph.transition import MARGIN_SHARE, switch_clocks
from mpgspec.report.read import ReportGraph

PENDULUM = Path(__file__).resolve().parents[2] / "specs" / "pendulum"


@dataclass
class _Edge:
    best_t_B: list
    row_margins: list = field(default_factory=list)


def test_margin_keeps_the_well_kept_rows_only():
    e = _Edge([0.0, None, 0.1, 0.2, 0.3], [0.5, None, 0.9, 1.0, 0.7])
    assert switch_clocks(e, "first") == e.best_t_B
    assert switch_clocks(e, "margin") == [None, None, 0.1, 0.2, None]
    # the best row is always kept; rows without measured margins switch as 'first'
    assert switch_clocks(_Edge([0.0, 0.1], [0.0, 0.0]), "margin") == [0.0, 0.1]
    assert switch_clocks(_Edge([0.0, 0.1]), "margin") == [0.0, 0.1]
    assert switch_clocks(_Edge([None, None], [None, None]), "margin") == [None, None]


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    """The pendulum verified with `switch: margin` (its sequence leaves swings for larger ones)."""
    proj = tmp_path_factory.mktemp("switch") / "pendulum"
    shutil.copytree(PENDULUM, proj)
    spec = proj / "project.yaml"
    text = spec.read_text()
    spec.write_text(text.replace("  duration: 40\n", "  duration: 40\n  switch: margin\n"))
    return api.verify(proj)["pendulum"]


def _left_at(report: dict) -> list[tuple[str, str, float]]:
    """(from, to, t_A on the grid clock) of each graph-run switch out of a periodic primitive."""
    prims = {p["name"]: p for p in report["primitives"]}
    out, since = [], None
    for s in report["sequence"]["runs"]["graph"]["switches"]:
        a = s.get("from")
        if a is not None and prims[a]["class"] == "periodic" and s["reason"].startswith("towards"):
            out.append((a, s["to"], grid_clock(since[1] + s["t"] - since[0], prims[a]["period"])))
        since = (s["t"], s["clock"])
    return out


def test_the_graph_run_leaves_swings_at_well_kept_phases_only(pendulum):
    report = pendulum.report
    assert report["lookup_table"]["switch"] == "margin"
    assert report["sequence"]["runs"]["graph"]["safe"]
    trs = {(t["from"], t["to"]): t for t in report["transitions"]}
    left = _left_at(report)
    assert left, "the sequence leaves no periodic primitive"
    thinned = 0
    for a, b, c in left:
        t = trs[(a, b)]
        i = int(np.argmin(np.abs(np.array(t["t_A"]) - c)))
        rows = [m for m, tb in zip(t["row_margins"], t["best_t_B"]) if tb is not None]
        assert t["row_margins"][i] >= MARGIN_SHARE * max(rows) - 1e-12, (a, b, c)
        thinned += sum(m < MARGIN_SHARE * max(rows) for m in rows)
    assert thinned > 0, "no edge taken has a thin verified row: the rule was not exercised"


def test_the_executor_plan_reads_the_same_rule_from_the_report(pendulum):
    """The executor's plan, from the report or the graph in memory, takes the switch-in clocks the rule
    takes; a transient's hand-over keeps every verified clock."""
    report, prims = pendulum.report, pendulum.compiled.prims
    g = ReportGraph(report)
    seq = pendulum.compiled.spec.project.sequence
    plan = ExecutorPlan.of(g, report["lookup_table"]["next"], seq, prims)
    assert plan.edges, "the plan has no edges"
    handovers = 0
    for (a, b), (_t_A, clocks) in plan.edges.items():
        # a transient hands over at the end of its domain whatever the margin: the rule chooses no time there
        rule = "first" if prims[a].cls.value == "transient" else "margin"
        handovers += rule == "first"
        assert clocks == switch_clocks(g.edge(a, b), rule)
        assert clocks == switch_clocks(pendulum.mpg.edge(a, b), rule)
    assert handovers == 1  # SwingUp -> Balance
