"""Stacked least squares (the contact projection's Gauss-Newton steps): the same solutions as
np.linalg.lstsq point by point, through NumPy's gufunc and through the per-point fallback."""
import numpy as np
import pytest

from mpgspec.compile.rigidbody import projection
from mpgspec.compile.rigidbody.projection import lstsq_many


@pytest.mark.parametrize("gufunc", [True, False])
def test_stacked_least_squares_equal_numpys_point_by_point(gufunc, monkeypatch):
    if not gufunc:
        monkeypatch.setattr(projection, "_lstsq_gufunc", None)
    rng = np.random.default_rng(0)
    A, b = rng.normal(size=(5, 4, 7)), rng.normal(size=(5, 4))  # underdetermined: the least-norm solution
    A[2, :, 3] = 0.0  # a column that weighs nothing
    want = np.array([np.linalg.lstsq(a, y, rcond=None)[0] for a, y in zip(A, b)])
    got = lstsq_many(A, b)
    assert got.shape == (5, 7) and np.allclose(got, want, rtol=1e-12, atol=1e-12)
    assert lstsq_many(A[:0], b[:0]).shape == (0, 7)
