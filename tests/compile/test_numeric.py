"""NumericFunction: the same numbers as Function.__call__, sparse inputs and outputs, pickling."""
from __future__ import annotations

import pickle

import casadi as ca
import numpy as np

from mpgspec.compile.numeric import numeric


def _f():
    x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 2, 2)
    return ca.Function("f", [x, y], [ca.vertcat(x[0] * y[0, 1], 0, ca.sin(x[2])),
                                     ca.sparsify(ca.SX(ca.DM([[1, 0], [0, 2]]))) * x[1], x[0] + y[1, 0]])


def test_same_bits_as_a_call_with_structural_zeros():
    f, rng = _f(), np.random.default_rng(1)
    g = numeric(f)
    for _ in range(5):
        a, b = rng.normal(size=3), rng.normal(size=(2, 2))
        ref = [np.asarray(o.full()).ravel(order="F") for o in f(a, b)]
        got = g(a, b)
        assert all(np.array_equal(u, v) for u, v in zip(got, ref))
        assert [u.shape for u in got] == [(3,), (4,), (1,)]


def test_results_are_copies_and_it_pickles():
    g = numeric(_f())
    first = g(np.ones(3), np.ones((2, 2)))[0]
    g(np.zeros(3), np.zeros((2, 2)))
    assert first[0] == 1.0  # not overwritten by the next call
    with ca.global_pickle_context():
        blob = pickle.dumps(g)
    with ca.global_unpickle_context():
        h = pickle.loads(blob)
    assert np.array_equal(h(np.ones(3), np.ones((2, 2)))[2], g(np.ones(3), np.ones((2, 2)))[2])
