"""Regions of attraction sized on a process pool equal those sized in this process."""
from pathlib import Path

import numpy as np

from mpgspec.api import compile_project
from mpgspec.certify.roa import size_regions
from mpgspec.oracle.executors import ProcessPool
from mpgspec.spec.loader import load_project

CART = Path(__file__).resolve().parents[2] / "specs" / "cart" / "project.yaml"


def _plain(v):
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items() if not (k == "seconds" or "time" in k or k.endswith("_solve_s"))}  # not the timings
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    return v


def test_sizing_on_two_processes_equals_sizing_here():
    """The cart's SOS certificates (sized here: a solver's threads do not survive a fork) and its
    Floquet tube (on a worker): every record (level, radius, message, evidence) is the same
    whichever process sized it."""
    spec = load_project(CART)
    here = size_regions(spec, compile_project(spec))
    seen = []
    pool = size_regions(spec, compile_project(spec), executor=ProcessPool(2),
                        progress=lambda what, i, n: seen.append(what))
    assert set(here) == set(pool)
    for name in here:
        assert _plain(here[name].to_dict()) == _plain(pool[name].to_dict()), name
    assert any("processes" in w for w in seen)
