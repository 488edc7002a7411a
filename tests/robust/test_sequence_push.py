"""The disturbance of the uncertain goal sequence: a push with a duration is the one the robust cells
withstand, on for that long after every switch-in, a fresh draw each time; a disturbance without one
is on throughout."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from mpgspec.robust.sequence import HOLD, PUSHES, DisturbedSequences, push_window
from mpgspec.spec.project import Uncertainty

RUNS = 5


def _draws(force: dict | None = None, inputs: bool = False, seed: int = 3, cols=None) -> DisturbedSequences:
    """The seeded draws of RUNS runs (of the runs `cols` only, when given) of a 6 s sequence."""
    dist = {"force": force, "segments": 4} if force else {"inputs": ["tau"], "bound": 0.3} if inputs else None
    unc = Uncertainty(parameters={"mass_scale": {"range": [0.9, 1.1]}}, disturbance=dist)
    prims = {"A": SimpleNamespace(system=SimpleNamespace(nx=2, state_names=["q", "v"]))}
    nd, bound = (3, force["bound"]) if force else (1, [0.3])
    return DisturbedSequences(prims, {"A": SimpleNamespace(nz=6)}, ["mass_scale"], nd, bound, unc,
                              SimpleNamespace(dt=0.001), SimpleNamespace(duration=6.0), RUNS, seed, cols)


PUSH = {"frame": "trunk", "bound": [7.5, 5.0, 0.0], "duration": 0.2}


def test_a_push_acts_for_its_duration_after_each_switch_in_only():
    ds = _draws(PUSH)
    assert (ds.window, ds.hold) == (0.2, 0.05)
    since = np.array([0.0, 0.0, 1.0, 1.0, 2.5])
    pushes = np.array([0, 0, 1, 2, 3])
    for t in np.arange(0.0, 3.0, 0.01):
        d = ds.disturbance(t, since, pushes)
        for r in range(RUNS):
            s = t - since[r]
            if 0 <= s < 0.2 - 1e-9:
                assert np.array_equal(d[:, r], ds.dist[pushes[r], int(s / 0.05 + 1e-9), :, r])
                assert np.all(np.abs(d[:, r]) <= [7.5, 5.0, 0.0]) and np.any(d[:, r] != 0)
            else:
                assert not d[:, r].any(), (t, r)
    # the same run's next switch-in draws a new push, its k-th switch-in the k-th draw
    d1 = ds.disturbance(1.0, since, pushes)
    d2 = ds.disturbance(1.0, since, pushes + 1)
    assert not np.array_equal(d1[:, 2], d2[:, 2])
    assert np.array_equal(ds.disturbance(1.0, since, pushes + PUSHES), d1)


def test_the_draws_of_a_block_of_runs_are_those_of_the_whole():
    whole = _draws(PUSH)
    cols = [1, 3]
    part = _draws(PUSH, cols=cols)
    assert np.array_equal(part.theta, whole.theta[:, cols]) and np.array_equal(part.dist, whole.dist[..., cols])


def test_a_disturbance_without_a_duration_is_on_throughout():
    for ds in (_draws({**PUSH, "duration": None}), _draws(inputs=True)):
        assert ds.window is None and ds.hold == HOLD
        zero = np.zeros(RUNS)
        for t in (0.0, 0.3, 2.0, 5.9):
            d = ds.disturbance(t, zero + t, zero.astype(int))  # switch-ins do not matter
            assert np.array_equal(d, ds.dist[int(t / HOLD)]) and np.all(d[:2] != 0)
    unc = Uncertainty(disturbance={"force": PUSH, "segments": 8})
    assert push_window(unc) == (0.2, 0.025) and push_window(Uncertainty()) == (None, HOLD)
