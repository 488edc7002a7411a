"""Clean output channels of the command line: stdout carries only mpgspec's result (one JSON document
with --format json, whatever a verifier or solver prints), GitHub workflow commands are escaped,
the exit code survives a closed stdout, --jobs is bounded, and SIGTERM leaves no worker process
and no temporary folder behind."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.cli import main
from mpgspec.errors import gh_command, gh_escape_data, gh_escape_property, gh_plain

ROOT = Path(__file__).parents[1]
TINY = Path(__file__).parent / "fixtures" / "cli_tiny" / "project.yaml"


def _script() -> list[str]:
    script = Path(sys.executable).with_name("mpgspec")
    return [str(script)] if script.exists() else [sys.executable, "-m", "mpgspec.cli"]


@pytest.fixture()
def failing_project(tmp_path) -> Path:
    text = TINY.read_text()
    path = tmp_path / "project.yaml"
    path.write_text(text.replace("assertions:\n", "assertions:\n  - edge: {from: Left, to: Right}\n", 1))
    return path


# ----------------------------------------------------------------------------- stdout: one JSON document
def test_json_stdout_is_one_document_even_when_a_verifier_prints(capfd, monkeypatch, tmp_path):
    real = api.check_stage

    def noisy(*a, **kw):
        print("verifier says hello")  # Python level
        os.write(1, b"solver iteration log from C\n")  # file descriptor level, as C or Rust code writes
        return real(*a, **kw)

    monkeypatch.setattr(api, "check_stage", noisy)
    rc = main(["verify", str(TINY), "-q", "--format", "json", "--out", str(tmp_path / "r")])
    out, err = capfd.readouterr()
    doc = json.loads(out)  # raises if anything else reached stdout
    assert rc == doc["exit_code"] == 0 and doc["projects"][0]["status"] == "pass"
    assert "verifier says hello" in err and "solver iteration log from C" in err


def test_json_stdout_of_a_usage_error_is_one_document(capfd):
    rc = main(["verify", str(TINY), "-q", "--format", "json", "-j", "0"])
    out, err = capfd.readouterr()
    assert rc == 2 and json.loads(out)["exit_code"] == 2 and "--jobs" in err


def test_a_verbose_solver_prints_nothing_on_stdout(capfd):
    sos = pytest.importorskip("verifiers.sos")
    from mpgspec.streams import stdout_to_stderr as solver_output_to_stderr

    p = {(2, 0): 1.0, (0, 2): 1.0, (1, 1): 0.5, (0, 0): 1.0}  # x^2 + xy + y^2 + 1 is SOS
    cert = sos.prove_sos(p, 2, solver_opts={"verbose": True})
    assert cert.ok
    with solver_output_to_stderr():
        os.write(1, b"from C\n")
        print("from Python", flush=True)
    out, err = capfd.readouterr()
    assert out == ""
    assert "from C" in err and "from Python" in err


# ----------------------------------------------------------------------------- --format github
def test_github_escaping_rules():
    assert gh_escape_data("50%\r\n::add-mask::x") == "50%25%0D%0A::add-mask::x"
    assert gh_escape_property("a:b,c%\n") == "a%3Ab%2Cc%25%0A"
    line = gh_command("error", "bad\n::add-mask::secret", file="x,y:z.yaml", line=3, title="t\r\nu")
    assert line == "::error file=x%2Cy%3Az.yaml,line=3,title=t%0D%0Au::bad%0A::add-mask::secret"
    assert "\n" not in gh_plain("PASS a\n::error::b") and not gh_plain("  ::warning::x").lstrip().startswith("::")


def test_github_output_cannot_inject_workflow_commands(capsys, monkeypatch):
    evil = "50% done\r\n::add-mask::secret\n::error::forged"
    project = api.ProjectResult(Path(f"specs/{evil}/project.yaml"), name=evil, status="error", errors=[
        {"code": "MPG100", "file": f"a,b:{evil}", "line": 1, "column": 2, "message": evil, "text": evil}])
    monkeypatch.setattr(api, "verify", lambda *a, **kw: api.VerifyResult([project]))
    rc = main(["verify", "x", "-q", "--no-write", "--format", "github"])
    out, err = capsys.readouterr()
    assert rc == 2
    commands = [ln for ln in (out + err).splitlines() if ln.lstrip().startswith("::")]
    assert len(commands) == 1  # the one annotation mpgspec meant, nothing forged
    (cmd,) = commands
    assert cmd.startswith("::error file=a%2Cb%3A50%25 done%0D%0A%3A%3Aadd-mask%3A%3Asecret")
    assert cmd.endswith("::50%25 done%0D%0A::add-mask::secret%0A::error::forged")
    assert "\r" not in out + err


# ----------------------------------------------------------------------------- a closed stdout
@pytest.mark.parametrize("fmt", ["human", "json"])
def test_broken_pipe_keeps_the_exit_code(failing_project, fmt):
    p = subprocess.Popen([*_script(), "verify", str(failing_project), "--no-write", "-q", "--format", fmt],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # the reader goes away at once, as `| head -0` does
    err = p.stderr.read().decode()
    rc = p.wait(timeout=300)
    assert rc == 1, err
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err


# ----------------------------------------------------------------------------- --jobs
@pytest.mark.parametrize("jobs", ["0", "-3", "100000", str(4 * (os.cpu_count() or 1) + 1)])
def test_jobs_out_of_range_is_a_usage_error(capsys, jobs):
    rc = main(["verify", str(TINY), "--no-write", "-q", "-j", jobs])
    _, err = capsys.readouterr()
    assert rc == 2 and "--jobs must be between 1 and" in err and "Traceback" not in err


# ----------------------------------------------------------------------------- SIGTERM
def _group(pgid: int) -> list[int]:
    """Live (not zombie) processes of a process group, from /proc."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            pids.append(int(d.name))
    return pids


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.parametrize("projects, procs", [(["specs/pendulum"], 3), (["specs/pendulum", "specs/cart"], 4)],
                         ids=["one project", "side by side"])
def test_sigterm_ends_workers_and_leaves_no_temporary_folder(tmp_path, projects, procs):
    out = tmp_path / "reports"
    p = subprocess.Popen([*_script(), "verify", "-j", "2", *projects, "--no-cache", "--out", str(out)],
                         cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        t0 = time.monotonic()
        while len(_group(p.pid)) < procs and p.poll() is None and time.monotonic() - t0 < 240:
            time.sleep(0.05)  # until the pool's workers run (the parent and two workers; side by side: the
            # parent, the two project processes and a worker of one of them)
        assert p.poll() is None, "the run ended before its worker processes were seen"
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=30)
        time.sleep(5)
        assert p.returncode == 128 + signal.SIGTERM, err.decode()[-2000:]
        assert _group(p.pid) == [], "a worker process outlived the SIGTERM"
        assert "Traceback" not in err.decode()
        assert not out.exists() or [q.name for q in out.iterdir() if q.name.startswith(".")] == []
    finally:
        if p.poll() is None:
            p.kill()
        for pid in _group(p.pid):
            os.kill(pid, signal.SIGKILL)
