"""`mpgspec diff OLD NEW`: two verifies that differ by one edited gain report exactly the edges and
assertions that changed; a regression exits 1, none 0, an unusable report 2; a report edited or
written elsewhere is compared with a note."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from mpgspec.cli import main

TINY_DIR = Path(__file__).resolve().parent.parent / "fixtures" / "cli_tiny"


def run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def two_reports(tmp_path_factory) -> tuple[Path, Path]:
    """The tiny project verified as it is and with Mid's gain kp edited from 2 to 0.3."""
    base = tmp_path_factory.mktemp("diff")
    folders = []
    for tag, kp in (("old", "2"), ("new", "0.3")):
        proj = base / tag / "tiny"
        shutil.copytree(TINY_DIR, proj)
        spec = proj / "project.yaml"
        text = spec.read_text()
        assert text.count("kp: [2]") == 1
        spec.write_text(text.replace("kp: [2]", f"kp: [{kp}]"))
        out = base / tag / "reports"
        main(["verify", str(proj), "--out", str(out), "-q", "-j", "1"])
        folders.append(out / "tiny")
    return folders[0], folders[1]


def _edges(folder: Path) -> dict:
    report = json.loads((folder / "report.json").read_text())
    return {(e["from"], e["to"]): e["class"] for e in report["edges"]}


def test_an_edited_gain_reports_exactly_the_edges_that_changed(capsys, two_reports):
    old, new = two_reports
    eo, en = _edges(old), _edges(new)
    assert eo != en  # the edit changes the graph, else the test proves nothing
    rc, out, _ = run(capsys, "diff", old, new, "--format", "json")
    d = json.loads(out)
    assert {(e["from"], e["to"]) for e in d["edges_lost"]} == set(eo) - set(en)
    assert {(e["from"], e["to"]) for e in d["edges_gained"]} == set(en) - set(eo)
    assert {(e["from"], e["to"]) for e in d["class_changed"]} == {p for p in set(eo) & set(en) if eo[p] != en[p]}
    assert d["regression"] is (bool(set(eo) - set(en)) or any(eo[p] != en[p] for p in set(eo) & set(en)))
    assert rc == (1 if d["regression"] else 0)
    failed = [a["description"] for a in d["assertions_changed"] if a["old"] == "pass" and a["new"] == "fail"]
    assert "edge Left -> Mid of class 1" in failed
    # the other way round: the same edges gained, nothing lost
    rc, out, _ = run(capsys, "diff", new, old, "--format", "json")
    back = json.loads(out)
    assert {(e["from"], e["to"]) for e in back["edges_gained"]} == set(eo) - set(en)
    assert not back["edges_lost"] and not back["regression"] and rc == 0


def test_human_markdown_and_github_name_each_change(capsys, two_reports, tmp_path, monkeypatch):
    old, new = two_reports
    lost = sorted(set(_edges(old)) - set(_edges(new)))
    rc, out, _ = run(capsys, "diff", old, new)
    assert rc == 1 and "REGRESSION" in out.splitlines()[0]
    for a, b in lost:
        assert f"edge lost: {a} -> {b}" in out
    summary = tmp_path / "summary.md"
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(summary))
    rc, out, _ = run(capsys, "diff", old, new, "--format", "github")
    assert rc == 1
    for a, b in lost:
        assert f"::error title=mpgspec diff%3A edge lost::{a} -> {b}" in out
    md = summary.read_text()
    assert "| level | change | what |" in md and "edge lost" in md


def test_the_same_report_has_no_changes(capsys, two_reports):
    old, _ = two_reports
    rc, out, _ = run(capsys, "diff", old, old / "report.json")
    assert rc == 0 and "no changes" in out and "no regression" in out


def test_an_edited_report_is_compared_with_a_note(capsys, two_reports, tmp_path):
    old, new = two_reports
    edited = json.loads((new / "report.json").read_text())
    edited["edges"] = [e for e in edited["edges"] if (e["from"], e["to"]) != ("Mid", "Right")]
    p = tmp_path / "report.json"
    p.write_text(json.dumps(edited))
    rc, out, _ = run(capsys, "diff", old, p)
    assert "note:" in out and "edited" in out
    assert "edge lost: Mid -> Right" in out and rc == 1


@pytest.mark.parametrize("content, expected", [(None, "no report.json here"), ("[1]", "a JSON object"),
                                               ("{not json", "not a readable report.json")])
def test_an_unusable_report_exits_2_naming_the_file(capsys, two_reports, tmp_path, content, expected):
    old, _ = two_reports
    p = tmp_path / "report.json"
    if content is not None:
        p.write_text(content)
    rc, out, err = run(capsys, "diff", old, p)
    assert rc == 2 and str(p) in err and expected in err and "Traceback" not in err


def _without_assertions(tmp_path: Path, kp: str, extra: str = "") -> Path:
    """The tiny project with Mid's gain kp and no assertions (its own run passes), plus `extra`."""
    proj = tmp_path / "tiny"
    shutil.copytree(TINY_DIR, proj)
    spec = proj / "project.yaml"
    text = spec.read_text().replace("kp: [2]", f"kp: [{kp}]")
    spec.write_text(text[:text.index("assertions:")] + text[text.index("sequence:"):] + extra)
    return proj


