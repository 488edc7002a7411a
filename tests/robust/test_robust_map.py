"""The robust stage through the executor: one job per target and the uncertain sequence's modes
spread over the workers, the same result in a process pool as in this process, and a target (or a
mode) whose work raises is its own evidence, not the end of the run."""
from __future__ import annotations

import json
import math
import pickle
from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.oracle.executors import InProcess, ProcessPool
from mpgspec.robust import graph as robust_graph
from mpgspec.robust import sequence
from mpgspec.robust.cells import run_target
from mpgspec.robust.graph import robust_stage
from mpgspec.robust.sequence import sequence_under_uncertainty
from mpgspec.spec.loader import load_project

PEND = Path(__file__).resolve().parents[2] / "specs" / "pendulum"


class Recording(InProcess):
    """In this process, recording each map's label and number of items."""

    def __init__(self):
        super().__init__()
        self.maps: list[tuple[str, int]] = []

    def map(self, fn, items, progress=None, label="tasks", shared=None):
        items = list(items)
        self.maps.append((label, len(items)))
        return super().map(fn, items, progress, label, shared)


def _plain(rob) -> str:
    d = rob.to_dict()
    d.pop("timing")
    return json.dumps(d, sort_keys=True, default=float)


@pytest.fixture(scope="module")
def built():
    spec = load_project(PEND / "project.yaml")
    return api.build(spec, api.settings_for(spec))


@pytest.fixture(scope="module")
def serial(built):
    ex = Recording()
    return robust_stage(*built, executor=ex), ex


def test_one_job_per_target_through_the_executor(built, serial):
    rob, ex = serial
    targets = {e["to"] for e in rob.edges}
    assert ("robust graph", len(targets)) in ex.maps
    assert len(rob.nodes) == len(targets)


def test_a_process_pool_gives_the_same_robust_graph(built, serial):
    assert _plain(robust_stage(*built, executor=ProcessPool(2))) == _plain(serial[0])


def test_a_target_job_pickles_and_reruns_to_the_same_records(built):
    from mpgspec.robust.graph import target_jobs

    cp, vg = built
    _, jobs = target_jobs(cp.spec, cp.prims, cp.settings, vg.graph)
    job = jobs[0]
    again = run_target(cp.prims, pickle.loads(pickle.dumps(job)))
    assert len(pickle.dumps(job)) < 1e6  # the closed loops travel apart, once per worker
    assert json.dumps(again[:3], sort_keys=True, default=float) == \
        json.dumps(run_target(cp.prims, job)[:3], sort_keys=True, default=float)


def test_a_target_whose_check_raises_is_its_own_evidence(built, serial, monkeypatch):
    rob, _ = serial
    real = robust_graph.run_target

    def refuse_balance(prims, job):
        if job.target == "Balance":
            raise RuntimeError("the rollout could not be compiled")
        return real(prims, job)

    monkeypatch.setattr(robust_graph, "run_target", refuse_balance)
    hurt = robust_stage(*built)
    node = next(n for n in hurt.nodes if n["node"] == "Balance")
    assert node["robust_safe"] is False and "RuntimeError: the rollout could not be compiled" in node["worst_case"]["error"]
    for e, ref in zip(hurt.edges, rob.edges):
        assert (e["from"], e["to"]) == (ref["from"], ref["to"])
        if e["to"] == "Balance":
            assert not e["survives"] and e["cells_checked"] == ref["cells_checked"] and e["worst_margin"] == -math.inf
            assert "could not be compiled" in e["worst_case"]["error"]
        else:
            assert e == ref  # the other targets are untouched


class TwoInProcess(InProcess):
    """In this process, but declaring two workers: the modes are split into two jobs."""

    workers = 2


def _graphs(built, rob):
    from mpgspec.plan.planner import lookup_table

    g = built[1].graph
    return {"graph": (g, lookup_table(g)), "robust_graph": (rob.graph, lookup_table(rob.graph))}


def test_sequence_modes_spread_over_a_pool_give_the_same_statistics(built, serial):
    cp = built[0]
    graphs = _graphs(built, serial[0])
    one = sequence_under_uncertainty(cp.spec, cp.prims, cp.settings, graphs, 6, 11)
    assert list(one["modes"]) == ["naive", "graph", "robust_graph"]
    assert sequence_under_uncertainty(cp.spec, cp.prims, cp.settings, graphs, 6, 11, ProcessPool(2)) == one


def test_a_sequence_mode_that_raises_is_its_own_evidence(built, serial, monkeypatch):
    cp = built[0]
    graphs = _graphs(built, serial[0])
    real = sequence.run_modes

    def refuse_naive(prims, job):
        if any(m == "naive" for m, _, _ in job.modes):
            raise RuntimeError("the stepper could not be built")
        return real(prims, job)

    monkeypatch.setattr(sequence, "run_modes", refuse_naive)
    out = sequence_under_uncertainty(cp.spec, cp.prims, cp.settings, graphs, 4, 11, TwoInProcess())["modes"]
    assert out["naive"]["safe_runs"] == 0 and "could not be built" in out["naive"]["first_violation"][0]["error"]
    monkeypatch.setattr(sequence, "run_modes", real)
    ref = sequence_under_uncertainty(cp.spec, cp.prims, cp.settings, graphs, 4, 11)["modes"]
    assert out["graph"] == ref["graph"] and out["naive"] != ref["naive"]


def test_the_check_stage_runs_its_parts_side_by_side_each_as_alone(built, serial):
    from mpgspec.check.severity import check_assumptions
    from mpgspec.pipeline.stages import check_stage

    cp, vg = built
    ex = Recording()
    ch = check_stage(cp, vg, executor=ex)
    here, alone = json.loads(_plain(ch.robust)), json.loads(_plain(serial[0]))
    for a in here["assertions"]:  # the check stage numbers them after the project's own assertions
        a.pop("index")
    for a in alone["assertions"]:
        a.pop("index")
    assert here == alone
    assumed = check_assumptions(cp.prims, cp.spec.project.assumptions, None, cp.roa)
    assert [a.to_dict() for a in ch.assumptions] == [a.to_dict() for a in assumed]
    targets = len({e["to"] for e in serial[0].edges})
    assert ("robust graph + assumptions (Definition 1)", targets + len(cp.prims)) in ex.maps  # one map for both
    assert ch.timing["checks_s"] >= max(ch.timing["robust_s"], ch.timing["assumptions_s"])
