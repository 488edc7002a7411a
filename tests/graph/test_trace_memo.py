"""Traces kept between runs: a second verify with nothing changed simulates no trace and reports
the same series; a changed closed loop is traced again."""
from __future__ import annotations

import json
from pathlib import Path

from mpgspec import api
from mpgspec.graph import traces
from mpgspec.oracle.executors import make_executor

ROOT = Path(__file__).parents[2]


def _series(report: dict) -> str:
    return json.dumps([report["edge_traces"], report["failures"]], sort_keys=True)


def test_second_run_takes_every_trace_from_the_memo(tmp_path, monkeypatch):
    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path / "cache"))
    calls = []
    real = traces.trace

    def counted(*a, **k):
        calls.append(a[0].name)
        return real(*a, **k)

    monkeypatch.setattr(traces, "trace", counted)
    (first,) = api.verify([ROOT / "specs" / "cart"], out_dir=None, executor=make_executor(1, cache=True)).projects
    traced = len(calls)
    assert traced == len(first.report["edge_traces"]) + len(first.report["failures"]) > 0
    (second,) = api.verify([ROOT / "specs" / "cart"], out_dir=None, executor=make_executor(1, cache=True)).projects
    assert len(calls) == traced  # nothing simulated again
    assert _series(second.report) == _series(first.report)
    project = tmp_path / "cart"
    project.mkdir()
    text = (ROOT / "specs" / "cart" / "project.yaml").read_text()
    (project / "project.yaml").write_text(text.replace("kp: [4], kd: [3]", "kp: [5], kd: [3]", 1))
    api.verify([project], out_dir=None, executor=make_executor(1, cache=True))
    assert len(calls) > traced  # ParkA's closed loop changed: its traces run again
