"""A project's report set is written as a unit: into a temporary folder inside --out, then moved into
place; a failure to write is an error (exit 2), never a PASS; inf/NaN become null in strict JSON; a
project folder outside --out is refused."""
from __future__ import annotations

import copy
import errno
import json
import os
import socket
from pathlib import Path

import pytest

from mpgspec.cli import main
from mpgspec.report import files as report_files
from mpgspec.report.files import (OLD_PREFIX, TMP_PREFIX, ReportWriteError, write_project_reports,
                                  write_reports)

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"
TINY = Path(__file__).parents[1] / "fixtures" / "cli_tiny" / "project.yaml"
SET = {"report.json", "report.html", "graph.dot", "graph.graphml", "lookup_table.json"}


@pytest.fixture
def sample() -> dict:
    return json.loads(SAMPLE.read_text(encoding="utf-8"))


def _strict(path: Path):
    """json.loads that refuses NaN/Infinity, and a round trip with allow_nan=False."""
    def no_constants(c):
        raise ValueError(f"non-standard JSON constant {c}")

    doc = json.loads(Path(path).read_text(encoding="utf-8"), parse_constant=no_constants)
    json.dumps(doc, allow_nan=False)
    return doc


def _temps(folder: Path) -> list[str]:
    return [p.name for p in Path(folder).iterdir() if p.name.startswith((TMP_PREFIX, OLD_PREFIX))]


def _verify_json(capsys, out) -> tuple[int, dict, str]:
    rc = main(["verify", str(TINY), "-q", "--format", "json", "--out", str(out)])
    o, err = capsys.readouterr()
    return rc, json.loads(o), err


# ----------------------------------------------------------------------------- the folder swap
def test_write_is_a_unit_and_leaves_no_temporary_folder(sample, tmp_path):
    out = tmp_path / "reports"
    files = write_project_reports(sample, out)
    name = sample["project"]["name"]
    assert sorted(p.name for p in out.iterdir()) == [name]
    assert {Path(p).name for p in files.values()} == SET == {p.name for p in (out / name).iterdir()}
    (out / name / "stray.txt").write_text("from an older run")
    sample["project"]["description"] = "second run"
    write_project_reports(sample, out)
    assert sorted(p.name for p in out.iterdir()) == [name]  # nothing left aside or half-written
    assert {p.name for p in (out / name).iterdir()} == SET  # the older folder was replaced as a whole
    assert _strict(out / name / "report.json")["project"]["description"] == "second run"
    assert oct((out / name).stat().st_mode & 0o777) != oct(0o700)  # an ordinary folder, not mkdtemp's


def test_failure_mid_write_keeps_the_older_reports(sample, tmp_path, monkeypatch):
    out = tmp_path / "reports"
    write_project_reports(sample, out)
    before = (out / "pendulum" / "report.json").read_text()
    calls = []

    def full_disk(path, text):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        Path(path).write_text(text)

    monkeypatch.setattr(report_files, "write_new", full_disk)
    sample["project"]["description"] = "never written"
    with pytest.raises(ReportWriteError, match="No space left on device"):
        write_project_reports(sample, out)
    assert (out / "pendulum" / "report.json").read_text() == before
    assert _temps(out) == []


def test_stale_temporary_folders_of_dead_runs_are_removed(sample, tmp_path):
    out = tmp_path / "reports"
    out.mkdir()
    host = socket.gethostname()
    dead = 2 ** 22 + 12345  # above the default pid_max: no such process
    (out / f"{TMP_PREFIX}{host}.{dead}.abcd1234").mkdir()
    (out / f"{TMP_PREFIX}{host}.{dead}.abcd1234" / "report.json").write_text("{half")
    (out / f"{OLD_PREFIX}{host}.{dead}.0badc0de").mkdir()
    live = out / f"{TMP_PREFIX}{host}.{os.getppid()}.zzzz9999"  # a run still going on: left alone
    live.mkdir()
    write_project_reports(sample, out)
    assert _temps(out) == [live.name]


