"""Run oracle batches of several targets in worker processes.

Compiled CasADi functions do not cross process boundaries, so each worker rebuilds the primitives
once from a picklable factory (for example: load this project file and compile it) and then
serves batches by target name. The same job list runs serially in-process when workers == 1.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from typing import Callable

import numpy as np

from ..settings import OracleSettings
from .evidence import OracleEvidence, Reason
from .oracle import SafetyOracle

Job = tuple[str, np.ndarray, np.ndarray]

_worker: dict = {}


def _init(factory: Callable[[], dict], settings: OracleSettings) -> None:
    _worker["prims"] = factory()
    _worker["settings"] = settings
    _worker["oracles"] = {}


def _run(job: Job) -> list[OracleEvidence]:
    name, x0s, t0s = job
    oracles = _worker["oracles"]
    try:
        if name not in oracles:
            oracles[name] = SafetyOracle(_worker["prims"][name], _worker["settings"])
        return oracles[name].evaluate(x0s, t0s)
    except Exception as err:  # the batch's evidence, not the end of the run
        return [OracleEvidence(0, Reason.ERROR, 0.0, message=str(err)[:500])] * len(t0s)


def run_jobs(jobs: list[Job], factory: Callable[[], dict], settings: OracleSettings, workers: int) -> list:
    """Evidence lists for each (target, x0s, t0s) job, in order, using `workers` processes."""
    with ProcessPoolExecutor(max_workers=workers, initializer=_init, initargs=(factory, settings)) as pool:
        return list(pool.map(_run, jobs))
