"""Stages side by side (mpgspec.oracle.joint): their maps merged into one executor map per wave,
every stage getting what it would get alone, on one process or a pool."""
from __future__ import annotations

import pytest

from mpgspec.oracle.executors import InProcess, ProcessPool
from mpgspec.oracle.joint import Map, concurrently, run, together
from mpgspec.oracle.tasks import Failed


def _scaled(k: float, x: float) -> float:
    if x < 0:
        raise ValueError("negative")
    return k * x


def _plus(x: int) -> int:
    return x + 1


def _two_waves(items, k):
    first = yield Map(_scaled, items, "scale", k)
    second = yield Map(_plus, first, "plus")
    return second


def _one_wave(items):
    return (yield Map(_plus, items, "plus", cost=[float(x) for x in items]))


def _none():
    return "nothing to run"
    yield  # noqa: unreachable - a stage that never maps


class Counting(InProcess):
    """InProcess that records each map it is handed (label, items)."""

    def __init__(self):
        super().__init__()
        self.maps = []

    def map(self, fn, items, progress=None, label="tasks", shared=None):
        items = list(items)
        self.maps.append((label, items))
        return super().map(fn, items, progress, label, shared)


def test_each_stage_gets_what_it_gets_alone_and_waiting_maps_are_one():
    alone = {"a": run(_two_waves([1.0, 2.0], 3.0), InProcess()), "b": run(_one_wave([5, 1, 9]), InProcess()),
             "c": run(_none(), InProcess())}
    ex = Counting()
    got = together({"a": _two_waves([1.0, 2.0], 3.0), "b": _one_wave([5, 1, 9]), "c": _none()}, ex)
    assert got == alone == {"a": [4.0, 7.0], "b": [6, 2, 10], "c": "nothing to run"}
    assert len(ex.maps) == 2  # wave 1: a's scale and b's plus as one map; wave 2: a's plus alone
    label, items = ex.maps[0]
    assert label == "scale + plus" and len(items) == 5
    assert [job[1] for job in items] == [9, 5, 1, 1.0, 2.0]  # b's costliest first, a's (cost 0) after


def test_a_pool_gives_the_same_results_and_a_raising_item_is_that_items_failure():
    stages = lambda: {"a": _two_waves([1.0, -1.0, 2.0], 2.0), "b": _one_wave(list(range(6)))}  # noqa: E731
    here = together(stages(), InProcess())
    there = together(stages(), ProcessPool(2))
    assert here["b"] == there["b"] == [1, 2, 3, 4, 5, 6]
    # the negative start fails in the first wave; the second maps _plus over the Failed, which raises too
    for got in (here, there):
        assert got["a"][0] == 3.0 and got["a"][2] == 5.0
        assert isinstance(got["a"][1], Failed)


def test_nested_stages_run_in_the_same_waves():
    ex = Counting()
    inner = concurrently({"x": _one_wave([1, 2]), "y": _two_waves([1.0], 1.0)})

    def outer():
        both = yield from inner
        return both["x"] + both["y"]

    got = together({"outer": outer(), "other": _one_wave([7])}, ex)
    assert got == {"outer": [2, 3, 2.0], "other": [8]}
    assert [len(items) for _, items in ex.maps] == [4, 1]


def test_an_exception_in_a_stage_propagates():
    def broken():
        yield Map(_plus, [1], "plus")
        raise RuntimeError("the stage's own error")

    with pytest.raises(RuntimeError, match="own error"):
        together({"ok": _one_wave([1]), "broken": broken()}, InProcess())
