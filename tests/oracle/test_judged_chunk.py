"""The judge inside the compiled chunk (oracle/judged.py) decides every rollout as the Python judge
(oracle/verdict.py) does on the rollout's full sample array: the same verdict and the same
evidence, every number bit for bit, whatever the rollout's neighbours in its batch."""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.compile.primitive import INACTIVE
from mpgspec.oracle.integrator import Rows
from mpgspec.oracle.judged import JudgedChunk, Layout, decided_evidence, judge_step
from mpgspec.oracle.verdict import AFTER_DOUBT, DOUBT, DOUBT_E, Block, Carry, evidences, judge, lane_sum
from mpgspec.spec.loader import load_project
from verifiers.rk4 import RK4Runner, _non_finite

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
    if overrides.get("dt") == 0.05:  # doubts, each followed by a certain violation
        assert any(e.message.startswith(AFTER_DOUBT) for e in ours)
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


SPAN = 0.06
"""Step doubling's envelope decays over 6 of the made-up 0.01 s steps (verdict.ENVELOPE_STEPS)."""


def _synthetic(n: int, steps: int, doubling: bool, rng) -> np.ndarray:
    """Per-step outputs (Rows order, nh = 2, nu = 1) of n made-up rollouts, built to hit every rule:
    margins and safety functions that wander across their error bands, shortened steps, inactive
    windows, inputs past their bounds and NaN or inf here and there."""
    rows = Rows(2, 1, doubling=doubling)
    O = np.zeros((rows.ds.stop if doubling else rows.u.stop, n, steps))
    walk = lambda scale, start: start + np.cumsum(rng.normal(0, scale, (n, steps)), axis=1)  # noqa: E731
    O[rows.h] = np.stack([walk(0.02, rng.uniform(0.02, 0.3, (n, 1))), walk(0.02, rng.uniform(0.02, 0.3, (n, 1)))])
    O[rows.h.start + 1, :, 10:30] = INACTIVE  # a window that is closed for a while
    O[rows.lb] = O[rows.h] - rng.uniform(0, 0.02, (2, n, steps))
    O[rows.dh] = rng.uniform(0, 2e-3, (2, n, steps))
    O[rows.margin] = walk(0.02, rng.uniform(-0.4, -0.05, (n, 1)))
    O[rows.err] = rng.uniform(0, 2e-2 if doubling else 4e-3, (n, steps))  # absolute under doubling
    O[rows.dt] = np.where(rng.random((n, steps)) < 0.1, 0.004, 0.01)
    O[rows.s] = np.cumsum(O[rows.dt], axis=1) - O[rows.dt]
    O[rows.u_raw] = rng.normal(0, 1.5, (1, n, steps))
    O[rows.u] = np.clip(O[rows.u_raw], -2, 2)
    if doubling:
        O[rows.ds] = rng.uniform(0, 4e-3, (2, n, steps))
    O[rows.margin, :3, 0], O[rows.h.start, :3, 0] = 0.005, -0.5  # inside E and outside C at switch-in: left C
    O[rows.margin, 3:9, 0], O[rows.h.start, 6:9, 0] = -0.0, -0.0  # signed zeros must come out as they went in
    for r in rng.choice(n, n // 6, replace=False):  # a NaN or an inf in some row at some step
        O[rng.integers(O.shape[0]), r, rng.integers(steps)] = rng.choice([np.nan, np.inf, -np.inf])
    return O


def _python_judge(O, T, B, tol, cm, lo, hi, prim, doubling):
    """verdict.judge over blocks of B steps of the full sample array, as RK4Runner(judged=False)."""
    rows, (_, n, steps) = Rows(2, 1, doubling=doubling), O.shape
    out, alive, carry = [None] * n, np.arange(n), Carry(2, 1, n)
    for j0 in range(0, steps, B):
        b = O[:, alive, j0:j0 + B]
        blk = Block(b[rows.h], b[rows.lb], b[rows.dh], b[rows.margin], b[rows.err], b[rows.s], b[rows.dt],
                    b[rows.u_raw], b[rows.u], np.isfinite(b).all(axis=0), b[rows.ds] if doubling else None, SPAN)
        d = judge(blk, carry, T[alive], tol, cm, lo, hi)
        done = np.flatnonzero(d.done)
        msgs = {int(i): _non_finite(b[:, i, int(d.k[i])], rows, False) for i in done if d.kind[i] == "non_finite"}
        for i, ev in zip(alive[done], evidences(prim, blk, carry, d, done, np.zeros(done.size), cm, msgs)):
            out[i] = ev
        carry.keep(~d.done)
        alive = alive[~d.done]
    assert not alive.size, "the made-up rollouts must all be decided"
    return out


def _compiled_judge(O, T, K, B, tol, cm, lo, hi, prim, doubling):
    """The judged chunk's steps (judge_step, K per chunk) over the same outputs; evidence from J."""
    rows, (n_out, n, steps) = Rows(2, 1, doubling=doubling), O.shape
    lay = Layout(2, 1, 1)
    fns = [judge_step(lay, rows, n_out, K, first, B, tol, cm, lo, hi, SPAN) for first in (True, False)]
    J = lay.start(T)
    for j in range(steps):
        zend, k = np.zeros((1, n)), j % K  # the end state is finite
        J = np.hstack([np.array(fns[k > 0](J[:, i], O[:, i, j], zend[:, i], float(k == K - 1))) for i in range(n)])
    ch = JudgedChunk(prim, 0.01, None, 1, lay, K, doubling)
    assert (J[lay.slice("done")] > 0.5).all()
    return decided_evidence(ch, J, np.zeros(n), cm)


@pytest.mark.parametrize("doubling", [False, True])
def test_the_judge_step_agrees_with_the_judge_on_made_up_outputs(doubling):
    """Every rule of the judge (doubts at samples and over steps, a doubtful step decided by the next
    sample within a block or across one, E perhaps entered, horizons inside blocks, non-finite
    outputs), compared with verdict.judge on the full sample array, every evidence field bit for bit."""
    rng = np.random.default_rng(11)
    n, steps, B, K = 60, 96, 16, 8
    O = _synthetic(n, steps, doubling, rng)
    T = np.where(rng.random(n) < 0.3, rng.uniform(0.05, 0.5, n), 0.8)
    prim = SimpleNamespace(h_names=["a", "b"], windows=[None, None], period=None)
    lo, hi, tol, cm = np.array([-2.0]), np.array([2.0]), 0.01, 1.5
    ours = _compiled_judge(O, T, K, B, tol, cm, lo, hi, prim, doubling)
    theirs = _python_judge(O, T, B, tol, cm, lo, hi, prim, doubling)
    _same(ours, theirs)
    messages = {e.message[:12] for e in ours}
    reasons = {e.reason.value for e in ours}
    assert {"entered_E", "left_C", "integration_failed", "horizon_reached", "inconclusive"} <= reasons
    assert {DOUBT[:12], DOUBT_E[:12]} <= messages
