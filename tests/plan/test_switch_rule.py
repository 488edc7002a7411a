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
    for (a, b), (_t_A, clocks, _shares) in plan.edges.items():
        # a transient hands over at the end of its domain whatever the margin: the rule chooses no time there
        rule = "first" if prims[a].cls.value == "transient" else "margin"
        handovers += rule == "first"
        assert clocks == switch_clocks(g.edge(a, b), rule)
        assert clocks == switch_clocks(pendulum.mpg.edge(a, b), rule)
    assert handovers == 1  # SwingUp -> Balance


@dataclass
class _Peaked:
    best_t_B: list
    row_peaks: list
    row_margins: list = field(default_factory=list)


def test_reserve_drops_the_rows_whose_cell_asks_too_much():
    e = _Peaked([0.0, None, 0.1, 0.2, 0.3], [[1.0, 2.0], None, [4.0, 0.5], [3.0, 3.2], None])
    bound = [5.0, 4.0]
    assert switch_clocks(e, "first", None, bound) == e.best_t_B
    # 0.8 of the bounds: 4.0 and 3.2; a cell at the share is kept, one above it (or without peaks) is not
    assert switch_clocks(e, "first", 0.8, bound) == [0.0, None, 0.1, 0.2, None]
    assert switch_clocks(e, "first", 0.5, bound) == [0.0, None, None, None, None]
    # peaks compare as report.json keeps them (4 significant digits): 3.20004 reads 3.2
    assert switch_clocks(_Peaked([0.2], [[3.0, 3.20004]]), "first", 0.8, bound) == [0.2]
    assert switch_clocks(_Peaked([0.2], [[3.0, 3.201]]), "first", 0.8, bound) == [None]
    # with 'margin', a row must pass both
    m = _Peaked([0.0, 0.1], [[1.0, 1.0], [9.0, 1.0]], [1.0, 1.0])
    assert switch_clocks(m, "margin", 0.8, bound) == [0.0, None]


def test_the_executor_plan_keeps_a_reserve_alike_from_the_report_and_in_memory(pendulum):
    """With sequence.reserve the plan takes, from the report or the graph in memory, the same clocks:
    the rule's, less those whose cell asks more than the share of the input bound (a transient still
    hands over at every verified clock)."""
    report, prims = pendulum.report, pendulum.compiled.prims
    g = ReportGraph(report)
    seq = pendulum.compiled.spec.project.sequence
    bound = float(np.max(np.abs(prims["Balance"].system.u_hi)))
    full = ExecutorPlan.of(g, report["lookup_table"]["next"], seq, prims)
    share = 0.8  # the swings saturate their 7 N m in many of the cells the rule takes
    kept = ExecutorPlan.of(g, report["lookup_table"]["next"], seq.model_copy(update={"reserve": share}), prims)
    mem = ExecutorPlan.of(pendulum.mpg, report["lookup_table"]["next"], seq.model_copy(update={"reserve": share}),
                          prims)
    assert kept.edges == mem.edges
    dropped = 0
    for (a, b), (_t_A, clocks, _shares) in kept.edges.items():
        before = full.edges[(a, b)][1]
        tr = g.edge(a, b)
        for c, c0, p in zip(clocks, before, tr.row_peaks):
            if prims[a].cls.value == "transient":
                assert c == c0
            elif c is not None:
                assert c == c0 and float(f"{p[0]:.4g}") <= share * bound
            else:
                dropped += c0 is not None
    assert dropped > 0 and any(c is not None for a, b in kept.edges if prims[a].cls.value != "transient"
                               for c in kept.edges[(a, b)][1])


@dataclass
class _Kept:
    best_t_B: list
    row_keeps: list
    row_margins: list = field(default_factory=list)


def test_keep_drops_the_rows_whose_cell_keeps_too_little():
    e = _Kept([0.0, None, 0.1, 0.2, 0.3], [{"friction_cone": 6.0, "q_max": 0.1}, None, {"friction_cone": 4.999999},
                                          {"q_max": 0.0}, None])
    assert switch_clocks(e, "first") == e.best_t_B
    # a cell below the value is dropped; a target without the family keeps its row; unknown values drop it
    assert switch_clocks(e, "first", keep={"friction_cone": 5.0}) == [0.0, None, None, 0.2, None]
    assert switch_clocks(e, "first", keep={"friction_cone": 5.0, "q_max": 0.05}) == [0.0, None, None, None, None]
    assert switch_clocks(e, "first", keep={"friction_cone": 4.0}) == [0.0, None, 0.1, 0.2, None]
    # with a reserve as well, a row must pass both
    p = _Peaked([0.0, 0.1], [[1.0, 1.0], [9.0, 1.0]])
    p.row_keeps = [{"friction_cone": 1.0}, {"friction_cone": 9.0}]
    assert switch_clocks(p, "first", 0.8, [5.0, 4.0], {"friction_cone": 2.0}) == [None, None]
    assert switch_clocks(p, "first", None, [5.0, 4.0], {"friction_cone": 0.5}) == [0.0, 0.1]


def test_the_executor_plan_keeps_alike_from_the_report_and_in_memory(pendulum):
    """With sequence.keep the plan takes, from the report or the graph in memory, the same clocks: the
    rule's, less those whose cell keeps the family below the value (report.json's 4 digits on both)."""
    report, prims = pendulum.report, pendulum.compiled.prims
    g = ReportGraph(report)
    seq = pendulum.compiled.spec.project.sequence
    full = ExecutorPlan.of(g, report["lookup_table"]["next"], seq, prims)
    taken = [m["speed_limit"] for (a, b), (_t, clocks, _s) in full.edges.items() if prims[a].cls.value != "transient"
             for c, m in zip(clocks, g.edge(a, b).row_keeps) if c is not None]
    value = float(np.median(taken))  # about half of the rows the rule takes keep less than this
    keep = seq.model_copy(update={"keep": {"speed_limit": value}})
    kept = ExecutorPlan.of(g, report["lookup_table"]["next"], keep, prims)
    assert kept.edges == ExecutorPlan.of(pendulum.mpg, report["lookup_table"]["next"], keep, prims).edges
    dropped = left = 0
    for (a, b), (_t_A, clocks, _shares) in kept.edges.items():
        for c, c0, m in zip(clocks, full.edges[(a, b)][1], g.edge(a, b).row_keeps):
            if prims[a].cls.value == "transient":
                assert c == c0
            elif c is not None:
                assert c == c0 and m["speed_limit"] >= value
                left += 1
            else:
                dropped += c0 is not None
    assert dropped > 0 and left > 0


def test_the_rows_the_rules_compare_read_alike_from_the_report_and_in_memory(pendulum):
    """The peaks and kept values reserve and keep compare are the same numbers in memory and in report.json
    (rounded once, to its 4 digits), on every edge, so a run from the report switches where verify's did."""
    g = ReportGraph(pendulum.report)
    rows = 0
    for (a, b), tr in pendulum.mpg.transitions.items():
        rt = g.edge(a, b)
        if rt is None:
            continue
        assert tr.row_keeps == rt.row_keeps, (a, b)
        assert [None if p is None else [float(f"{v:.4g}") for v in p] for p in tr.row_peaks] == rt.row_peaks, (a, b)
        rows += sum(k is not None for k in tr.row_keeps)
    assert rows > 100
