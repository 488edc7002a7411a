"""Common-subexpression elimination changes the robust rollout's code, never its numbers."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.oracle import jit
from mpgspec.robust.rollout import RobustRollout, plant
from mpgspec.robust.sequence import _step
from mpgspec.spec.loader import load_project

PEND = Path(__file__).resolve().parents[2] / "specs" / "pendulum" / "project.yaml"


@pytest.fixture(scope="module")
def pendulum():
    spec = load_project(PEND)
    return spec, compile_project(spec), dataclasses.replace(settings_for(spec), jit=False)


def _built(use_cse: bool, spec, prims, st):
    jit.CSE = use_cse
    try:
        P = plant(spec, ["m"])
        rr = RobustRollout(prims["Swing(1)"], P, [0], 4, st, 1.0)
        return rr, _step(prims["Swing(1)"], P, np.ones((1, 1)), st.dt)
    finally:
        jit.CSE = True


def _args(fn, rng):
    return [rng.uniform(-1, 1, fn.size_in(i)) for i in range(fn.n_in())]


def test_cse_keeps_the_robust_functions_outputs(pendulum):
    (plain, step0), (elim, step1) = _built(False, *pendulum), _built(True, *pendulum)
    rng = np.random.default_rng(1)
    pairs = [(plain.first, elim.first), (plain.chunk, elim.chunk), (plain.grad, elim.grad), (step0, step1)]
    for f, g in pairs:
        assert f.name() == g.name()
        for _ in range(5):
            a = _args(f, rng)
            for y0, y1 in zip(f.call(a), g.call(a)):
                assert np.max(np.abs(np.asarray(y0) - np.asarray(y1)), initial=0.0) <= 1e-12
    assert step1.n_instructions() < step0.n_instructions()
