"""The notebook API: verify writes nothing by default; the result's graph is the planner's, plan()
and simulate() answer from it; load_report reads back what verify wrote; HTML for notebooks."""
from __future__ import annotations

from pathlib import Path

import networkx as nx
import pytest

from mpgspec import api

TINY = Path(__file__).parent / "fixtures" / "cli_tiny"


@pytest.fixture(scope="module")
def tiny():
    return api.verify(TINY)


def test_verify_writes_nothing_by_default(tiny, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    api.verify(TINY)
    assert not (tmp_path / "reports").exists()
    assert tiny["tiny"] is tiny.projects[0] and tiny.exit_code == 0


def test_graph_is_the_planners(tiny):
    p = tiny["tiny"]
    G = p.graph
    assert isinstance(G, nx.DiGraph) and all("class" in d and "cls" not in d for *_, d in G.edges(data=True))
    plan = p.plan("Left", "Right", weight="hops")
    assert plan["path"] == nx.shortest_path(G, "Left", "Right", weight="hops") == ["Left", "Mid", "Right"]
    assert [h["class"] for h in plan["hops"]] == [1, 1] and plan["cost"] == 2
    with pytest.raises(api.UsageError):
        p.plan("Left", "Nowhere")


def test_simulate_matches_the_report(tiny):
    p = tiny["tiny"]
    run = p.simulate("graph")
    stored = p.report["sequence"]["runs"]["graph"]
    assert run.safe == stored["safe"] and [s["to"] for s in run.switches] == [s["to"] for s in stored["switches"]]
    assert p.simulate(mode="naive").safe is False


def test_load_report_round_trip(tmp_path):
    res = api.verify(TINY, out_dir=tmp_path)
    back = api.load_report(tmp_path / "tiny")
    assert back.name == "tiny" and back.status == res["tiny"].status and back.mpg is None
    assert back.plan("Left", "Right")["path"] == res["tiny"].plan("Left", "Right")["path"]
    assert back.simulate("graph").safe
    html = back._repr_html_()
    assert "<table>" in html and "tiny" in html and "report.html" in html


def test_all_names_exist():
    assert all(hasattr(api, n) for n in api.__all__)


def test_reprs_are_one_line(tiny):
    text = repr(tiny)
    assert "\n" not in text and len(text) < 300 and "ProjectResult(tiny: pass" in text and "edges" in text


def test_plan_on_the_robust_graph(tiny, example):
    with pytest.raises(api.UsageError, match="no robust graph"):
        tiny["tiny"].plan("Left", "Right", robust=True)
    p = example("pendulum").projects[0]  # its assertion: robust plan Hang => Balance through the swings
    assert p.plan("Hang", "Balance", robust=True)["path"] == ["Hang", "Swing(1)", "Swing(2.6)", "Balance"]
    assert p.plan("Hang", "Balance")["path"] == ["Hang", "Swing(1)", "Swing(2.6)", "Balance"]


def test_a_report_verified_from_relative_paths_simulates_from_any_folder(tmp_path, monkeypatch):
    import shutil

    repo = tmp_path / "repo"
    shutil.copytree(TINY, repo / "specs" / "tiny")
    monkeypatch.chdir(repo)
    api.verify("specs/tiny", out_dir="reports")
    assert (repo / "reports" / "index.html").is_file()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    back = api.load_report(repo / "reports" / "tiny")
    assert back.path == repo / "specs" / "tiny" / "project.yaml"
    assert back.simulate("graph").safe and back.plan("Left", "Right")["path"] == ["Left", "Mid", "Right"]


def test_verify_reuses_stored_results_like_the_command(tmp_path):
    first = api.verify(TINY)["tiny"].report["timing"]
    again = api.verify(TINY)["tiny"].report["timing"]
    assert again["oracle_calls"] == first["oracle_calls"] and again.get("cache_hits") == again["oracle_calls"]
    fresh = api.verify(TINY, cache=False)["tiny"].report["timing"]
    assert not fresh.get("cache_hits")


def test_the_notebook_view_shows_the_verdict_the_graph_and_the_warnings(tmp_path):
    import shutil

    proj = tmp_path / "tiny"
    shutil.copytree(TINY, proj)
    spec = proj / "project.yaml"
    drift = ("  - name: Drift\n    class: fixed\n    setpoint: {expr: [0.5]}\n"
             "    controller: {type: pd, outputs: [x], kp: [0], kd: [0]}\n    roa: {radius: 0.05}\n")
    spec.write_text(spec.read_text().replace("primitives:\n", "primitives:\n" + drift, 1))
    html = api.verify(proj)["tiny"]._repr_html_()
    assert "<b>FAIL</b>" in html and "<svg" in html and "edges</summary>" in html
    assert "WARN assumption local_stability of Drift" in html