# ----------------------------------------------------------------------------- non-finite numbers
def test_inf_and_nan_become_null_in_strict_json(sample, tmp_path):
    inf, nan = float("inf"), float("nan")
    r = copy.deepcopy(sample)
    r["primitives"][0]["roa_radius"] = inf
    r["primitives"][1]["period"] = nan
    r["edges"][0]["duration"] = -inf
    r["timing"]["graph_s"] = nan
    r["settings"]["horizon"] = inf
    r["lookup_table"]["extra"] = {"cost": inf}
    files = write_reports(r, None, tmp_path / "reports" / r["project"]["name"])
    doc = _strict(files["json"])
    assert doc["primitives"][0]["roa_radius"] is None and doc["primitives"][1]["period"] is None
    assert doc["edges"][0]["duration"] is None and doc["timing"]["graph_s"] is None
    assert doc["settings"]["horizon"] is None
    assert _strict(files["lookup_table"])["extra"] == {"cost": None}
    assert {Path(p).name for p in files.values()} == SET  # HTML, DOT and GraphML written as well
    assert "Infinity" not in Path(files["json"]).read_text() and "NaN" not in Path(files["json"]).read_text()


# ----------------------------------------------------------------------------- outside --out
@pytest.mark.parametrize("name", ["../x", "../../x", "/tmp/x", ".", "a/../../x"])
def test_a_project_folder_outside_out_is_refused(sample, tmp_path, name):
    out = tmp_path / "out" / "reports"
    out.mkdir(parents=True)
    sample["project"]["name"] = name
    with pytest.raises(ReportWriteError, match="refusing"):
        write_project_reports(sample, out, name)
    with pytest.raises(ReportWriteError, match="refusing"):
        write_reports(sample, None, out / name)  # as mpgspec.api calls it
    assert list(out.iterdir()) == [] and sorted(p.name for p in (tmp_path / "out").iterdir()) == ["reports"]
    assert not (tmp_path / "out" / "x").exists()


def test_a_symlink_out_of_the_report_folder_is_refused(sample, tmp_path):
    out, elsewhere = tmp_path / "reports", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / "pendulum").symlink_to(elsewhere)
    with pytest.raises(ReportWriteError, match="not inside the report folder"):
        write_project_reports(sample, out)
    assert list(elsewhere.iterdir()) == []


# ----------------------------------------------------------------------------- through the CLI: exit 2, never PASS
def test_out_that_is_a_file_is_an_error(capsys, tmp_path):
    f = tmp_path / "afile"
    f.write_text("not a folder")
    rc, doc, err = _verify_json(capsys, f)
    assert rc == doc["exit_code"] == 2
    (proj,) = doc["projects"]
    assert proj["status"] == "error" and proj["files"] == {}
    assert "not a folder" in proj["errors"][-1]["message"]
    assert f.read_text() == "not a folder"


def test_out_dev_null_is_an_error(capsys):
    rc, doc, _ = _verify_json(capsys, os.devnull)
    assert rc == 2 and doc["projects"][0]["status"] == "error"


@pytest.mark.parametrize("how", ["mode", "file system"])
def test_read_only_out_is_an_error_not_a_pass(capsys, tmp_path, monkeypatch, how):
    out = tmp_path / "ro"
    out.mkdir()
    if how == "mode":
        out.chmod(0o555)  # refused even for root, whom the permissions would let through
    else:  # a read-only mount that the access check does not see, or a permission error on creation

        def read_only(root):
            raise OSError(errno.EROFS, "Read-only file system", str(root))

        monkeypatch.setattr(report_files, "_make_temp_dir", read_only)
    try:
        rc, doc, _ = _verify_json(capsys, out)
        assert rc == doc["exit_code"] == 2
        (proj,) = doc["projects"]
        assert proj["status"] == "error" and proj["files"] == {}
        assert proj["errors"][-1]["code"] == "MPG400"
        assert "read-only" in proj["errors"][-1]["message"].lower()
        assert list(out.iterdir()) == []
        rc = main(["verify", str(TINY), "-q", "--out", str(out)])
        o, err = capsys.readouterr()
        assert rc == 2 and "PASS" not in o.splitlines()[0] and o.startswith("ERROR tiny")
        assert "MPG400" in err and "Traceback" not in o + err
    finally:
        out.chmod(0o755)


def test_cli_writes_the_set_and_no_temporary_folder(capsys, tmp_path):
    out = tmp_path / "reports"
    for _ in range(2):
        rc, doc, _ = _verify_json(capsys, out)
        assert rc == 0 and doc["projects"][0]["status"] == "pass"
    assert sorted(p.name for p in out.iterdir()) == ["index.html", "tiny"]
    assert {p.name for p in (out / "tiny").iterdir()} == SET
    assert {Path(p).name for p in doc["projects"][0]["files"].values()} == SET
