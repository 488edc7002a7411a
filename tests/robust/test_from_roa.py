"""Switches checked from the boundary of E_A: the share of r_A a switch is verified from, against a
target whose safe region of attraction is known in closed form, and the executor that keeps to it.

x' = x + u. Hold: u = -4x (x' = -3x, stable everywhere), E_Hold of radius R. Go: u = -2x + x^3, so
x' = -x + x^3: from |x0| < 1 the flow converges to 0 (x^2 = 1 / (1 + (1/x0^2 - 1) e^2t)), from |x0| > 1
it escapes in finite time and leaves C = {16 - x^2 >= 0}. Algorithm 1 checks Hold -> Go from
x_Hold* = 0 only, where Go is safe. From E_Hold's boundary |x0| = R the switch is safe iff R < 1; the
check tries R, R/2, R/4 in turn, so its share is the first of 1, 1/2, 1/4 with share x R < 1.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.execute.crosscheck.executor import ExecutorPlan

TAIL = """\
oracle: {{horizon: 3, dt: 0.01, accuracy: low, grid: {{t_A: 2, t_B: 2}}{extra}}}
assumptions: {{roa_invariant: warn}}
sequence:
  start: Hold
  duration: 4
  dt: 0.01
  commands:
    - {{t: 0, goal: Hold}}
    - {{t: 1, goal: Go}}
