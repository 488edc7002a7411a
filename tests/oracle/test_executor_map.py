"""Executor.map: results in item order on every executor, what is shared reaches every call, and a
raising call (or a dying worker) is that item's Failed result while the other items still run."""
from __future__ import annotations

import os
import time

import pytest

from mpgspec.oracle.cache import CachedExecutor, ResultStore
from mpgspec.oracle.executors import DaskExecutor, InProcess, ProcessPool, make_executor
from mpgspec.oracle.tasks import Failed


def _square_late_first(x: int) -> int:
    """x squared; the first items take longest, so a pool finishes them last."""
    time.sleep(0.04 * max(0, 4 - x))
    return x * x


def _refuse_two(x: int) -> int:
    if x == 2:
        raise ValueError("no input for item 2")
    return -x


def _scaled(shared: dict, x: int) -> int:
    return shared["scale"] * x


def _die_on_one(x: int) -> int:
    if x == 1:
        os._exit(3)  # the worker process dies, as on a segmentation fault in compiled code
    return x


def _executors(tmp_path):
    yield "in-process", InProcess()
    yield "pool", ProcessPool(2)
    yield "cached pool", CachedExecutor(ProcessPool(2), ResultStore(tmp_path / "results.sqlite"))


@pytest.fixture(params=["in-process", "pool", "cached pool", "dask"])
def executor(request, tmp_path):
    if request.param == "dask":
        pytest.importorskip("dask.distributed")
        return DaskExecutor(workers=2)
    return dict(_executors(tmp_path))[request.param]


def test_map_keeps_item_order_and_reports_progress(executor):
    seen = []
    out = executor.map(_square_late_first, list(range(7)), lambda what, i, n: seen.append((what, i, n)),
                       label="squares")
    assert out == [x * x for x in range(7)]
    assert seen and all(what.startswith("squares") and n == 7 for what, _, n in seen)


def test_a_raising_call_is_that_items_failure(executor):
    out = executor.map(_refuse_two, [0, 1, 2, 3])
    assert out[:2] == [0, -1] and out[3] == -3
    assert isinstance(out[2], Failed) and out[2].error == "ValueError: no input for item 2"


def test_shared_reaches_every_call(executor):
    assert executor.map(_scaled, [1, 2, 3], shared={"scale": 10}) == [10, 20, 30]


def test_map_of_nothing_is_empty(executor):
    assert executor.map(_square_late_first, []) == []


def test_a_dying_worker_is_its_items_failure_not_the_end_of_the_run():
    out = ProcessPool(2).map(_die_on_one, [0, 1, 2])
    assert isinstance(out[1], Failed) and "BrokenProcessPool" in out[1].error
    assert all(o == k or isinstance(o, Failed) for k, o in enumerate(out))


def test_make_executor_gives_a_map_on_every_kind():
    for ex in (make_executor(1), make_executor(2), make_executor(2, cache=True)):
        assert ex.map(_square_late_first, [3, 2]) == [9, 4]


def test_a_local_dask_cluster_serves_every_map_until_closed():
    """A DaskExecutor without an address starts its LocalCluster on the first map and keeps it for the
    next ones (a verify maps once per stage); close() stops it, and a copy starts its own."""
    pytest.importorskip("dask.distributed")
    import pickle

    ex = DaskExecutor(workers=2)
    assert ex.map(_square_late_first, [1, 2]) == [1, 4]
    client = ex._local[0]
    assert ex.map(_scaled, [3], shared={"scale": 2}) == [6] and ex._local[0] is client
    assert pickle.loads(pickle.dumps(ex))._local is None
    ex.close()
    assert ex._local is None and client.status == "closed"
    assert ex.map(_square_late_first, [3]) == [9] and ex._local[0] is not client
    ex.close()
