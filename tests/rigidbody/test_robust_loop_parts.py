"""The robust steps call the primitive's loop library (the sampled law's solve, the control law with its
reverse derivative, a large RoA margin) instead of compiling them again: rollouts and push gradients
equal, bit for bit, those of steps with every part inlined."""
import numpy as np
import pytest

from mpgspec.oracle import looplib
from mpgspec.robust import rigid
from mpgspec.robust.rigid import RigidRobustRollout, library_for, loop_parts

NAMES = ["mass_scale", "friction"]


def _rollouts(prim, settings, inline: bool, monkeypatch):
    with monkeypatch.context() as m:
        if inline:
            m.setattr(rigid, "loop_parts", lambda p, lib, reverse: ({}, ()))
        return RigidRobustRollout(prim, NAMES, "trunk", True, 4, settings, 0.05, 0.04)


@pytest.mark.parametrize("name, kinds", [("Walk(slow)", {"control"}), ("Stand", {"solve"}),
                                         ("Jump", {"control"})])
def test_steps_through_the_loop_library_equal_the_inlined_ones(a1, monkeypatch, name, kinds):
    """Walk(slow): the trot law and its derivative; Stand: the sampled ID-QP's solve; Jump: the jump law."""
    _, prims, settings = a1
    prim = prims[name]
    called, paths = loop_parts(prim, library_for(prim, settings), prim.sampled is None)
    assert kinds <= set(called)
    assert prim.sampled is not None or "roa_margin" not in called  # no reverse derivative in its unit
    assert set(paths) >= set(looplib.attach(prim).paths)
    rr, rr0 = _rollouts(prim, settings, False, monkeypatch), _rollouts(prim, settings, True, monkeypatch)
    assert set(paths) - set(rr0.libs) and rr.libs[-1] != rr0.libs[-1]  # a step library of its own
    rng = np.random.default_rng(2)
    n = 3
    X0 = np.tile(prim.system.default_state(), (n, 1)) + 0.01 * rng.standard_normal((n, prim.system.nx))
    TH = np.column_stack([rng.uniform(0.9, 1.1, n), rng.uniform(0.4, 0.8, n)])
    D = rng.uniform(-7.5, 7.5, (n, 3, rr.K))
    T0 = rng.uniform(0, 0.3, n)
    Y, last = rr.run(X0, T0, TH, D, np.full(n, rr.N), tol=1e9, until_entry=False)
    Y0, last0 = rr0.run(X0, T0, TH, D, np.full(n, rr.N), tol=1e9, until_entry=False)
    np.testing.assert_array_equal(Y, Y0)
    np.testing.assert_array_equal(last, last0)
    if rr0.grad is not None:
        args = (X0, T0, TH, D, [0, 3, 5], [rr.N, rr.N - 1, 2])
        g = rr.gradients(*args)
        assert np.abs(g).max() > 0
        np.testing.assert_array_equal(g, rr0.gradients(*args))
