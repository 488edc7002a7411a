"""index.html over a report folder: a row per project report found below it (an unreadable one
listed as such), links to its pages, the environment table; written by `mpgspec verify`."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from mpgspec.cli import main
from mpgspec.report.index import environment, index_html

HERE = Path(__file__).parent
SAMPLE = HERE / "data" / "sample_report.json"
TINY = HERE.parent / "fixtures" / "cli_tiny"


def test_every_report_is_a_row_and_an_unreadable_one_says_so(tmp_path):
    report = json.loads(SAMPLE.read_text())
    for name in ("alpha", "beta"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "report.json").write_text(json.dumps({**report, "project": {**report["project"],
                                                                                    "name": f"<b>{name}</b>"}}))
    (tmp_path / "beta" / "report.html").write_text("<html></html>")
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "report.json").write_text("{not json")
    (tmp_path / ".mpgspec-tmp.x").mkdir()  # a report set being written: not a project
    (tmp_path / ".mpgspec-tmp.x" / "report.json").write_text("{}")
    page = index_html(tmp_path)
    assert "&lt;b&gt;alpha&lt;/b&gt;" in page and "<b>alpha</b>" not in page
    assert 'href="beta/report.html"' in page and 'href="alpha/report.html"' not in page
    assert "unreadable" in page and "broken/report.json" in page
    assert ".mpgspec-tmp" not in page
    assert page.count("<tr><td>") == 3


def test_the_environment_names_the_libraries_that_decide_the_numbers():
    env = dict(environment())
    assert {"mpgspec", "Python", "casadi", "pinocchio", "numpy"} <= set(env)


def test_verify_writes_the_index_beside_the_project_folders(tmp_path, capsys):
    proj = tmp_path / "tiny"
    shutil.copytree(TINY, proj)
    out = tmp_path / "out"
    assert main(["verify", str(proj), "--out", str(out), "-q", "-j", "1"]) == 0
    capsys.readouterr()
    page = (out / "index.html").read_text()
    assert 'href="tiny/report.html"' in page and "PASS" in page
