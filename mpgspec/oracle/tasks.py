"""What an executor runs: tasks of (target primitive, batch of start points), and the Executor contract.

Executors (executors.py) run the tasks where the oracle calls go; the result cache (cache.py)
wraps any executor and hands it only the start points it has not stored.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..settings import OracleSettings
from .evidence import OracleEvidence

Progress = Callable[[str, int, int], None]


@dataclass
class Task:
    """Start points (rows of x0s, clocks t0s) of one target primitive."""

    target: str
    x0s: np.ndarray
    t0s: np.ndarray

    def __len__(self) -> int:
        return len(self.t0s)


class Executor(Protocol):
    """Runs tasks and returns each one's evidence, in task order, on `workers` processes."""

    workers: int

    def run(self, prims: dict[str, CompiledPrimitive], settings: OracleSettings, tasks: list[Task],
            progress: Progress | None = None) -> list[list[OracleEvidence]]: ...


