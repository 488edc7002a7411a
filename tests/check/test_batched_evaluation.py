"""Points evaluated in batches give the bits they get one by one: NumericMap against NumericFunction,
h and f_cl of many points against those of each, and how h is read (active functions, NaN)."""
from __future__ import annotations

import pickle
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.check.evaluate import active_rows, f_cl, f_cl_many, fold_min, h_active, h_many, least
from mpgspec.compile.numeric import numeric, numeric_map
from mpgspec.compile.primitive import INACTIVE
from mpgspec.spec.loader import load_project

PENDULUM = Path(__file__).parents[2] / "specs" / "pendulum" / "project.yaml"


def _f():
    x, t, y = ca.SX.sym("x", 3), ca.SX.sym("t"), ca.SX.sym("y", 2, 2)
    return ca.Function("f", [x, t, y], [ca.vertcat(x[0] * y[0, 1] * t, 0, ca.sin(x[2])),
                                        ca.sparsify(ca.SX(ca.DM([[1, 0], [0, 2]]))) * x[1], x[0] + y[1, 0]])


@pytest.mark.parametrize("n", [1, 2, 13, 64])
def test_map_gives_every_point_its_own_bits(n):
    f, rng = _f(), np.random.default_rng(n)
    one, many = numeric(f), numeric_map(f, shared=(1,))
    X, Y = rng.normal(size=(n, 3)), rng.normal(size=(n, 4))
    got = many(X, 0.7, Y)
    assert [g.shape for g in got] == [(n, 3), (n, 4), (n, 1)]
    for i in range(n):
        ref = one(X[i], 0.7, Y[i].reshape(2, 2, order="F"))
        assert all(np.array_equal(g[i], r) for g, r in zip(got, ref))


def test_map_pickles():
    m = numeric_map(_f(), shared=(1,))
    X, Y = np.ones((3, 3)), np.ones((3, 4))
    with ca.global_pickle_context():
        blob = pickle.dumps(m)
    with ca.global_unpickle_context():
        back = pickle.loads(blob)
    assert np.array_equal(back(X, 2.0, Y)[0], m(X, 2.0, Y)[0])


def test_least_and_fold_min_read_h_as_the_single_point_checks_do():
    V = np.array([[1.0, INACTIVE, -2.0], [np.nan, 3.0, INACTIVE], [INACTIVE, INACTIVE, INACTIVE]])
    assert least(V).tolist() == [-2.0, 3.0, np.inf]  # NaN and INACTIVE are not active
    assert least(np.zeros((2, 0))).tolist() == [np.inf, np.inf]  # no safety functions at all
    assert least(np.array([[-1e300, INACTIVE]])).tolist() == [-1e300]  # far below zero is active, not parked
    assert fold_min(0.5, np.array([np.nan, 0.25, 1.0])) == 0.25
    assert fold_min(0.5, np.array([np.nan])) == 0.5
    with pytest.raises(ValueError):
        active_rows(V)
    assert active_rows(V[:1]).tolist() == [[1.0, -2.0]]


def test_h_of_many_points_is_h_of_each():
    prims = compile_project(load_project(PENDULUM))
    rng = np.random.default_rng(0)
    for p in prims.values():
        ts = np.linspace(*p.t_range, 5) if p.t_range[1] > p.t_range[0] else np.zeros(5)
        X = np.array([p.x_star(t) for t in ts]) + 0.3 * rng.normal(size=(5, len(p.x_star(0.0))))
        V = h_many(p, X, ts)
        for x, t, v in zip(X, ts, V):
            assert np.array_equal(v[v < INACTIVE / 2], h_active(p, x, t))
        assert np.array_equal(h_many(p, X, ts[2]), np.array([h_many(p, x, ts[2])[0] for x in X]))
        assert np.array_equal(f_cl_many(p, X, ts[1]), np.array([f_cl(p, x, ts[1]) for x in X]))
