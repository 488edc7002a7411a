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
