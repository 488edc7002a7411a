"""The HTML report renders from the JSON alone, shows every section and escapes all text."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpgspec.report.html import render_html

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"
EVIL = "<script>alert(1)</script>"


@pytest.fixture
def sample_text() -> str:
    return SAMPLE.read_text(encoding="utf-8")


def test_renders_sections(sample_text):
    report = json.loads(sample_text)
    html = render_html(report)
    assert html.startswith("<!DOCTYPE html>")
    assert "<svg" in html
    for p in report["primitives"]:
        assert p["name"] in html
    for label in ("certified", "simulated", "empirical"):
        assert label in html
    assert "Every edge here is" in html
    for s in ("□", "○", "◇", "Lookup table", "naive execution", "graph execution", "oracle_calls"):
        assert s in html
    assert html.count("<details") >= len(report["transitions"])


def _own_scripts() -> int:
    """The inline scripts of the report template (tables, graph): the only scripts a page may hold."""
    from mpgspec.report.html import _env

    return _env().loader.get_source(_env(), "report.html.j2")[0].count("<script")


def test_self_contained(sample_text):
    html = render_html(json.loads(sample_text))
    assert "<link" not in html and "src=" not in html and "<script src" not in html
    assert html.count("<script") == _own_scripts() == 2


def test_escapes_primitive_names(sample_text):
    report = json.loads(sample_text.replace('"Hang"', json.dumps(EVIL)).replace("Hang ->", f"{EVIL} ->"))
    html = render_html(report)
    assert html.count("<script") == _own_scripts() and "<script>alert" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_without_sequence_or_failures(sample_text):
    report = json.loads(sample_text)
    report["sequence"], report["failures"] = None, []
    report["failures"] = [{**json.loads(sample_text)["failures"][0], "series": {"error": "diverged"}}]
    html = render_html(report)
    assert "diverged" in html and 'id="sequence"' not in html


def test_a_cross_check_disagreement_is_a_warning_on_the_first_screen(sample_text):
    report = json.loads(sample_text)
    n = sum(c["status"] == "warn" for c in report["assumptions"])
    report["crosscheck"] = {"simulator": "mujoco", "agree": False, "runs": {
        "naive": {"mode": "naive", "agree": True, "mujoco": {"safe": False}, "mpgspec": {"safe": False}},
        "graph": {"mode": "graph", "agree": False, "mpgspec": {"safe": True, "first_violation": None},
                  "mujoco": {"safe": False, "first_violation": {"t": 8.427, "primitive": "Walk", "h": "cone[RR]",
                                                                 "value": -4.857}}}}}
    from mpgspec.report.html import _disagreements
    (w,) = _disagreements(report)
    assert w["status"] == "warn" and w["href"] == "#crosscheck"
    assert w["text"] == ("MuJoCo finds the graph run unsafe where mpgspec finds it safe: cone[RR] of Walk at "
                         "t = 8.427 s, -4.857")
    report.pop("crosscheck")
    report["crosscheck"] = {"simulator": "mujoco", "agree": False, "runs": {"graph": {
        "agree": False, "mpgspec": {"safe": True}, "mujoco": {"safe": False}}}}
    from mpgspec.report.html import Anchors, _summary
    summary = _summary(report, Anchors(report))
    assert summary["label"] == f"PASS with {n + 1} warnings" and summary["problems"][0]["what"] == "cross-check of the graph run"


def test_summary_names_every_warning_and_links_it(sample_text):
    report = json.loads(sample_text)
    html = render_html(report)
    warns = [c for c in report["assumptions"] if c["status"] == "warn"]
    assert warns and f"PASS with {len(warns)} warning" in html
    k = report["assumptions"].index(warns[0])
    assert f'href="#assumption-{k}"' in html and f'id="assumption-{k}"' in html


def test_a_failed_assertion_links_to_its_grid(sample_text):
    report = json.loads(sample_text)
    a = next(a for a in report["assertions"] if a["kind"] == "edge")
    a["status"], report["status"] = "fail", "fail"
    html = render_html(report)
    names = [p["name"] for p in report["primitives"]]
    src, dst = (n for n in a["description"].removeprefix("edge ").split(" of class")[0].split(" -> "))
    grid = f"grid-{names.index(src)}-{names.index(dst)}"
    assert f'<a href="#{grid}">' in html and f'<details id="{grid}">' in html
    assert "FAIL" in html.split('id="summary"')[1].split("</section>")[0]


def test_grids_and_switches_are_folded_and_tables_scroll(sample_text):
    html = render_html(json.loads(sample_text))
    grids = html.split('id="grids"')[1].split("</section>")[0]
    assert "<details" in grids and "<details open" not in grids and "details open" not in html
    assert html.count('<div class="scroll">') >= 5 and "@media (max-width" in html and "@media print" in html
    assert "position: sticky" in html


def test_unusable_edges_are_grey_and_explained(sample_text, monkeypatch):
    report = json.loads(sample_text)
    bad = [e for e in report["edges"] if e.get("usable") is False]
    assert bad
    monkeypatch.setenv("MPGSPEC_GRAPHVIZ", "0")  # the built-in layout
    html = render_html(report)
    assert "built-in layout" in html and "#9a9a9a" in html
    assert "not usable by the planner" in html and bad[0]["unusable_reason"] in html


def test_graphviz_layout_when_dot_is_installed(sample_text):
    import shutil

    if shutil.which("dot") is None:
        pytest.skip("Graphviz dot is not installed")
    report = json.loads(sample_text)
    html = render_html(report)
    assert "Layout: Graphviz dot" in html and 'class="mpg-graph"' in html
    c2 = next(e for e in report["edges"] if e["class"] == 2)
    assert "t_A ∈ [" in html and "safe only from t_A in" in html  # Class 2 windows on label and tooltip
    assert c2["from"] in html


def test_graphviz_failure_falls_back(sample_text, monkeypatch):
    import subprocess

    def boom(*a, **k):
        raise subprocess.TimeoutExpired("dot", 10)

    monkeypatch.setattr(subprocess, "run", boom)
    assert "built-in layout" in render_html(json.loads(sample_text))


def test_floquet_multipliers_are_tabulated(sample_text):
    report = json.loads(sample_text)
    p = next(p for p in report["primitives"] if p["roa_method"] == "floquet")
    p["roa_evidence"]["neutral"] = [{"name": "phase", "multiplier": 1.0}]
    html = render_html(report)
    assert f"Floquet multipliers of {p['name']}" in html and "Neutral directions: phase" in html


def test_what_bounds_a_tube_is_shown_beside_its_radius(sample_text):
    """A gait's E column names the safety functions its failing starts left C at and where against the
    contact changes (the floquet verifier's bounded_by); a long sizing message folds away; names are escaped."""
    report = json.loads(sample_text)
    p = next(p for p in report["primitives"] if p["roa_method"] == "floquet")
    exits = [{"t": 0.179, "h": "above_ground[FR_foot]", "value": -2.5e-4, "from_change_s": -0.001},
             {"t": 0.358, "h": EVIL, "value": -1e-4, "from_change_s": -0.002}]
    p["roa_evidence"]["tube"]["bounded_by"] = {"r": 0.0078125, "failed": 2, "located": 2, "exits": exits,
                                               "functions": {}, "not_in_c_within_a_period": 0, "text": "t"}
    p["roa_message"] = "m" * 200
    html = render_html(report)
    assert "starts leave C from r = 0.007812: <code>above_ground[FR_foot]</code>" in html
    assert "1-2 ms before a contact change" in html and EVIL not in html
    assert "<summary>how it was sized</summary>" + "m" * 200 in html


def test_sequence_runs_share_their_y_axes(sample_text):
    from mpgspec.report.compact import run_rows
    from mpgspec.report.svg import run_limits

    seq = json.loads(sample_text)["sequence"]
    runs = [run_rows(r) for r in seq["runs"].values()]
    both = run_limits(runs, len(seq["state_names"]))
    for r in runs:
        one = run_limits([r], len(seq["state_names"]))
        assert both[0][0] <= one[0][0] and both[0][1] >= one[0][1]


def _robust_sequence(safe: dict[str, int], runs: int = 8) -> dict:
    def mode(n, switches):
        return {"safe_fraction": n / runs, "safe_runs": n, "runs": runs, "final": ["Hang"] * runs,
                "reached_goal": n // 2, "first_violation": [] if n == runs else [{"t": 2.01, "primitive": "Balance"}], "switches": switches}

    return {"runs": runs, "seed": 3, "disturbance_hold_s": 0.5, "modes": {
        "naive": mode(safe["naive"], [{"from": "Hang", "to": "Balance", "count": runs}]),
        "graph": mode(safe["graph"], [{"from": "Balance", "to": "SwingUp", "count": 5},
                                      {"from": "Hang", "to": "Swing(1)", "count": runs}]),
        "robust_graph": mode(safe["robust_graph"], [{"from": "Hang", "to": "Swing(1)", "count": runs}])}}


def test_robust_edges_in_summary_legend_and_sequence_fractions(sample_text):
    report = json.loads(sample_text)
    report["robust"]["sequence"] = _robust_sequence({"naive": 0, "graph": 6, "robust_graph": 8})
    html = render_html(report)
    assert "<b>19</b> robust edges" in html and "nominal only: Balance -&gt; SwingUp" in html
    assert ("disturbed sequence safe: naive 0/8, nominal graph 6/8 (3 in every goal), robust graph 8/8 (4 in every "
            "goal)") in html
    lost = [f"A{k} -> B{k}" for k in range(23)]  # many: counted on the first screen, listed under robust
    report["robust"]["summary"] = {**report["robust"]["summary"], "robust_edges": 1, "nominal_only": lost}
    many = render_html(report)
    card = many[many.index('id="summary"'):many.index('id="graph"')]
    assert "23 nominal only (listed under robust)" in card and "A7 -&gt; B7" not in card
    assert "A7 -&gt; B7" in many[many.index('id="robust"'):]
    assert 'class="key nominal"' in html  # the graph legend
    table = html[html.index('id="robust-sequence"'):]
    table = table[: table.index("</table>")]
    rows = table.split("<tr")[2:]
    assert len(rows) == 3
    assert "naive" in rows[0] and "0 / 8" in rows[0] and "0.0 %" in rows[0] and "t = 2.01 s in Balance" in rows[0]
    assert "nominal graph" in rows[1] and "6 / 8" in rows[1] and "75.0 %" in rows[1]
    assert "Balance → SwingUp ×5" in rows[1] and "Hang → Swing(1)" not in rows[1]  # only nominal-only edges
    assert "robust graph" in rows[2] and "8 / 8" in rows[2] and "100.0 %" in rows[2] and "none" in rows[2]
    assert 'class="fail"' in rows[1] and 'class="pass"' in rows[2]


def test_no_robust_graph_no_robust_legend(sample_text):
    report = json.loads(sample_text)
    report["robust"] = None
    html = render_html(report)
    assert 'class="key nominal"' not in html and "robust edges" not in html and 'id="robust"' not in html


def test_warnings_are_counted_alike_everywhere(sample_text):
    from mpgspec.pipeline.results import ProjectResult
    from mpgspec.progress import summary
    from mpgspec.report.findings import warning_count
    report = json.loads(sample_text)
    n = sum(c["status"] == "warn" for c in report["assumptions"])
    report["crosscheck"] = {"simulator": "mujoco", "runs": {"graph": {"agree": False, "mpgspec": {"safe": True},
                                                                      "mujoco": {"safe": False}}}}
    p = ProjectResult(path=Path("x"), name="x", status="pass", report=report)
    assert warning_count(report) == p.warnings == n + 1
    assert f"; {n + 1} warnings;" in summary([p], 1.0) and f"with {n + 1} warnings" in p._repr_html_()


def test_the_sequence_says_how_its_switches_are_chosen(sample_text):
    """The switching rule, the torque reserve and the kept margins of the graph run are stated where the runs are."""
    r = json.loads(sample_text)
    plain = render_html(r)
    assert "at the first verified t_A it meets." in plain and "of each input's bound" not in plain
    assert "cells that keep" not in plain
    r["lookup_table"].update(switch="margin", reserve=0.8)
    html = render_html(r)
    assert "at least 0.8 of its edge's best, and only through cells whose law asks at most 0.8 of each input's bound." \
        in html
    r["lookup_table"]["keep"] = {"friction_cone": 5.0, "q_max": 0.1}
    assert ("of each input's bound, and only through cells that keep friction_cone at least 5.0, q_max at least 0.1."
            in render_html(r))
