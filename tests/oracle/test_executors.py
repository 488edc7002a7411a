"""Executors and the result cache: the same report whatever runs the oracle, and no call run twice.

report.json must be byte-identical (apart from timings and the timestamp) for one process, a
process pool of two, a Dask LocalCluster of two workers and a warm cache, on the pendulum (periodic
and transient primitives, windows of t_A) and on a hybrid project (contact events on the A1).
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.oracle.cache import CachedExecutor, ResultStore
from mpgspec.oracle.executors import DaskExecutor, InProcess, ProcessPool, split
from mpgspec.spec.loader import load_project

ROOT = Path(__file__).parents[2]
sys.path.insert(0, str(ROOT / "tests"))
from a1_lie import pd_lie as _pd_lie  # noqa: E402


def _untimed(v):
    """The report without wall-clock figures (the timing block and the time_s of RoA evidence)."""
    if isinstance(v, dict):
        return {k: _untimed(x) for k, x in v.items() if k not in ("timing", "generated_at", "time_s")}
    if isinstance(v, list):
        return [_untimed(x) for x in v]
    return v


def report_text(res) -> str:
    (p,) = res.projects
    assert p.status in ("pass", "fail"), p.errors
    return json.dumps(_untimed(p.report), sort_keys=True)


@pytest.fixture(scope="module")
def pendulum_serial(example):
    return report_text(example("pendulum"))  # api.verify's executor is InProcess() when none is given


def test_split_gives_every_worker_several_tasks():
    import numpy as np

    pts = {"A": (np.zeros((40, 2)), np.zeros(40)), "B": (np.zeros((40, 2)), np.zeros(40))}
    assert [len(t) for t in split(pts, 1)] == [40, 40]
    tasks = split(pts, 2)
    assert len(tasks) >= 2 * 2 and sum(len(t) for t in tasks) == 80
    for name in pts:  # batches of one target: all but the last hold at least MIN_BATCH points
        assert all(len(t) >= 16 for t in [t for t in tasks if t.target == name][:-1])


def test_process_pool_gives_the_same_report(pendulum_serial):
    res = api.verify([ROOT / "specs" / "pendulum"], out_dir=None, executor=ProcessPool(2))
    assert report_text(res) == pendulum_serial


def test_dask_local_cluster_gives_the_same_report(pendulum_serial, tmp_path, monkeypatch):
    """...and its workers, which receive the closed loops pickled, generate the same C code as this
    process did for the serial run: every library they ask for is found compiled."""
    pytest.importorskip("dask.distributed")
    log = tmp_path / "jit.log"
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(log))
    res = api.verify([ROOT / "specs" / "pendulum"], out_dir=None, executor=DaskExecutor(workers=2))
    assert report_text(res) == pendulum_serial
    asked = [json.loads(line) for line in log.read_text().splitlines()]
    assert asked and [r["name"] for r in asked if not r["hit"]] == []


def test_a_closed_loop_shipped_to_a_worker_generates_the_same_code():
    """A pickled closed loop (what a Dask worker receives) builds the oracle's chunks from the same
    C code as the original, so a worker finds them in the compile cache instead of compiling again."""
    import pickle

    import casadi as ca

    from mpgspec.oracle.judged import _judged_function

    prims = api.compile_project(load_project(ROOT / "specs" / "pendulum" / "project.yaml"))

    def code(prim) -> str:
        cg = ca.CodeGenerator("chunk.c", {"with_header": False})
        cg.add(_judged_function(prim, 0.01, 8, 64, 1e-3, 0.0, True)[0])
        return cg.dump()

    for name, prim in prims.items():
        assert code(pickle.loads(pickle.dumps(prim))) == code(prim), name


def test_cache_replays_every_call_and_reruns_only_the_edited_primitive(tmp_path, pendulum_serial):
    store = ResultStore(tmp_path / "results.sqlite")
    proj = tmp_path / "pendulum"
    shutil.copytree(ROOT / "specs" / "pendulum", proj)
    cold = CachedExecutor(InProcess(), store)
    first = api.verify([proj], out_dir=None, executor=cold)
    total = cold.stats["cache_misses"]
    assert cold.stats["cache_hits"] == 0 and total == 4930
    warm = CachedExecutor(InProcess(), store)
    second = api.verify([proj], out_dir=None, executor=warm)
    assert warm.stats == {"cache_hits": total, "cache_misses": 0, "cache_verified": 0, "cache_mismatch": 0,
                          "cache_rejected": 0}  # no oracle call at all, every stored row authentic
    assert report_text(second) == report_text(first)
    assert report_text(first).replace(str(proj), "") == pendulum_serial.replace(str(ROOT / "specs" / "pendulum"), "")
    # edit Balance's E: only the calls into Balance (its closed loop changed) and out of it (its
    # setpoint did not change, so those start points are the same) are affected
    bal = proj / "primitives" / "balance.yaml"
    bal.write_text(bal.read_text().replace("radius: 0.2", "radius: 0.19"))
    edit = CachedExecutor(InProcess(), store)
    third = api.verify([proj], out_dir=None, executor=edit)
    g = third.projects[0].mpg
    into = sum(len(tr.t_A) * len(tr.t_B) for (a, b), tr in g.transitions.items() if b == "Balance")
    assert edit.stats["cache_misses"] == into
    assert 0 < edit.stats["cache_misses"] <= 0.25 * total


def hybrid_project(folder: Path) -> Path:
    """The A1 with contact events: Lie on the ground and Drop, the same legs held in the air (by the
    paper's joint PD, which needs no feet on the ground)."""
    d = folder / "a1_hybrid"
    shutil.copytree(ROOT / "specs" / "a1", d)
    _pd_lie(d)
    p = (d / "project.yaml").read_text()
    p = p.replace("  - primitives/stand.yaml\n", "  - primitives/drop.yaml\n").replace("  - primitives/walk.yaml\n", "")
    p = p.replace("  - primitives/jump.yaml\n", "").replace("  - primitives/land.yaml\n", "")
    p = p[: p.index("sequence:")].replace("horizon: 2.5", "horizon: 0.6")
    (d / "project.yaml").write_text(p)
    lie = (d / "primitives" / "lie.yaml").read_text()
    weights = "0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1]"
    lie = lie.replace(weights, weights[:-1] + ", 0,0,0,0, 0,0]").replace("  profile: {duration: 1.0}\n", "")
    (d / "primitives" / "lie.yaml").write_text(lie)
    drop = lie.replace("name: Lie", "name: Drop").replace("  feet_on_ground: true\n", "")
    drop = drop.replace("  named: &lie\n", "  named: &lie\n    base_z: 0.16\n").replace("roa:\n", "contacts: []\nroa:\n")
    drop = drop.replace("  - use: quadruped_ground\n", "  - use: joint_limits\n")
    (d / "primitives" / "drop.yaml").write_text(drop)
    return d / "project.yaml"


def test_hybrid_project_gives_the_same_report_in_a_process_pool(tmp_path):
    path = hybrid_project(tmp_path)
    serial = api.verify([path], out_dir=None, executor=InProcess())
    assert serial.projects[0].report["transitions"], serial.projects[0].errors
    pooled = api.verify([path], out_dir=None, executor=ProcessPool(2))
    assert report_text(pooled) == report_text(serial)


def test_one_executor_keeps_projects_apart(tmp_path):
    """Two projects whose primitives share names but not dynamics, through one executor in one run:
    the second gets its own oracles (the same report as alone), not the first one's `ParkA`."""
    text = (ROOT / "specs" / "cart" / "project.yaml").read_text()
    tight = text.replace("project: cart", "project: cart_tight").replace('h: "1 - v^2"', 'h: "0.3 - v^2"')
    assert tight != text
    for name, body in (("cart", text), ("cart_tight", tight)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "project.yaml").write_text(body)
    def numbers(report):  # without wall-clock figures (the SOS solves' *_s too)
        drop = lambda v: ({k: drop(x) for k, x in v.items() if not k.endswith("_s") and k not in ("timing", "generated_at")}
                          if isinstance(v, dict) else [drop(x) for x in v] if isinstance(v, list) else v)  # noqa: E731
        return json.dumps(drop(report), sort_keys=True)

    (alone,) = api.verify([tmp_path / "cart_tight"], out_dir=None, executor=InProcess()).projects
    both = api.verify([tmp_path / "cart", tmp_path / "cart_tight"], out_dir=None, executor=InProcess())
    second = next(p for p in both.projects if p.report["project"]["name"] == "cart_tight")
    assert alone.report["edges"] != both.projects[0].report["edges"]  # the two projects differ
    assert numbers(second.report) == numbers(alone.report)
