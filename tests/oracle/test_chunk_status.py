"""A compiled rollout whose evaluation reports an error (a failed QP inside a law, say) must not hand
back the numbers of the call before it."""
import casadi as ca
import numpy as np
import pytest

from mpgspec.oracle.integrator import Chunk, Rows


class _Failing:
    """Wraps a FunctionBuffer and reports a non-zero status, as a failed compiled evaluation does."""

    def __init__(self, buf):
        self.buf = buf

    def ret(self):
        return 1


def test_a_failed_evaluation_raises_instead_of_returning_stale_outputs():
    z = ca.MX.sym("z", 2)
    fn = ca.Function("chunk", [z], [z + 1, ca.repmat(z[0], 1, 3)])
    ch = Chunk(prim=None, dt=0.1, K=3, fn=fn, nh=0, nu=0, rows=Rows(0, 0))
    zf, out = ch.run(np.array([[1.0], [2.0]]))
    assert zf[:, 0].tolist() == [2.0, 3.0]
    buf, *rest = ch._buffers[1]
    ch._buffers[1] = (_Failing(buf), *rest)
    with pytest.raises(RuntimeError, match="failed"):
        ch.run(np.array([[5.0], [6.0]]))
    assert np.isnan(rest[2]).all()  # the bound output buffer no longer holds the previous call


def test_a_crash_is_the_evidence_of_the_call_that_crashes_not_of_its_batch():
    """A batch whose compiled call fails is run again one call at a time: only the call that fails
    gets error evidence, the others the verdicts they get alone."""
    from pathlib import Path

    from mpgspec.api import compile_project, settings_for
    from mpgspec.oracle import SafetyOracle
    from mpgspec.spec.loader import load_project

    spec = load_project(Path(__file__).parents[2] / "specs" / "pendulum" / "project.yaml")
    prims = compile_project(spec)
    settings = settings_for(spec, {"jit": False})
    target = prims["Balance"]
    x_star = target.x_star(0.0)
    x0s = np.array([x_star + [0.5, 0.1], x_star + [0.6, 0.0], x_star + [0.712345, 0.0]])
    oracle = SafetyOracle(target, settings)
    alone = [oracle(x, 0.0) for x in x0s[:2]]
    assert all(a.t_stop > 0 for a in alone)  # judged in the compiled chunks, not at the first sample
    run = oracle.runner.chunk.run

    def crash_on_marker(Z):
        if np.any(np.isclose(Z[0], x_star[0] + 0.712345)):
            raise RuntimeError("the compiled rollout failed (status 1)")
        return run(Z)

    oracle.runner.chunk.run = crash_on_marker
    ev = oracle.evaluate(x0s, np.zeros(3))
    assert [e.status for e in ev[:2]] == [a.status for a in alone]
    assert [e.t_stop for e in ev[:2]] == pytest.approx([a.t_stop for a in alone])
    assert ev[2].status == "inconclusive" and ev[2].reason.value == "error" and "failed" in ev[2].message


def _pendulum_balance():
    from pathlib import Path

    from mpgspec.api import compile_project, settings_for
    from mpgspec.oracle import SafetyOracle
    from mpgspec.spec.loader import load_project

    spec = load_project(Path(__file__).parents[2] / "specs" / "pendulum" / "project.yaml")
    target = compile_project(spec)["Balance"]
    x_star = target.x_star(0.0)
    x0s = np.array([x_star + [0.5, 0.1], x_star + [0.6, 0.0], x_star + [0.55, -0.05]])
    return SafetyOracle(target, settings_for(spec, {"jit": False})), x0s


def test_a_batch_that_fails_after_its_first_chunk_runs_again_from_where_it_stood():
    """A judged chunk hands back a view of its output buffer, which the next call's input then is. When
    that call's evaluation fails, the calls run again alone must start from the states it was given, not
    from what the failure left in the buffer: each gets the verdict it gets alone."""
    oracle, x0s = _pendulum_balance()
    alone = [oracle(x, 0.0) for x in x0s]
    ch = oracle.runner.chunk
    assert min(a.t_stop for a in alone) > 2 * ch.K * oracle.runner.dt  # still running at the second chunk
    run, calls = ch.run, []

    def second_batch_call_fails(Z):
        calls.append(Z.shape[1])
        if Z.shape[1] == 3 and calls.count(3) == 2:
            buf, *rest = ch._bound(3)
            ch._buffers[3] = (_Failing(buf), *rest)  # the real call, reporting the status of a failed one
            try:
                return run(Z)
            finally:
                ch._buffers[3] = (buf, *rest)
        return run(Z)

    ch.run = second_batch_call_fails
    ev = oracle.evaluate(x0s, np.zeros(3))
    assert calls[:5] == [3, 3, 1, 1, 1]  # the batch failed at its second chunk, then ran alone
    assert [e.status for e in ev] == [a.status for a in alone]
    assert [e.t_stop for e in ev] == pytest.approx([a.t_stop for a in alone])


def test_a_rollout_decided_on_a_non_finite_judge_is_an_error_of_its_own():
    """A call whose compiled chunk reports success but leaves its decision NaN (what a failed inner
    evaluation can leave) gets error evidence; the other calls of its batch keep their verdicts."""
    oracle, x0s = _pendulum_balance()
    alone = [oracle(x, 0.0) for x in x0s[:2]]
    ch = oracle.runner.chunk
    run, lay = ch.run, ch.lay
    kind, done = ch.nz + lay.slice("kind").start, ch.nz + lay.slice("done").start

    def third_left_nan(Z):
        out = run(Z)
        if Z.shape[1] == 3:
            out[kind, 2], out[done, 2] = np.nan, 1.0
        return out

    ch.run = third_left_nan
    ev = oracle.evaluate(x0s, np.zeros(3))
    assert [e.status for e in ev[:2]] == [a.status for a in alone]
    assert [e.t_stop for e in ev[:2]] == pytest.approx([a.t_stop for a in alone])
    assert ev[2].status == "inconclusive" and ev[2].reason.value == "error" and "non-finite" in ev[2].message