"""


def _verify(tmp_path: Path, line_spec, r: float, samples: int | None = 8):
    path = tmp_path / "project.yaml"
    tail = TAIL.format(extra="" if samples is None else f", from_roa: {samples}")
    path.write_text(line_spec("escape", 100, [("Hold", "-4*x", "16 - x^2", r), ("Go", "-2*x + x^3", "16 - x^2", 0.2)],
                              tail))
    res = api.verify([path], out_dir=None, overrides={"jit": False})
    (p,) = res.projects
    assert not p.errors, p.errors
    (tr,) = [t for t in p.report["transitions"] if t["from"] == "Hold" and t["to"] == "Go"]
    (edge,) = [e for e in p.report["edges"] if e["from"] == "Hold" and e["to"] == "Go"]
    return p.report, tr, edge


@pytest.mark.parametrize("r, share", [(0.9, 1.0), (1.5, 0.5), (3.0, 0.25)])
def test_a_switch_is_verified_within_the_share_of_e_a_whose_samples_are_safe(tmp_path, r, share, line_spec):
    report, tr, edge = _verify(tmp_path, line_spec, r)
    assert tr["class"] == 1 and edge["usable"]  # Algorithm 1 from x_Hold* = 0
    (row,) = tr["from_roa"]["rows"]
    assert row[0] == share and row[2] == 8
    assert row[1] == (8 if share == 1.0 else 0)  # every sample of |x0| = r escapes when r > 1
    if share < 1:
        worst = tr["from_roa"]["worst"]
        assert worst["status"] == "unsafe" and worst["violated"] == "wall"
    run = report["sequence"]["runs"]["graph"]
    assert run["safe"] and [s["to"] for s in run["switches"]][-1] == "Go"  # x = x_Hold* lies within any share


def test_a_switch_unsafe_from_every_share_makes_the_edge_unusable(tmp_path, line_spec):
    """R = 5: |x0| = 5, 2.5 and 1.25 all escape; the edge stays in the graph (Algorithm 1) but the
    planner and the executor do not take it."""
    report, tr, edge = _verify(tmp_path, line_spec, 5.0)
    assert tr["class"] == 1 and tr["from_roa"]["rows"][0][0] == 0.0
    assert edge["usable"] is False and "E_Hold" in edge["unusable_reason"]
    assert report["lookup_table"]["next"]["Hold"]["Go"] in (None, "Hold")
    run = report["sequence"]["runs"]["graph"]
    assert "Go" not in [s["to"] for s in run["switches"]]


def test_without_the_check_the_rows_carry_no_share(tmp_path, line_spec):
    _, tr, edge = _verify(tmp_path, line_spec, 5.0, samples=None)  # an analytic system: off unless asked
    assert "from_roa" not in tr and edge["usable"]


def test_the_executor_switches_only_within_the_rows_share():
    plan = ExecutorPlan("A", ((0.0, "B"),), {"A": {"B": "B"}}, {("A", "B"): ([0.0], [0.0], [0.5])})
    r = 2.0
    assert plan.admits("A", "B", 0.0, 1e-9, margin=r - 0.9, radius=r)  # ||x - x*|| = 0.9 <= 0.5 r
    assert not plan.admits("A", "B", 0.0, 1e-9, margin=r - 1.1, radius=r)
    full = ExecutorPlan("A", (), {}, {("A", "B"): ([0.0], [0.0], [1.0])})
    assert full.admits("A", "B", 0.0, 1e-9, margin=0.0, radius=r)  # share 1: anywhere in E_A
    assert not full.admits("A", "B", 0.0, 1e-9, margin=-1e-6, radius=r)  # but not outside it
    refused = ExecutorPlan("A", (), {}, {("A", "B"): ([0.0], [None], [0.0])})
    assert not refused.admits("A", "B", 0.0, 1e-9, margin=r, radius=r)


def test_only_the_rows_the_sequences_rule_takes_are_checked(tmp_path):
    """The pendulum with `switch: margin` and 4 samples: a row the margin rule does not take on the
    unchecked grid is refused unchecked ([0, 0, 0]); every other verified row is checked; the graph
    run leaves a primitive only through checked rows with a share above 0."""
    from mpgspec.compile.contacts import grid_clock
    from mpgspec.graph.transition import switch_clocks

    report = _pendulum_by_margin(tmp_path)
    checked = skipped = 0
    for t in report["transitions"]:
        fr = t.get("from_roa")
        if fr is None:
            continue
        plain = type("Row", (), {"best_t_B": t["best_t_B"], "row_margins": t.get("row_margins") or []})
        taken = switch_clocks(plain, "margin")
        for row, tb, tk in zip(fr["rows"], t["best_t_B"], taken):
            if tb is None or row is None:
                continue
            if tk is None:
                assert row == [0.0, 0, 0]
                skipped += 1
            else:
                assert row[2] == 4 and row[0] in (0.0, 0.25, 0.5, 1.0)
                checked += 1
    assert checked and skipped
    prims = {p["name"]: p for p in report["primitives"]}
    trs = {(t["from"], t["to"]): t for t in report["transitions"]}
    since = None
    for s in report["sequence"]["runs"]["graph"]["switches"]:
        a = s.get("from")
        if a is not None and s["reason"].startswith("towards") and prims[a]["class"] != "transient":
            t = trs[(a, s["to"])]
            c = 0.0 if prims[a]["class"] == "fixed" else grid_clock(since[1] + s["t"] - since[0], prims[a]["period"])
            i = min(range(len(t["t_A"])), key=lambda k: abs(t["t_A"][k] - c))
            assert t["from_roa"]["rows"][i][0] > 0 and t["from_roa"]["rows"][i][2] == 4
        since = (s["t"], s["clock"])


def test_a_primitive_may_be_checked_from_more_samples_than_the_project(tmp_path, line_spec):
    """roa.boundary_samples of the source primitive overrides the project's oracle.from_roa for the rows out
    of it (the rows record the samples drawn), and the checks' count goes into the memo keys of the runs."""
    path = tmp_path / "project.yaml"
    text = line_spec("escape", 100, [("Hold", "-4*x", "16 - x^2", 0.9), ("Go", "-2*x + x^3", "16 - x^2", 0.2)],
                     TAIL.format(extra=", from_roa: 4"))
    path.write_text(text.replace("    roa: {radius: 0.9}\n", "    roa: {radius: 0.9, boundary_samples: 12}\n", 1))
    (p,) = api.verify([path], out_dir=None, overrides={"jit": False}).projects
    assert not p.errors, p.errors
    rows = {(t["from"], t["to"]): t["from_roa"]["rows"] for t in p.report["transitions"] if "from_roa" in t}
    assert rows[("Hold", "Go")][0] == [1.0, 12, 12]  # from Hold: its own 12
    assert all(r[2] == 4 for r in rows.get(("Go", "Hold"), []) if r)  # from Go: the project's 4
    from mpgspec.robust.from_roa import from_roa_samples
    from mpgspec.spec.loader import load_project

    assert from_roa_samples(load_project(path)) == {"Hold": 12, "Go": 4}