def test_verify_baseline_fails_on_a_lost_edge_unless_the_spec_allows_it(capsys, two_reports, tmp_path, monkeypatch):
    old, _ = two_reports
    lost = sorted(set(_edges(old)) - set(_edges(two_reports[1])))
    assert lost
    proj = _without_assertions(tmp_path / "a", "0.3")
    rc, out, _ = run(capsys, "verify", proj, "--out", tmp_path / "a" / "out", "-q", "-j", "1",
                     "--baseline", old.parent)
    assert rc == 1
    for a, b in lost:
        assert f"FAIL  baseline: edge {a} -> {b}" in out
    monkeypatch.delenv("GITHUB_STEP_SUMMARY", raising=False)
    rc, out, _ = run(capsys, "verify", proj, "--out", tmp_path / "a" / "out", "-q", "-j", "1",
                     "--baseline", old.parent, "--format", "github")
    assert rc == 1 and "::error file=" in out and "title=mpgspec baseline::baseline: edge" in out
    allow = "baseline:\n  may_lose:\n" + "".join(f"    - {{from: {a}, to: {b}}}\n" for a, b in lost)
    proj = _without_assertions(tmp_path / "b", "0.3", allow)
    rc, out, _ = run(capsys, "verify", proj, "--out", tmp_path / "b" / "out", "-q", "-j", "1",
                     "--baseline", old.parent)
    assert rc == 0, out
    for a, b in lost:
        assert f"INFO  baseline: edge {a} -> {b}" in out and "may_lose allows" in out
    # a project the baseline folder does not hold is noted, not failed
    rc, out, _ = run(capsys, "verify", proj, "--out", tmp_path / "b" / "out", "-q", "-j", "1",
                     "--baseline", tmp_path / "empty")
    assert rc == 0 and "NOTE  baseline: no " in out


def test_odd_counts_and_assertions_do_not_break_the_comparison(capsys, two_reports, tmp_path):
    old, new = two_reports
    odd = json.loads((new / "report.json").read_text())
    for t in odd["transitions"]:
        t["counts"] = ["not", "an", "object"]
    odd["assertions"] = 5
    p = tmp_path / "report.json"
    p.write_text(json.dumps(odd))
    rc, out, err = run(capsys, "diff", old, p)
    assert rc == 1 and "edge lost" in out and "internal error" not in err
    odd["project"] = [1]
    p.write_text(json.dumps(odd))
    rc, out, err = run(capsys, "diff", old, p)
    assert rc == 2 and "project" in err and "internal error" not in err


def test_verify_baseline_reads_a_spec_with_files_in_an_allowed_folder(capsys, two_reports, tmp_path):
    """The baseline check takes the spec as the run did: a primitive file in an --allow-path folder
    is no error, in this process (-j 1) and with projects verified side by side in other processes."""
    old, _ = two_reports
    shared = tmp_path / "shared"
    shared.mkdir()
    (shared / "mid.yaml").write_text("name: Mid\nclass: fixed\nsetpoint: {expr: [0.6]}\n"
                                     "controller: {type: pd, outputs: [x], kp: [2], kd: [0]}\nroa: {radius: 0.05}\n")
    projects = []
    for tag in ("a", "b"):
        proj = _without_assertions(tmp_path / tag, "2")
        spec = proj / "project.yaml"
        text = spec.read_text()
        block = text[text.index("  - name: Mid"):text.index("  - name: Right")]
        text = text.replace(block, f"  - {shared / 'mid.yaml'}\n")
        spec.write_text(text if tag == "a" else text.replace("project: tiny", "project: tiny_b", 1))
        projects.append(proj)
    for jobs, paths in (("1", projects[:1]), ("2", projects)):
        rc, out, err = run(capsys, "verify", *paths, "--out", tmp_path / "out", "-q", "-j", jobs,
                           "--allow-path", shared, "--baseline", old.parent)
        assert rc == 0 and "MPG305" not in out + err, out + err
    assert "NOTE  baseline: no " in out  # tiny_b has no baseline report: noted only


def test_an_unwritable_step_summary_is_said_not_an_internal_error(capsys, two_reports, tmp_path, monkeypatch):
    old, new = two_reports
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(tmp_path / "no_such_folder" / "summary.md"))
    rc, out, err = run(capsys, "diff", old, new, "--format", "github")
    assert rc == 1 and "::error title=mpgspec diff%3A edge lost::" in out
    assert "cannot write the step summary" in err and "internal error" not in err


def test_names_cannot_break_the_markdown_table_or_the_workflow_commands(monkeypatch):
    """A '|' in a name or description is escaped in markdown, a line break in a message cannot start
    another workflow command, and ':' or ',' in a title is escaped as GitHub reads properties."""
    from mpgspec.report import diff as df

    monkeypatch.setattr(df, "_lines", lambda d: [("error", "edge lost", "A|B -> C\n::error::injected")])
    d = {"old": {"project": "p|q", "status": "PASS", "edges": 2}, "new": {"project": "p|q", "status": "FAIL", "edges": 1},
         "regression": True}
    md = df.format_diff(d, "markdown")
    row = [ln for ln in md.splitlines() if ln.startswith("| error")]
    assert row == ["| error | edge lost | A\\|B -> C ::error::injected |"]
    assert row[0].count("|") - row[0].count("\\|") == 4  # three cells, whatever the names hold
    gh = df.format_diff(d, "github").splitlines()
    assert gh[0] == "::error title=mpgspec diff%3A edge lost::A|B -> C%0A::error::injected"
    assert not any(ln.startswith("::error::") for ln in gh)
