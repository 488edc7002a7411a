"""plan and simulate answer from what verify wrote while it matches the specs; GitHub annotations
carry the spec line; --format json holds the whole result; python -m mpgspec."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mpgspec.cli import main

TINY_DIR = Path(__file__).parent / "fixtures" / "cli_tiny"


def run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture()
def verified(tmp_path, capsys) -> tuple[Path, Path]:
    """A copy of the tiny project and the report folder verify wrote for it."""
    proj = tmp_path / "tiny"
    shutil.copytree(TINY_DIR, proj)
    out = tmp_path / "reports"
    rc, _, err = run(capsys, "verify", proj, "--out", out, "-q")
    assert rc == 0, err
    return proj, out


def test_plan_reads_the_verified_report(capsys, verified):
    proj, out = verified
    t0 = time.perf_counter()
    rc, text, err = run(capsys, "plan", proj, "--from", "Left", "--to", "Right", "--out", out)
    assert time.perf_counter() - t0 < 1.0
    assert rc == 0 and "rebuild" not in err
    lines = text.splitlines()
    assert lines[0].startswith("Left -> Mid -> Right")
    assert lines[1].startswith("  Left -> Mid: class 1") and "switch at any t_A" in lines[1]
    rc, text, _ = run(capsys, "plan", proj, "--from", "Left", "--to", "Right", "--out", out, "--format", "json")
    doc = json.loads(text)
    assert doc["source"].endswith("report.json") and [h["class"] for h in doc["hops"]] == [1, 1]


def test_plan_says_when_the_report_is_stale(capsys, verified):
    proj, out = verified
    f = proj / "project.yaml"
    f.write_text(f.read_text() + "\n# edited\n")
    rc, text, err = run(capsys, "plan", proj, "--from", "Left", "--to", "Right", "--out", out)
    assert rc == 0 and "is stale" in err and "rebuilding" in err
    assert text.startswith("Left -> Mid -> Right")


def test_simulate_from_the_report_matches_expectations(capsys, verified):
    proj, out = verified
    rc, text, err = run(capsys, "simulate", proj, "--out", out)
    assert rc == 0 and "rebuild" not in err
    assert "naive: UNSAFE; ends in Right (as expected)" in text and "graph: safe; ends in Right (as expected)" in text
    f = proj / "project.yaml"  # now the project expects the naive run to be safe
    f.write_text(f.read_text().replace("  - simulation_safe: naive\n    expect: false\n", "  - simulation_safe: naive\n"))
    rc, text, _ = run(capsys, "simulate", proj, "--out", out, "--mode", "naive", "--format", "json")
    doc = json.loads(text)
    assert rc == 1 and doc["naive"]["as_expected"] is False and doc["naive"]["expected_safe"] is True


@pytest.fixture()
def failing(tmp_path) -> Path:
    proj = tmp_path / "tiny"
    shutil.copytree(TINY_DIR, proj)
    f = proj / "project.yaml"
    f.write_text(f.read_text().replace("assertions:\n", "assertions:\n  - edge: {from: Left, to: Right}\n", 1))
    return f


def test_github_annotations_carry_the_line_and_a_step_summary(capsys, failing, tmp_path, monkeypatch):
    summary = tmp_path / "summary.md"
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(summary))
    rc, out, _ = run(capsys, "verify", failing, "--no-write", "-q", "--format", "github")
    assert rc == 1
    line = next(i for i, t in enumerate(failing.read_text().splitlines(), 1) if "edge: {from: Left, to: Right}" in t)
    errors = [t for t in out.splitlines() if t.startswith("::error")]
    assert errors and f"line={line}," in errors[0] and "line=0" not in out
    assert "::error file=" in errors[0] and "project.yaml" in errors[0]
    table = summary.read_text()
    assert "| project | result |" in table and "| tiny | FAIL |" in table
    row = next(ln for ln in table.splitlines() if ln.startswith("| tiny |"))
    assert row.rstrip().endswith("| not written |")  # --no-write: no report to link


def test_github_warnings_and_escaping(capsys, monkeypatch):
    from mpgspec import cli

    monkeypatch.delenv("GITHUB_STEP_SUMMARY", raising=False)
    line = cli._annotation("warning", "50% done\nnext", {"file": "a,b.yaml", "line": 3, "column": 2}, "t: x")
    assert line == "::warning file=a%2Cb.yaml,line=3,col=2,title=t%3A x::50%25 done%0Anext"
    assert "line=" not in cli._annotation("error", "m", None, file="p.yaml")


def test_json_format_holds_the_whole_result(capsys, tmp_path):
    proj = tmp_path / "tiny"
    shutil.copytree(TINY_DIR, proj)
    rc, out, _ = run(capsys, "verify", proj, "--no-write", "-q", "--format", "json")
    doc = json.loads(out)
    p = doc["projects"][0]
    assert rc == 0 and p["report"]["edges"] and p["report"]["schema_version"].startswith("2.")


def test_python_dash_m():
    ok = subprocess.run([sys.executable, "-m", "mpgspec", "--version"], capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0 and ok.stdout.startswith("mpgspec ")


def test_every_option_has_help():
    from mpgspec.cli import parser

    ap = parser()
    subs = next(a for a in ap._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, sp in subs.choices.items():
        for a in sp._actions:
            if a.dest != "help":
                assert a.help, f"{name} {a.option_strings or a.dest} has no help text"
        assert "examples:" in (sp.epilog or ""), name


def test_every_spec_error_is_reported_with_did_you_mean(capsys, tmp_path):
    proj = tmp_path / "tiny"
    shutil.copytree(TINY_DIR, proj)
    f = proj / "project.yaml"
    f.write_text(f.read_text().replace("kd: [0]", "kdd: [0]").replace("horizon: 3.0", "horizn: 3.0"))
    rc, _, err = run(capsys, "verify", proj, "--no-write", "-q")
    assert rc == 2
    assert "controller.kdd: unknown key; found 'kdd' (hint: did you mean 'kd'?)" in err
    assert "oracle.horizn: unknown key; found 'horizn' (hint: did you mean 'horizon'?)" in err