def test_robust_cells_are_switches_the_executor_makes(tmp_path):
    """The pendulum with `switch: margin` and checks from E_A's boundary: every robust cell of a nominal
    edge is a t_A row the graph executor switches through (the rule takes it and its share is above 0),
    where the edge has such rows; the rows are spread as before (cell_rows) over those alone."""
    import numpy as np

    from mpgspec.graph.transition import executor_clocks
    from mpgspec.robust.cells import cell_rows

    report = _pendulum_by_margin(tmp_path)
    prims = {p["name"]: p for p in report["primitives"]}
    trs = {(t["from"], t["to"]): t for t in report["transitions"]}
    narrowed = 0
    for e in report["robust"]["edges"]:
        t = trs[(e["from"], e["to"])]
        plain = type("Row", (), {"best_t_B": t["best_t_B"], "row_margins": t.get("row_margins") or [],
                                 "row_from_roa": (t.get("from_roa") or {}).get("rows") or []})
        taken = executor_clocks(plain, prims[e["from"]]["class"] == "transient", "margin")
        verified = [i for i, b in enumerate(t["best_t_B"]) if b is not None]
        usable = [i for i in verified if taken[i] is not None]
        assert set(e["cells"]["row"]) <= set(usable or verified), (e["from"], e["to"])
        narrowed += len(usable) < len(verified)
    assert narrowed  # the rule and the checks leave out some verified rows, so the choice matters here
    tr = type("Tr", (), {"available": np.array([True] * 12)})
    taken = [None if i % 3 else 0.1 for i in range(12)]
    assert cell_rows(tr, 2, taken) == [0, 9] and cell_rows(tr, 4, [None] * 12) == [0, 4, 7, 11]


def test_the_robust_graph_switches_where_the_report_says(tmp_path):
    """The robust graph verify runs the sequence through keeps each row's margin and its check from
    E_A's boundary: the graph executor reads the same rows, switch-in clocks and shares from it as from
    the robust graph `simulate --uncertain` and `plan --robust` read back from the report."""
    from mpgspec.robust.plan import report_lookup_table, robust_report_graph
    from mpgspec.spec.loader import load_project

    report = _pendulum_by_margin(tmp_path)
    spec = load_project(tmp_path / "pendulum" / "project.yaml")
    cp, vg = api.build(spec, api.settings_for(spec))
    built = api.robust_stage(cp, vg).graph
    read = robust_report_graph(report)
    table = report_lookup_table(read)
    seq = spec.project.sequence
    mine, theirs = ExecutorPlan.of(built, table, seq, cp.prims), ExecutorPlan.of(read, table, seq, cp.prims)
    assert mine.edges == theirs.edges
    shares = [s for _, _, sh in mine.edges.values() for s in sh]
    assert any(s == 0 for s in shares)  # some rows were refused by the check from E_A's boundary


def _pendulum_by_margin(tmp_path) -> dict:
    """The report of specs/pendulum with `switch: margin` and 4 samples of E_A's boundary a row."""
    import shutil

    proj = tmp_path / "pendulum"
    shutil.copytree(Path(__file__).resolve().parents[2] / "specs" / "pendulum", proj)
    spec = proj / "project.yaml"
    text = spec.read_text().replace("  duration: 40\n", "  duration: 40\n  switch: margin\n")
    spec.write_text(text.replace("  horizon: 6.0\n", "  horizon: 6.0\n  from_roa: 4\n"))
    return api.verify(proj)["pendulum"].report
