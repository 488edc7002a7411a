"""report.json carries an integrity record (its content hash and the mac of it under this machine's
key); plan and simulate refuse a report that was edited, whose hash was recomputed without the key,
or that is malformed: exit 2 and one message naming the file and the key, never a traceback, never a
plan through an edge the report did not verify. An unedited report still plans and simulates.

The pendulum is verified once per module (through the oracle cache); each test edits a copy.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.cli import main
from mpgspec.integrity import content_hash
from mpgspec.report.read import ReportGraph, report_status
from mpgspec.report.trust import UNHASHED, ReportError, integrity_record

PENDULUM = Path(__file__).parents[2] / "specs" / "pendulum"
FAKE = {"from": "Hang", "to": "Balance", "class": 1, "duration": 0.01, "peak_input": 0.1, "hops": 1.0,
        "usable": True}
"""An edge the oracle refused (naive Hang -> Balance is unsafe): a plan through it is the attack."""


def run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def verified(tmp_path_factory) -> Path:
    """The report folder `mpgspec verify` wrote for the pendulum."""
    out = tmp_path_factory.mktemp("verified")
    assert main(["verify", str(PENDULUM), "--out", str(out), "-q"]) == 0
    return out


@pytest.fixture()
def copy(verified, tmp_path) -> tuple[Path, dict]:
    """A copy of the verified report folder: (its report.json, the report read back)."""
    out = tmp_path / "reports"
    shutil.copytree(verified, out)
    path = out / "pendulum" / "report.json"
    return path, json.loads(path.read_text(encoding="utf-8"))


def write(path: Path, report: dict, seal: str) -> None:
    """report.json as an editor leaves it. seal: 'none' (the record kept as it was), 'hash' (the
    sha256 recomputed by someone without the key), 'key' (sealed with this machine's key, so that
    only the structural checks stand between the report and the planner)."""
    report = dict(report)
    if seal == "hash":
        rest = {k: v for k, v in report.items() if k not in UNHASHED}
        report["integrity"] = {**report["integrity"], "sha256": content_hash(rest)}
    elif seal == "key":
        report["integrity"] = integrity_record(report)
    path.write_text(json.dumps(report), encoding="utf-8")


def index(report: dict, key: str, a: str, b: str) -> int:
    return next(i for i, e in enumerate(report[key]) if (e["from"], e["to"]) == (a, b))


def add_fake_edge(r: dict) -> str:
    r["edges"].append(dict(FAKE))
    return ""


def set_edge(field, value, a="Hang", b="Swing(1)"):
    def edit(r: dict) -> str:
        i = index(r, "edges", a, b)
        r["edges"][i][field] = value
        return f"edges[{i}].{field}"
    return edit


def drop_from(r: dict) -> str:
    del r["edges"][0]["from"]
    return "edges[0].from"


def negative_window(r: dict) -> str:
    i = index(r, "transitions", "Swing(2.6)", "Balance")
    r["transitions"][i]["windows"][0] = [0.5, -1.0]
    return f"transitions[{i}].windows[0]"


def unknown_in_table(r: dict) -> str:
    r["lookup_table"]["next"]["Hang"]["Balance"] = "Nowhere"
    return "lookup_table.next.Hang.Balance"


def table_skips_an_edge(r: dict) -> str:
    r["lookup_table"]["next"]["Hang"]["Balance"] = "Balance"  # no edge Hang -> Balance was verified
    return "lookup_table.next.Hang.Balance"


def fake_edge_with_key(r: dict) -> str:
    r["edges"].append(dict(FAKE))
    return f"edges[{len(r['edges']) - 1}]"


EDITS = {  # name: (seal, edit returning the key path the message names; '' for the integrity record's)
    "fake edge": ("none", add_fake_edge),
    "fake edge, hash recomputed": ("hash", add_fake_edge),
    "record removed": ("none", lambda r: r.pop("integrity") and "integrity"),
    "fake edge without a verified transition, sealed": ("key", fake_edge_with_key),
    "NaN duration": ("key", set_edge("duration", float("nan"))),
    "infinite duration": ("key", set_edge("duration", float("inf"))),
    "negative duration": ("key", set_edge("duration", -1)),
    "duration a string": ("key", set_edge("duration", "1")),
    "class 10**400": ("key", set_edge("class", 10 ** 400)),
    "class true": ("key", set_edge("class", True)),
    "edge to an unknown primitive": ("key", set_edge("to", "Nowhere")),
    "edge without from": ("key", drop_from),
    "edges a string": ("key", lambda r: r.__setitem__("edges", "Hang -> Balance") or "edges"),
    "transitions a string": ("key", lambda r: r.__setitem__("transitions", "none") or "transitions"),
    "window end before start": ("key", negative_window),
    "lookup table names an unknown primitive": ("key", unknown_in_table),
    "lookup table hop without an edge": ("key", table_skips_an_edge),
    "lookup table a list": ("key", lambda r: r.__setitem__("lookup_table", [1]) or "lookup_table"),
    "report a list": ("key", None),
}
INTEGRITY_KEYS = {"none": "integrity.sha256", "hash": "integrity.mac"}


def edited(copy, name: str) -> tuple[Path, str]:
    """The copy edited as EDITS[name] says: (report.json, the key path the refusal must name)."""
    path, report = copy
    seal, edit = EDITS[name]
    if edit is None:
        path.write_text("[1]", encoding="utf-8")
        return path, ""
    key = edit(report)
    write(path, report, seal)
    return path, key or INTEGRITY_KEYS.get(seal, "integrity")


def assert_refused(rc: int, out: str, err: str, path: Path, key: str) -> None:
    assert rc == 2, out + err
    assert "Traceback" not in out + err and "internal error" not in err, err
    assert f"{path} MPG410" in err and (not key or f" {key}:" in err), err
    assert "Hang -> Balance" not in out and "safe" not in out, out


@pytest.mark.parametrize("name", EDITS)
def test_plan_refuses_an_edited_or_malformed_report(capsys, copy, name):
    path, key = edited(copy, name)
    rc, out, err = run(capsys, "plan", PENDULUM, "--from", "Hang", "--to", "Balance", "--out", path.parents[1])
    assert_refused(rc, out, err, path, key)


@pytest.mark.parametrize("name", ["fake edge", "fake edge, hash recomputed", "NaN duration", "negative duration",
                                  "class 10**400", "edge without from", "transitions a string",
                                  "lookup table names an unknown primitive", "lookup table a list"])
def test_simulate_refuses_an_edited_or_malformed_report(capsys, copy, name):
    path, key = edited(copy, name)
    rc, out, err = run(capsys, "simulate", PENDULUM, "--out", path.parents[1])
    assert_refused(rc, out, err, path, key)


@pytest.mark.parametrize("weight, value", [("duration", -5), ("from", "Balance")])
def test_plan_robust_refuses_a_malformed_robust_edge(capsys, copy, weight, value):
    path, report = copy
    i = next(i for i, e in enumerate(report["robust"]["edges"]) if e["survives"])
    report["robust"]["edges"][i]["robust_weights"][weight] = value
    write(path, report, "key")
    rc, out, err = run(capsys, "plan", PENDULUM, "--from", "Hang", "--to", "Balance", "--out", path.parents[1],
                       "--robust")
    assert_refused(rc, out, err, path, f"robust.edges[{i}].robust_weights.{weight}")


def test_an_unedited_report_plans_and_simulates(capsys, copy):
    path, report = copy
    assert report["integrity"] == integrity_record(report)  # the hash is over exactly what was written
    rc, out, err = run(capsys, "plan", PENDULUM, "--from", "Hang", "--to", "Balance", "--out", path.parents[1])
    assert rc == 0 and "rebuild" not in err, err
    assert out.startswith("Hang -> Swing(1) -> Swing(2.6) -> Balance")
    rc, out, err = run(capsys, "simulate", PENDULUM, "--out", path.parents[1])
    assert rc == 0 and "rebuild" not in err, err
    assert "graph: safe; ends in Hang (as expected)" in out


def test_the_wall_clock_figures_are_not_hashed(capsys, copy):
    """Two runs that verified the same thing store the same record: timing and generated_at are
    left out of the hash (plan and simulate read neither)."""
    path, report = copy
    report["timing"] = {"graph_s": 1e6}
    report["generated_at"] = "2000-01-01T00:00:00+00:00"
    write(path, report, "none")
    rc, out, err = run(capsys, "plan", PENDULUM, "--from", "Hang", "--to", "Balance", "--out", path.parents[1])
    assert rc == 0, err


def test_a_refused_report_is_only_not_reused_outside_plan_and_simulate(copy):
    """report_status (not strict) and the API's readers: (None, why) or ReportError, no crash."""
    path, key = edited(copy, "negative duration")
    report, why = report_status(path, PENDULUM / "project.yaml")
    assert report is None and key in why and str(path) in why
    with pytest.raises(ReportError, match=r"edges\[\d+\]\.duration"):
        report_status(path, PENDULUM / "project.yaml", strict=True)
    with pytest.raises(ReportError, match="MPG410"):
        api.load_report(path.parent)


def test_report_graph_refuses_what_it_cannot_rebuild(copy):
    _, report = copy
    report["edges"][0]["duration"] = -1
    with pytest.raises(ReportError, match=r"report MPG410 edges\[0\]\.duration"):
        ReportGraph(report)
