"""The judge inside the compiled chunk (oracle/judged.py) decides every rollout as the Python judge
(oracle/verdict.py) does on the rollout's full sample array: the same verdict and the same
evidence, every number bit for bit, whatever the rollout's neighbours in its batch."""
from pathlib import Path

import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.oracle.verdict import lane_sum
from mpgspec.spec.loader import load_project
from verifiers.rk4 import RK4Runner

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def pendulum():
    spec = load_project(ROOT / "specs" / "pendulum" / "project.yaml")
    return spec, compile_project(spec)


def _all_in_chunks(runner: RK4Runner) -> RK4Runner:
    """No first-sample shortcut: rollouts decided at their first sample are judged in the chunks too."""
    runner._first = lambda Z, T, t0s, results: np.arange(Z.shape[1])
    return runner


def _both(prim, settings, x0s, t0s, T):
    judged = _all_in_chunks(RK4Runner(prim, settings, judged=True))
    python = _all_in_chunks(RK4Runner(prim, settings, judged=False))
    assert judged.judged and not python.judged
    return judged.evaluate(x0s, t0s, T), python.evaluate(x0s, t0s, T)


def _starts(prim, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Start points around the orbit, some far off, some with velocities that blow the rollout up."""
    t0s = rng.uniform(0, prim.period or 1.0, n)
    x0s = np.array([np.asarray(prim.x_star(t), float) for t in t0s])
    x0s += rng.normal(0, 1, x0s.shape) * rng.choice([0.01, 0.1, 0.5, 1.5], (n, 1))
    x0s[::7, 1] = 1e155  # squared in the dynamics: inf, then NaN
    x0s[3::11, 0] = np.nan
    return x0s, t0s


def _same(a, b) -> None:
    for i, (x, y) in enumerate(zip(a, b)):
        assert repr(x.to_dict()) == repr(y.to_dict()), f"rollout {i}"


@pytest.mark.parametrize("overrides", [
    {"refinements": 0},  # the project's steps, 64-step blocks
    {"refinements": 0, "dt": 0.05, "chunk": 16},  # coarse steps: doubts, pending steps across blocks
    {"refinements": 0, "dt": 0.05, "error": "doubling"},  # absolute estimates from a companion rollout
])
def test_the_judge_in_the_chunk_agrees_with_the_python_judge_bit_for_bit(pendulum, overrides):
    spec, prims = pendulum
    settings = settings_for(spec, overrides)
    prim = prims["Swing(2.6)"]
    x0s, t0s = _starts(prim, 120, np.random.default_rng(3))
    T = np.where(np.arange(len(t0s)) % 5 == 0, 0.4123, 6.0)  # some horizons end inside a block
    ours, theirs = _both(prim, settings, x0s, t0s, T)
    _same(ours, theirs)
    reasons = {e.reason.value for e in ours}
    assert {"entered_E", "left_C", "integration_failed", "horizon_reached"} <= reasons
    assert any(e.steps == 0 for e in ours)  # decided at the first sample, inside a chunk
    if overrides.get("dt") == 0.05:
        assert any(e.status == "inconclusive" for e in ours)
        assert any(e.entry_error for e in ours)


def test_a_rollout_is_judged_alone_whatever_its_batch(pendulum):
    """Alone or among others, a rollout's evidence is the same: the error sums fold per rollout."""
    spec, prims = pendulum
    settings = settings_for(spec, {"refinements": 0})
    prim = prims["Swing(2.6)"]
    x0s, t0s = _starts(prim, 24, np.random.default_rng(5))
    T = np.full(len(t0s), 6.0)
    batch = RK4Runner(prim, settings).evaluate(x0s, t0s, T)
    runner = RK4Runner(prim, settings)
    for i in range(0, len(t0s), 5):
        _same([batch[i]], runner.evaluate(x0s[i:i + 1], t0s[i:i + 1], T[i:i + 1]))


def test_lane_sum_is_numpys_sum_for_whole_blocks_and_lanes_otherwise():
    a = np.random.default_rng(0).random((3, 64)) * 1e-6
    assert (lane_sum(a) == a.sum(axis=1)).all()
    b = a[:, :13]
    lanes = np.zeros((3, 8))
    for k in range(13):
        lanes[:, k % 8] += b[:, k]
    want = ((lanes[:, 0] + lanes[:, 1]) + (lanes[:, 2] + lanes[:, 3])) + ((lanes[:, 4] + lanes[:, 5]) + (lanes[:, 6] + lanes[:, 7]))
    assert (lane_sum(b) == want).all()
