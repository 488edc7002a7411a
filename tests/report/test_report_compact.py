"""report.json v2: columnar cells and runs that expand back to the same content, rounded floats,
and a pendulum report a quarter of the size of the v1 one."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpgspec.report.compact import (MAX_RUN, MAX_TRACE, compact_cells, compact_run, compact_series, expand_cells,
                                    rnd, run_rows)
from mpgspec.report.schema import validate_report
from mpgspec.report.write import json_text

SPECS = Path(__file__).resolve().parents[2] / "specs"


def _cell(i, j, **kw):
    return {"verdict": int(i == j), "status": "safe" if i == j else "unsafe", "reason": "entered_E" if i == j else
            "left_C", "t_stop": 0.1 * i + 1 / 3, "t_enter": None, "violated": None if i == j else "b",
            "checked": True, "refined": j == 1, "margin": 1 / 7, "error_bound": 1.23456e-5,
            "peak_input": [2.0, 3.0], "peak_demand": [2.5, 3.0], "saturated": False, "min_margins": [0.5, -0.25],
            "best_roa_margin": None, "message": "m" if (i, j) == (1, 0) else "",
            "method": "certified" if i == j else "validated" if j == 2 else "simulated", **kw}


def test_cells_round_trip():
    rows = [[_cell(i, j) for j in range(3)] for i in range(2)]
    tr = {"h_names": ["a", "b"], "verdicts": [[c["verdict"] for c in r] for r in rows],
          "cells": compact_cells(rows, ["a", "b"])}
    back = expand_cells(tr)
    for r0, r1 in zip(rows, back):
        for c0, c1 in zip(r0, r1):
            assert c1 == {**c0, "t_stop": rnd(c0["t_stop"]), "margin": rnd(c0["margin"]), "error_bound": 1.23e-5}
    assert tr["cells"]["status"] == ["011", "101"] and tr["cells"]["messages"] == [[1, 0, "m"]]
    assert tr["cells"]["method"] == ["102", "012"]


def test_runs_and_series_round_trip():
    n = 3 * MAX_RUN
    run = {"mode": "graph", "t": [i * 0.01 for i in range(n)], "x": [[i * 1.0, -i * 1.0] for i in range(n)],
           "min_h": [1.0] * n, "active": ["A"] * (n // 2) + ["B"] * (n - n // 2), "switches": [], "violations": []}
    c = compact_run(run)
    assert len(c["t"]) <= MAX_RUN + 1 and len(c["x"]) == 2 and c["active"][0][0] == "A"
    rows = run_rows(c)
    assert len(rows["x"]) == len(rows["active"]) == len(c["t"]) and rows["x"][1] == [c["x"][0][1], c["x"][1][1]]
    s = {"t": [i * 0.005 for i in range(1000)], "h": {"a": [0.1234567] * 1000}, "roa_margin": [1.0] * 1000,
         "u": [[0.0] * 1000], "x": [[1.0] * 1000]}
    cs = compact_series(s, t_keep=2.0021)
    assert len(cs["t"]) <= MAX_TRACE + 2 and 2.005 in cs["t"] and cs["h"]["a"][0] == 0.1235
    assert "x" not in cs and "u" not in cs and cs["h_count"] == 1


def test_safety_functions_are_grouped_by_family_for_the_cells_least_margins():
    from mpgspec.report.build import _least
    from mpgspec.report.compact import h_families
    names = ["trunk_clearance", "friction_cone[FR_foot]", "q_min[FR_hip]", "friction_cone[FL_foot]"]
    fams, members = h_families(names)
    assert fams == ["trunk_clearance", "friction_cone[2]", "q_min[FR_hip]"]
    assert members[1] == ["friction_cone[FR_foot]", "friction_cone[FL_foot]"]
    assert _least({"friction_cone[FR_foot]": 0.5, "friction_cone[FL_foot]": -0.25}, members[1]) == -0.25
    assert h_families(["speed_limit", "upright_cone"])[0] == ["speed_limit", "upright_cone"]


def test_traces_share_a_sample_budget_and_keep_the_least_margin():
    from mpgspec.report.compact import TRACE_BUDGET, trace_samples
    assert trace_samples(1) == MAX_TRACE and trace_samples(10 ** 6) == 40
    assert trace_samples(56) * 56 <= TRACE_BUDGET
    n = 1000
    dip = [1.0] * n
    dip[517] = -2.0  # between every-k-th samples
    cs = compact_series({"t": [0.01 * i for i in range(n)], "h": {"a": dip}, "roa_margin": [0.0] * n}, samples=50)
    assert len(cs["t"]) <= 52 and -2.0 in cs["h"]["a"] and min(cs["h_least"]) == -2.0


def test_a_sequence_run_keeps_its_first_states():
    from mpgspec.report.compact import RUN_STATES
    run = {"mode": "graph", "t": [0.0, 0.1], "x": [[float(k) for k in range(43)]] * 2, "min_h": [1.0, 1.0],
           "active": ["A", "A"], "switches": [], "violations": []}
    c = compact_run(run)
    assert len(c["x"]) == RUN_STATES and c["x"][RUN_STATES - 1] == [RUN_STATES - 1.0] * 2


def test_a_trace_keeps_the_violated_and_the_least_functions_and_the_floor_of_all():
    n = 10
    h = {f"far{k}": [5.0 + k] * n for k in range(40)}
    h["dips"] = [1.0] * 5 + [-0.5] + [1.0] * 4        # least minimum
    h["low"] = [0.2] * n
    h["broken"] = [0.9] * 9 + [-0.1]                  # the violated one, not the least
    h["none"] = [None] * n
    cs = compact_series({"t": [0.1 * i for i in range(n)], "h": h, "roa_margin": [0.0] * n}, violated="broken")
    assert list(cs["h"]) == ["broken", "dips", "low"] and cs["h_count"] == 44
    assert cs["h_least"] == [0.2] * 5 + [-0.5] + [0.2] * 3 + [-0.1]


@pytest.fixture(scope="module")
def pendulum(example) -> dict:
    return example("pendulum").projects[0].report


def test_pendulum_report_is_a_quarter_of_v1(pendulum):
    validate_report(json.loads(json_text(pendulum, compact=True)))
    size = len(json_text(pendulum, compact=True).encode())
    assert size < 2_757_477 / 4, size  # v1 of the same project: 2.76 MB
    assert pendulum["schema_version"].startswith("2.") and pendulum["project"]["digest"].startswith("sha256:")


def test_guarded_primitives_count_the_crossings_of_their_traces(pendulum):
    """Each loop stepped piece by piece reports the crossings located along the traced rollouts into
    it: the sum of those traces' counts, over as many rollouts as there are traces into it."""
    traces = pendulum["edge_traces"] + pendulum["failures"]
    for p in pendulum["primitives"]:
        into = [t["series"]["crossings"] for t in traces if t["to"] == p["name"] and "crossings" in t["series"]]
        assert p["guards"]["guards"] and into, p["name"]  # every pendulum loop saturates
        assert p["guards"]["crossings"] == {"located": sum(c["count"] for c in into), "rollouts": len(into)}
        assert all(len(c["t"]) == min(c["count"], 50) and c["t"] == sorted(c["t"]) for c in into)
    assert sum(p["guards"]["crossings"]["located"] for p in pendulum["primitives"]) > 0
