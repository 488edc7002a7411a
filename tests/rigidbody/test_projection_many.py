"""The batched projection onto the contact manifold: every row gets the state it gets alone, also
rows far from the manifold that need many Gauss-Newton steps, mixed with rows already on it."""
from __future__ import annotations

import numpy as np

FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


def _points(p, radii, n, seed):
    W = np.asarray(p.info["roa_W"])
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, L.shape[1]))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d *= rng.choice(radii, size=n)[:, None]
    return W, p.x_star(0.0) + d @ L.T


def test_rows_project_as_they_do_alone(a1):
    _, prims, _ = a1
    p = prims["Stand"]
    sys = p.system
    W, X = _points(p, [0.0, 0.01, 0.1, 0.4, 0.8], 40, seed=5)
    for feet in (FEET, ("FL_foot", "RR_foot"), ()):
        many = sys.project_to_contacts_many(X, feet, W)
        alone = np.array([sys.project_to_contacts(x, feet, W) for x in X])
        assert np.array_equal(many, alone, equal_nan=True)
        assert np.array_equal(sys.project_to_contacts_many(X[::-1], feet, W), many[::-1], equal_nan=True)


def test_far_rows_take_many_steps_and_reach_the_manifold(a1):
    _, prims, _ = a1
    p = prims["Stand"]
    sys = p.system
    W, X = _points(p, [0.0, 0.8], 24, seed=6)
    full = sys.project_to_contacts_many(X, FEET, W)
    few = sys.project_to_contacts_many(X, FEET, W, max_iter=3)
    far = ~np.all(full == few, axis=1)
    assert 0 < far.sum() < len(X)  # some rows need more than 3 steps, the points at x* none
    for k in np.flatnonzero(far):  # stopping early gives the row's own early state
        assert np.array_equal(few[k], sys.project_to_contacts(X[k], FEET, W, max_iter=3))
    heights = sys._projection.kinematics(full[:, :sys.model.nq])[0]
    assert np.abs(heights[np.isfinite(heights).all(axis=1)]).max() < 1e-10
