"""Independent stages side by side on one executor: their maps merged into one, so no core waits.

A stage written as a generator yields `Map(fn, items, label, shared)` where it would call
`executor.map` and receives the results (or yields a list of Maps and receives a list of result
lists). `concurrently` makes one stage of several: each wave it advances every one to its next
map and yields them all; `run` merges what a stage yields into one executor map (each item still
calls its own stage's function with its own shared data, the costliest items first) and sends the
results back. Alone, a stage leaves a core idle while its last, longest item runs; merged,
another stage's items fill it. The stages run in this process one after the other between maps
(no threads), and every item is computed as it would be alone, so the results do not depend on
which stages ran together.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Generator

from .tasks import call

Stage = Generator[Any, list, Any]


@dataclass
class Map:
    """fn over items (fn(shared, item) when shared is given), as `executor.map` would run them;
    cost (optional, one number per item) orders the merged map, the costliest first."""

    fn: Callable
    items: list
    label: str = "tasks"
    shared: Any = None
    cost: list | None = None


def _maps(request) -> list[Map]:
    return [request] if isinstance(request, Map) else list(request)


def _answer(request, results: list[list]):
    return results[0] if isinstance(request, Map) else results


def concurrently(stages: dict[str, Stage]) -> Stage:
    """One stage made of several: name -> what each returns. Each wave yields the maps every
    unfinished stage waits on, as one list."""
    out: dict[str, Any] = {}
    send: dict[str, Any] = {name: None for name in stages}
    while send:
        waiting: dict[str, Any] = {}
        for name, value in send.items():
            try:
                waiting[name] = stages[name].send(value)
            except StopIteration as stop:
                out[name] = stop.value
        if not waiting:
            break
        results = yield [m for request in waiting.values() for m in _maps(request)]
        send, at = {}, 0
        for name, request in waiting.items():
            n = len(_maps(request))
            send[name] = _answer(request, results[at:at + n])
            at += n
    return out


def run(stage: Stage, executor, progress=None) -> Any:
    """What the stage returns, each of its requests run as one executor map (labelled with its
    maps' labels, costliest items first; progress(what, done, total) as items finish). An exception
    in the stage propagates."""
    value = None
    while True:
        try:
            request = stage.send(value)
        except StopIteration as stop:
            return stop.value
        maps = _maps(request)
        jobs = [(k, item) for k, m in enumerate(maps) for item in m.items]
        costs = [c for m in maps for c in (m.cost if m.cost is not None else [0.0] * len(m.items))]
        order = sorted(range(len(jobs)), key=lambda i: -costs[i])
        label = " + ".join(dict.fromkeys(m.label for m in maps if m.items)) or "tasks"
        shared = tuple((m.fn, m.shared) for m in maps)
        done = executor.map(_part, [jobs[i] for i in order], progress, label=label, shared=shared) if jobs else []
        results: list = [None] * len(jobs)
        for i, r in zip(order, done):
            results[i] = r
        split, at = [], 0
        for m in maps:
            split.append(results[at:at + len(m.items)])
            at += len(m.items)
        value = _answer(request, split)


def together(stages: dict[str, Stage], executor, progress=None) -> dict[str, Any]:
    """name -> what each stage returns, their maps merged wave by wave (concurrently, run)."""
    return run(concurrently(stages), executor, progress)


def _part(shared: tuple, job: tuple) -> Any:
    """One item of a merged map: its stage's function on its stage's shared data."""
    k, item = job
    fn, data = shared[k]
    return call(fn, item, data)
