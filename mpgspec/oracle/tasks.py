"""What an executor runs: tasks of (target primitive, batch of start points), any picklable
function over a list of items (map), and the Executor contract.

Executors (executors.py) run the tasks where the oracle calls go, and the other per-item work of a
build (the robust stage's targets, the uncertain sequence's modes) through `map`; the result cache
(cache.py) wraps any executor and hands it only the start points it has not stored.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..settings import OracleSettings
from .evidence import OracleEvidence

Progress = Callable[[str, int, int], None]


@dataclass
class Task:
    """Start points (rows of x0s, clocks t0s) of one target primitive; recheck (optional, one flag
    per row): rows whose stored result a verifying cache runs again (the edges assertions name)."""

    target: str
    x0s: np.ndarray
    t0s: np.ndarray
    recheck: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t0s)


@dataclass(frozen=True)
class Failed:
    """The result of a map item whose call raised (or whose worker died): the error, as that item's
    evidence; the other items still run."""

    error: str

    @classmethod
    def of(cls, err: BaseException) -> "Failed":
        """The error's type and message (at most 500 characters)."""
        return cls(f"{type(err).__name__}: {err}"[:500])


def call(fn: Callable[..., Any], item: Any, shared: Any = None) -> Any:
    """fn(item), or fn(shared, item) when shared is given; Failed with the error's type and message
    when it raises an Exception."""
    try:
        return fn(item) if shared is None else fn(shared, item)
    except Exception as err:
        return Failed.of(err)


class Executor(Protocol):
    """Runs tasks and returns each one's evidence, in task order, on `workers` processes; maps a
    picklable module-level function over items, results in item order (a raising call is Failed).
    With `shared`, each call is fn(shared, item) and shared reaches each worker once (the closed
    loops: tens of megabytes each, not to be sent with every item)."""

    workers: int

    def run(self, prims: dict[str, CompiledPrimitive], settings: OracleSettings, tasks: list[Task],
            progress: Progress | None = None) -> list[list[OracleEvidence]]: ...

    def map(self, fn: Callable[..., Any], items: list, progress: Progress | None = None,
            label: str = "tasks", shared: Any = None) -> list: ...
