"""Levels of findings: INFO notes (a transient has no stability test) never fail; WARN findings
(a neutral eigenvalue at a setpoint) fail only under `verify --strict`."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from mpgspec.cli import main

TINY_DIR = Path(__file__).parent / "fixtures" / "cli_tiny"

DRIFT = """  - name: Drift
    class: fixed
    setpoint: {expr: [0.5]}
    controller: {type: pd, outputs: [x], kp: [0], kd: [0]}
    roa: {radius: 0.05}
"""
SWEEP = """  - name: Sweep
    class: transient
    domain: [0, 0.5]
    next: Mid
    setpoint: {expr: [0.6]}
    controller: {type: pd, outputs: [x], kp: [2], kd: [0]}
    roa: {radius: 0.05}
"""


def _project(tmp_path: Path, extra: str) -> Path:
    """The tiny project without its assertions, with the primitives `extra` added."""
    proj = tmp_path / "tiny"
    shutil.copytree(TINY_DIR, proj)
    spec = proj / "project.yaml"
    text = spec.read_text()
    text = text[:text.index("oracle:")] + text[text.index("oracle:"):text.index("assertions:")] \
        + text[text.index("sequence:"):]
    spec.write_text(text.replace("primitives:\n", "primitives:\n" + extra, 1))
    return proj


def _verify(capsys, proj: Path, *extra) -> tuple[int, str, dict]:
    out = proj.parent / "out"
    rc = main(["verify", str(proj), "--out", str(out), "-q", "-j", "1", *extra])
    text = capsys.readouterr().out
    return rc, text, json.loads((out / "tiny" / "report.json").read_text())


def test_a_transients_missing_stability_test_is_info_and_never_fails(capsys, tmp_path):
    rc, out, report = _verify(capsys, _project(tmp_path, SWEEP), "--strict")
    checks = {(c["primitive"], c["name"]): c["status"] for c in report["assumptions"]}
    assert checks[("Sweep", "local_stability")] == "info"
    assert "INFO  assumption local_stability of Sweep" in out
    assert rc == 0, out


def test_a_warning_fails_only_under_strict(capsys, tmp_path):
    proj = _project(tmp_path, DRIFT)
    rc, out, report = _verify(capsys, proj)
    checks = {(c["primitive"], c["name"]): c["status"] for c in report["assumptions"]}
    assert checks[("Drift", "local_stability")] == "warn"
    assert rc == 0 and "WARN  assumption local_stability of Drift" in out
    rc, out, _ = _verify(capsys, proj, "--strict")
    assert rc == 1 and "FAIL --strict: 1 warning" in out
    html = (proj.parent / "out" / "tiny" / "report.html").read_text()
    assert "PASS with 1 warning" in html
