"""The robust steps call the primitive's loop library (the sampled law's solve; a large RoA margin
where no gradient goes through the step: the forward step, never its reverse-derivative twin)
instead of compiling them again: rollouts and push gradients equal, bit for bit, those of steps with
every part inlined."""
import numpy as np
import pytest

from mpgspec.oracle import looplib
from mpgspec.robust import rigid
from mpgspec.robust.rigid import RigidRobustRollout, library_for, loop_parts

NAMES = ["mass_scale", "friction"]


def _rollouts(prim, settings, inline: bool, gradient: bool, monkeypatch):
    with monkeypatch.context() as m:
        if inline:  # every part inlined, its step library compiled unoptimised (the same bits, less gcc)
            m.setattr(rigid, "loop_parts", lambda p, lib, reverse: ({}, ()))
            m.setattr(rigid, "STEP_FLAGS", ("-O0",))
        return RigidRobustRollout(prim, NAMES, "trunk", True, 4, settings, 0.05, 0.04, gradient=gradient)


@pytest.mark.parametrize("name, gradient, kinds", [("Stand", True, {"solve"}), ("Walk(slow)", True, {"roa_margin"})])
def test_steps_through_the_loop_library_equal_the_inlined_ones(a1, monkeypatch, name, gradient, kinds):
    """Stand: the sampled ID-QP's solve (no gradient through a held input); Walk(slow): its RoA margin
    (a gait table's setpoint) in the rollouts' step, inlined in the step its push gradient goes through."""
    _, prims, settings = a1
    prim = prims[name]
    called, paths = loop_parts(prim, library_for(prim, settings), False)
    assert set(called) == kinds
    assert set(paths) == set(looplib.attach(prim).paths)
    rr = _rollouts(prim, settings, False, gradient, monkeypatch)
    rr0 = _rollouts(prim, settings, True, gradient, monkeypatch)
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
    assert rr.searchable == (prim.sampled is None) and rr.__dict__.get("grad") is None  # built on first use
    if rr0.grad is not None:
        args = (X0, T0, TH, D, [0, 3, 5], [rr.N, rr.N - 1, 2])
        g = rr.gradients(*args)
        assert np.abs(g).max() > 0
        np.testing.assert_array_equal(g, rr0.gradients(*args))


def test_a_gradient_step_calls_no_part_without_a_reverse_derivative(a1):
    """With a push gradient through it, a walk's step keeps its RoA margin inlined (the margin's unit
    has no reverse derivative); Stand takes no gradient (its input is held) and calls its solve."""
    _, prims, settings = a1
    walk, stand = prims["Walk(slow)"], prims["Stand"]
    assert loop_parts(walk, library_for(walk, settings), True) == ({}, ())
    assert loop_parts(walk, None, False) == ({}, ())  # no robot library: every part inlined
    assert set(loop_parts(stand, library_for(stand, settings), False)[0]) == {"solve"}
