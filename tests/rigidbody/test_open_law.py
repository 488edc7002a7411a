"""The cross-check's law under a sensing error: h at the simulator's state under the input the law
asked from the sensed state. The no-slip rows must be the ground forces of that input, as the robust
stage's perturbed plant (a second model of the same dynamics, at nominal mass and no push) gives them,
not the forces of the input the law would ask at the true state."""
import numpy as np
import pytest

from mpgspec.compile.rigidbody.system import no_slip
from mpgspec.execute.crosscheck.replay import _evaluate, _Law
from mpgspec.robust.rigid import no_slip_rows, robust_plant


def _sensed(prim, x, dv: float):
    """x with every velocity read dv off (the base's and the joints': as a state read late gives it)."""
    nq, nv = prim.system.model.nq, prim.system.model.nv
    seen = x.copy()
    seen[nq:nq + nv] += dv
    return seen


@pytest.mark.parametrize("name, clock", [("Lie", 0.0), ("Walk(fast)", 0.01), ("Walk(fast)", 0.1)])
def test_a_law_reading_a_sensed_state_is_judged_under_the_input_it_applies(a1, a1_pd_lie, name, clock):
    prim = (a1_pd_lie if name == "Lie" else a1)[1][name]  # Lie under the paper's joint PD: a continuous law
    assert prim.sampled is None and prim.open_loop is not None
    x = np.asarray(prim.x_star(clock), float).ravel()
    seen = _sensed(prim, x, 0.3)
    law = _Law(prim, 1000.0, {})
    hv, u = law(x, clock, 0.5, x, seen)
    h_true, u_true = _evaluate(prim, x, clock, 0.5, x)
    assert np.array_equal(u, _evaluate(prim, seen, clock, 0.5, x)[1])  # the input asked from the sensed state
    assert np.abs(u - u_true).max() > 0.1  # ... which is not the one asked at x
    rows = no_slip_rows(prim)
    assert rows
    xdot, lam, c = robust_plant(prim, "trunk")(x, u, 1.0, np.zeros(3), clock)
    lam, c = np.asarray(lam, float).ravel(), np.asarray(c, float).ravel()
    moved = 0.0
    for j, (i, kind) in rows.items():
        if prim.contacts.varies and c[i] < 0.5:
            continue  # a swing foot: its rows are not active here
        want = float(no_slip(lam[3 * i], lam[3 * i + 1], lam[3 * i + 2], float(prim.system.friction))[kind])
        assert hv[j] == pytest.approx(want, rel=1e-7, abs=1e-7), prim.h_names[j]
        moved = max(moved, abs(hv[j] - h_true[j]))
    assert moved > 1e-3  # the applied input's ground forces differ from those of the input asked at x
    # the rows that do not read the input are the closed loop's at x
    same = [j for j in range(len(hv)) if j not in rows]
    assert np.allclose(hv[same], h_true[same], rtol=1e-12, atol=1e-12)
    # read exactly, the law is judged as before
    h0, u0 = law(x, clock, 0.5, x, None)
    assert np.array_equal(h0, h_true) and np.array_equal(u0, u_true)
