"""`mpgspec verify` of several projects with more than one job: one process per project, the same
reports as one project after the other, progress from every project, a dead project process is
that project's error."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from mpgspec.cli import main
from mpgspec.pipeline import side_by_side

FIXTURES = Path(__file__).parent / "fixtures"
TINY = FIXTURES / "cli_tiny"
BROKEN = FIXTURES / "cli_spec_error" / "project.yaml"


@pytest.fixture()
def two(tmp_path) -> list[Path]:
    """Two small projects: the tiny one and a copy under another name."""
    a = tmp_path / "projects" / "tiny_a"
    b = tmp_path / "projects" / "tiny_b"
    shutil.copytree(TINY, a)
    shutil.copytree(TINY, b)
    text = (b / "project.yaml").read_text()
    (b / "project.yaml").write_text(text.replace("project: tiny", "project: tiny_b", 1))
    return [a / "project.yaml", b / "project.yaml"]


def _reports(out: Path) -> dict:
    docs = {}
    for path in sorted(out.glob("*/report.json")):
        r = json.loads(path.read_text())
        r.pop("timing"), r.pop("generated_at")
        docs[path.parent.name] = r
    return docs


def test_side_by_side_writes_the_reports_of_one_after_the_other(two, tmp_path, capsys):
    assert main(["verify", *map(str, two), "-j", "1", "-q", "--no-cache", "--out", str(tmp_path / "one")]) == 0
    capsys.readouterr()
    assert main(["verify", *map(str, two), "-j", "2", "--no-cache", "--out", str(tmp_path / "two")]) == 0
    out, err = capsys.readouterr()
    one, both = _reports(tmp_path / "one"), _reports(tmp_path / "two")
    assert len(one) == 2 and both == one
    names = [line.split()[1].rstrip(":") for line in out.splitlines() if line.startswith("PASS ")]
    assert names == [json.loads((tmp_path / "one" / n / "report.json").read_text())["project"]["name"]
                     for n in sorted(one)]  # results in the order of the files
    assert all(f"[{p.parent.name}] load" in err for p in two)  # progress from both processes
    assert "2 projects: 2 passed" in out


def test_a_spec_error_beside_a_passing_project(two, tmp_path, capsys):
    rc = main(["verify", str(two[0]), str(BROKEN), "-j", "2", "-q", "--no-cache", "--out", str(tmp_path / "o")])
    out, err = capsys.readouterr()
    assert rc == 2
    assert str(BROKEN) in err and "Traceback" not in err
    assert len(list((tmp_path / "o").glob("*/report.json"))) == 1  # the passing project is written


def test_a_project_process_that_dies_is_that_projects_error(two, tmp_path, capsys, monkeypatch):
    run = side_by_side._verify_one

    def dies_on_b(path, *args):
        if path.parent.name == "tiny_b":
            os._exit(3)
        return run(path, *args)

    monkeypatch.setattr(side_by_side, "_verify_one", dies_on_b)  # inherited by the forked processes
    rc = main(["verify", *map(str, two), "-j", "2", "-q", "--no-cache", "--out", str(tmp_path / "o")])
    out, err = capsys.readouterr()
    assert rc == 2
    assert "MPG900" in err + out and "process ended" in err + out
    assert [p.parent.name for p in (tmp_path / "o").glob("*/report.json")]  # the other project's reports


def test_the_largest_project_starts_first(two, monkeypatch, tmp_path):
    (two[1].parent / "table.csv").write_text("0\n" * 50_000)  # tiny_b: the larger folder
    log = tmp_path / "started.txt"

    def child(conn, queue, path, *args):  # one at a time (workers=1): the log is the order of starts
        with open(log, "a") as f:
            f.write(path.parent.name + "\n")
        conn.send(RuntimeError("not run"))

    monkeypatch.setattr(side_by_side, "_child", child)
    res = side_by_side.verify_side_by_side(two, None, None, None, 1, False, 1)
    assert log.read_text().split() == ["tiny_b", "tiny_a"]
    assert [p.path for p in res.projects] == two and {p.status for p in res.projects} == {"error"}
