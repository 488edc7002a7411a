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


def test_every_kind_of_argument_reads_as_function_call_reads_it():
    """Floats, NumPy scalars, vectors (also strided, integer, a column, a list) and scalars spread over a
    vector: copied as given where they are already doubles, converted otherwise; the same bits."""
    x, t = ca.SX.sym("x", 3), ca.SX.sym("t")
    f = ca.Function("g", [x, t], [ca.vertcat(x[0] * t, ca.cos(x[1]) - x[2], t * t)])
    g = numeric(f)
    base = np.array([0.3, -1.7, 2.5, 9.0, 4.25, -0.5])
    for a, b in [(base[:3], 0.7), (base[::2], np.float64(0.7)), (base[:3].reshape(3, 1), np.array(0.7)),
                 (np.array([1, 2, 3]), 2), ([0.1, 0.2, 0.3], [1.5]), (2.0, 0.25)]:
        ref = np.asarray(f(np.broadcast_to(np.asarray(a, float).ravel(), 3), np.asarray(b, float)).full()).ravel()
        assert np.array_equal(g(a, b)[0], ref), (a, b)
    try:
        g(np.zeros(4), 1.0)
    except ValueError:
        pass
    else:
        raise AssertionError("a vector of the wrong length was accepted")


def test_content_hash_is_the_serializations_and_computed_once_per_function():
    import hashlib

    from mpgspec.compile import numeric
    x = ca.SX.sym("x")
    f, g = ca.Function("f", [x], [ca.sin(x)]), ca.Function("f", [x], [ca.cos(x)])
    assert numeric.content_hash(f) == hashlib.sha256(f.serialize().encode()).hexdigest()
    assert numeric.content_hash(g) != numeric.content_hash(f)
    assert numeric.content_hash(ca.Function("f", [x], [ca.sin(x)])) == numeric.content_hash(f)  # by content
    calls = []
    real = ca.Function.serialize
    try:
        ca.Function.serialize = lambda self, *a: calls.append(1) or real(self, *a)
        numeric.content_hash(f)
    finally:
        ca.Function.serialize = real
    assert calls == []  # remembered for this object


def test_by_column_runs_a_failed_batch_column_by_column():
    """A batch whose call raises is run one column at a time: a failing column is NaN in every output and
    named, the others get what they get alone; when every column fails there are no outputs."""
    from mpgspec.compile.numeric import by_column

    def fn(x, y):
        if (x[0] < 0).any():
            raise RuntimeError("Evaluation failed")
        return x * 2, (x + y).sum(axis=0)

    x, y = np.array([[1.0, -1.0, 3.0], [4.0, 5.0, 6.0]]), np.ones((2, 3))
    outs, failed = by_column(fn, [x[:, [0, 2]], y[:, [0, 2]]])
    assert failed == [] and outs[0].tolist() == [[2.0, 6.0], [8.0, 12.0]] and outs[1].tolist() == [[7.0, 11.0]]
    outs, failed = by_column(fn, [x, y])
    assert failed == [1]
    assert np.isnan(outs[0][:, 1]).all() and np.isnan(outs[1][0, 1])
    assert outs[0][:, [0, 2]].tolist() == [[2.0, 6.0], [8.0, 12.0]] and outs[1][0, [0, 2]].tolist() == [7.0, 11.0]
    assert by_column(fn, [x[:, [1]], y[:, [1]]]) == (None, [0])
