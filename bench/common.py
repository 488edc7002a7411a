"""Helpers shared by the benchmarks: interleaved timing rounds, median ratios, machine facts."""
from __future__ import annotations

import os
import platform
import statistics
import time
from pathlib import Path


def rounds(fns: dict, repeats: int) -> dict[str, list[float]]:
    """Wall times of every fn, interleaved: `repeats` rounds that each run all of them once, so
    that load from other processes hits all measurements alike and per-round ratios stay fair."""
    out = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t = time.perf_counter()
            fn()
            out[k].append(time.perf_counter() - t)
    return out


def med_ratio(a: list[float], b: list[float]) -> float:
    """Median over rounds of a/b."""
    return statistics.median(x / y for x, y in zip(a, b))


def machine(**versions: str) -> dict:
    """CPU count and model, Python and the given package versions."""
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        avail = len(os.sched_getaffinity(0))
    except AttributeError:
        avail = os.cpu_count()
    return {"nproc": avail, "cpu": cpu or platform.processor() or platform.machine(),
            "python": platform.python_version(), **versions, "platform": platform.platform()}
