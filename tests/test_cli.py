"""Command line: exit codes (0 pass, 1 a check failed, 2 spec/usage error) and every sub-command.

Runs on the tiny fixture projects in tests/fixtures/ (scalar integrator, three fixed primitives).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mpgspec.cli import main

FIXTURES = Path(__file__).parent / "fixtures"
TINY = FIXTURES / "cli_tiny" / "project.yaml"
BROKEN = FIXTURES / "cli_spec_error" / "project.yaml"


def run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture()
def failing_project(tmp_path) -> Path:
    """The tiny project plus one assertion that cannot hold (Right forbids x < 0.4, Left sits at 0)."""
    text = TINY.read_text()
    assert "assertions:\n" in text
    text = text.replace("assertions:\n", "assertions:\n  - edge: {from: Left, to: Right}\n", 1)
    path = tmp_path / "project.yaml"
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- verify: exit codes
def test_verify_passing_project_exits_0(capsys):
    rc, out, err = run(capsys, "verify", TINY, "--no-write", "-q")
    assert rc == 0, out + err
    assert "PASS tiny: 3 primitives" in out
    assert "Left -> Mid -> Right" in out
    assert "FAIL" not in out
    assert "[tiny]" not in err  # -q: no progress lines


def test_verify_failing_assertion_exits_1(capsys, failing_project):
    rc, out, err = run(capsys, "verify", failing_project, "--no-write", "-q")
    assert rc == 1, out + err
    assert "FAIL tiny" in out
    assert "FAIL  edge Left -> Right: no transition was verified" in out
    assert "Traceback" not in out + err


def test_verify_spec_error_exits_2(capsys):
    rc, out, err = run(capsys, "verify", BROKEN, "--no-write", "-q")
    assert rc == 2
    assert f"ERROR {BROKEN}" in out
    assert f"{BROKEN}:17:" in err and "MPG202" in err and "unknown function 'saturate'" in err
    assert "Traceback" not in out + err


def test_verify_missing_path_exits_2(capsys, tmp_path):
    rc, out, err = run(capsys, "verify", tmp_path / "nowhere", "--no-write", "-q")
    assert rc == 2
    assert "MPG001" in err and "no such file or folder" in err
    assert "Traceback" not in out + err


def test_verify_folder_without_projects_exits_2(capsys, tmp_path):
    rc, _, err = run(capsys, "verify", tmp_path, "--no-write", "-q")
    assert rc == 2
    assert "no project.yaml found" in err


@pytest.mark.parametrize("argv", [
    [],
    ["verify"],
    ["frobnicate"],
    ["verify", str(TINY), "--format", "xml"],
    ["plan", str(TINY), "--from", "Left"],
    ["simulate", str(TINY), "--mode", "sideways"],
    ["schema", "--kind", "robot"],
], ids=["no_command", "verify_without_path", "unknown_command", "bad_format", "plan_without_to",
        "bad_mode", "bad_schema_kind"])
def test_bad_usage_exits_2(capsys, argv):
    rc, out, err = run(capsys, *argv)
    assert rc == 2
    assert "usage: mpgspec" in err
    assert "Traceback" not in out + err


def test_version_exits_0(capsys):
    rc, out, _ = run(capsys, "--version")
    assert rc == 0
    assert out.startswith("mpgspec ")


def test_folder_of_projects_reports_each_and_exits_with_the_worst(capsys, tmp_path):
    for name, src in (("good", TINY), ("bad", BROKEN)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "project.yaml").write_text(src.read_text())
    rc, out, err = run(capsys, "verify", tmp_path, "--no-write", "-q")
    assert rc == 2
    assert "PASS tiny" in out
    assert f"ERROR {tmp_path / 'bad' / 'project.yaml'}" in out
    assert "MPG202" in err


def test_unknown_oracle_method_is_a_usage_error(capsys):
    rc, out, err = run(capsys, "verify", TINY, "--no-write", "-q", "--method", "no_such_backend")
    assert rc == 2
    assert "unknown oracle method 'no_such_backend'" in out + err


# ----------------------------------------------------------------------------- verify: output formats
def test_verify_json_output(capsys, failing_project):
    rc, out, _ = run(capsys, "verify", failing_project, "--no-write", "-q", "--format", "json")
    doc = json.loads(out)
    assert rc == doc["exit_code"] == 1
    (proj,) = doc["projects"]
    assert proj["name"] == "tiny" and proj["status"] == "fail" and proj["files"] == {}
    status = {a["description"]: a["status"] for a in proj["assertions"]}
    assert status["edge Left -> Right"] == "fail"
    assert status["edge Left -> Mid of class 1"] == "pass"
    assert status["naive sequence is unsafe"] == "pass"


def test_verify_json_output_of_a_spec_error(capsys):
    rc, out, _ = run(capsys, "verify", BROKEN, "--no-write", "-q", "--format", "json")
    doc = json.loads(out)
    assert rc == doc["exit_code"] == 2
    (proj,) = doc["projects"]
    assert proj["status"] == "error"
    (e,) = proj["errors"]
    assert (e["code"], e["line"], e["column"]) == ("MPG202", 17, 15)
    assert e["file"] == str(BROKEN)


def test_verify_github_format_annotates_errors(capsys):
    rc, out, _ = run(capsys, "verify", BROKEN, "--no-write", "-q", "--format", "github")
    assert rc == 2
    assert f"::error file={os.path.relpath(BROKEN)},line=17,col=15,title=MPG202::" in out  # relative, as GitHub wants


def test_verify_writes_reports(capsys, tmp_path):
    out_dir = tmp_path / "reports"
    rc, out, _ = run(capsys, "verify", TINY, "-q", "--out", out_dir)
    assert rc == 0
    doc = json.loads((out_dir / "tiny" / "report.json").read_text())
    assert {p["name"] for p in doc["primitives"]} == {"Left", "Mid", "Right"}
    assert f"wrote json: {out_dir / 'tiny' / 'report.json'}" in out


def test_verify_progress_goes_to_stderr(capsys):
    rc, out, err = run(capsys, "verify", TINY, "--no-write")
    assert rc == 0
    assert "[tiny] oracle" in err
    assert "[tiny]" not in out


# ----------------------------------------------------------------------------- schema, plan, simulate
def test_schema_is_json_with_primitives(capsys):
    rc, out, _ = run(capsys, "schema")
    assert rc == 0
    schema = json.loads(out)
    assert "primitives" in schema["properties"]
    assert {"project", "system", "primitives"} <= set(schema["required"])


def test_report_schema_is_json(capsys):
    rc, out, _ = run(capsys, "schema", "--kind", "report")
    assert rc == 0
    assert isinstance(json.loads(out), dict)


def test_plan_prints_the_path(capsys):
    rc, out, _ = run(capsys, "plan", TINY, "--from", "Left", "--to", "Right", "--weight", "hops")
    assert rc == 0
    assert out.startswith("Left -> Mid -> Right")
    assert "hops 2" in out


def test_plan_json(capsys):
    rc, out, _ = run(capsys, "plan", TINY, "--from", "Right", "--to", "Left", "--format", "json")
    assert rc == 0
    plan = json.loads(out)
    assert plan["path"] == ["Right", "Left"]
    assert plan["cost"] == pytest.approx(1.5, abs=0.05)  # |x| from 1 to 0.05 at rate 2: ln(20)/2 s


def test_plan_unknown_primitive_exits_2(capsys):
    rc, _, err = run(capsys, "plan", TINY, "--from", "Left", "--to", "Nowhere")
    assert rc == 2
    assert "unknown primitive 'Nowhere'" in err and "did you mean" not in err
    rc, _, err = run(capsys, "plan", TINY, "--from", "left", "--to", "Right")
    assert rc == 2 and "unknown primitive 'left'; did you mean 'Left'?" in err


def test_simulate_runs_both_modes(capsys):
    rc, out, _ = run(capsys, "simulate", TINY)
    assert rc == 0  # the naive run is unsafe, as the project expects
    assert "naive: UNSAFE; ends in Right (as expected)" in out
    assert "first violation: right_floor of Right at t = 0.500 s" in out
    assert "graph: safe; ends in Right" in out


def test_simulate_graph_mode_json(capsys):
    rc, out, _ = run(capsys, "simulate", TINY, "--mode", "graph", "--format", "json")
    assert rc == 0
    runs = json.loads(out)
    assert set(runs) == {"graph"}
    g = runs["graph"]
    assert g["safe"] and g["violations"] == [] and g["final_primitive"] == "Right"
    assert [s["to"] for s in g["switches"]] == ["Left", "Mid", "Right"]


def test_simulate_without_sequence_exits_2(capsys, tmp_path):
    text = TINY.read_text()
    path = tmp_path / "project.yaml"
    path.write_text(text[: text.index("sequence:")])
    rc, _, err = run(capsys, "simulate", path)
    assert rc == 2
    assert "has no 'sequence'" in err


# ----------------------------------------------------------------------------- the installed entry point
def test_console_script_entry_point():
    script = Path(sys.executable).with_name("mpgspec")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "mpgspec.cli"]
    ok = subprocess.run([*cmd, "verify", str(TINY), "--no-write", "-q"], capture_output=True, text=True,
                        timeout=300)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert "PASS tiny" in ok.stdout
    bad = subprocess.run([*cmd, "verify", str(BROKEN), "--no-write", "-q"], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 2
    assert "MPG202" in bad.stderr and "Traceback" not in bad.stderr


# ----------------------------------------------------------------------------- executors and the cache
def _untimed_report(folder: Path) -> dict:
    (path,) = folder.glob("*/report.json")
    r = json.loads(path.read_text())
    r.pop("timing"), r.pop("generated_at")
    return r


def test_jobs_dask_and_one_process_write_the_same_report(capsys, tmp_path):
    outs = {}
    for name, flags in {"one": ["-j", "1"], "pool": ["-j", "2"], "dask": ["--dask", "local"]}.items():
        rc, _, err = run(capsys, "verify", TINY, "--out", tmp_path / name, "-q", "--no-cache", *flags)
        assert rc == 0, err
        outs[name] = _untimed_report(tmp_path / name)
    assert outs["pool"] == outs["one"] and outs["dask"] == outs["one"]


def test_second_verify_takes_every_call_from_the_cache(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path / "cache"))
    rc, first, _ = run(capsys, "verify", TINY, "--out", tmp_path / "a", "-q")
    assert rc == 0 and "from the cache" not in first
    rc, second, _ = run(capsys, "verify", TINY, "--out", tmp_path / "b", "-q")
    (path,) = (tmp_path / "b").glob("*/report.json")
    timing = json.loads(path.read_text())["timing"]
    assert rc == 0 and timing["cache_misses"] == 0 and timing["cache_hits"] == timing["oracle_calls"] > 0
    assert f"{int(timing['cache_hits'])} from the cache" in second
    assert _untimed_report(tmp_path / "a") == _untimed_report(tmp_path / "b")
    rc, out, _ = run(capsys, "cache", "info")
    assert rc == 0 and f"{int(timing['cache_hits'])} oracle results" in out
    rc, out, _ = run(capsys, "cache", "clear")
    assert rc == 0 and "removed" in out and not (tmp_path / "cache" / "results.sqlite").exists()


def test_jobs_below_one_is_a_usage_error(capsys):
    rc, _, err = run(capsys, "verify", TINY, "--no-write", "-q", "-j", "0")
    assert rc == 2 and "--jobs" in err


@pytest.mark.parametrize("flags", [["--scheduler", "http://x; rm -rf /"], ["--dask", ""], ["--dask", "tcp://h:1 --x"],
                                   ["--dask", "local", "--scheduler", "tcp://h:8786"], ["--scheduler", "local"]])
def test_dask_addresses_are_checked_before_any_work(capsys, flags):
    rc, out, err = run(capsys, "verify", TINY, "--no-write", "-q", *flags)
    assert rc == 2 and ("--dask" in err or "--scheduler" in err) and "Traceback" not in out + err
