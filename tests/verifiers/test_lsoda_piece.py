"""The reference backend's LSODA piece is solve_ivp's, bit for bit: the same end time and state, the
same dense solution, status and events, whether the piece reaches its end, stops at an event (in
its direction or either way) or its state turns NaN."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from verifiers.lsoda_piece import lsoda_piece

OPTS = {"rtol": 1e-10, "atol": 1e-12, "max_step": 0.0025}


def _oscillator(t, x):
    return np.array([x[1], -4.0 * x[0] - 0.3 * x[1] + np.sin(3 * t)])


def _event(fn, direction):
    fn.terminal, fn.direction = True, direction
    return fn


CASES = {
    "no event fires": (_oscillator, (0.0, 0.4), [1.0, 0.0], lambda: [_event(lambda t, x: x[0] - 5.0, 1)]),
    "enters upward": (_oscillator, (0.1, 3.0), [1.0, 0.0], lambda: [_event(lambda t, x: x[1] - 0.5, 1)]),
    "downward only": (_oscillator, (0.0, 3.0), [1.0, 0.0],
                      lambda: [_event(lambda t, x: x[1] + 10.0, 1), _event(lambda t, x: x[0] - 0.2, -1)]),
    "either way, second event": (_oscillator, (0.0, 3.0), [0.5, 1.0],
                                 lambda: [_event(lambda t, x: x[0] - 9.0, 1), _event(lambda t, x: x[1], 0)]),
    "no events": (_oscillator, (0.0, 0.7), [0.3, -0.2], lambda: []),
    # x0 first falls through 0.5 (not an upward crossing: the event must not fire there), then rises through it
    "upward after a downward crossing": (_oscillator, (0.0, 3.0), [1.0, 0.0], lambda: [_event(lambda t, x: x[0] - 0.5, 1)]),
    "zero at the start": (_oscillator, (0.0, 1.0), [0.5, 1.0], lambda: [_event(lambda t, x: x[0] - 0.5, 0)]),
    "turns NaN": (lambda t, x: np.array([np.nan if t > 0.3 else 1.0]), (0.0, 1.0), [1.0],
                  lambda: [_event(lambda t, x: x[0] - 5.0, 1), _event(lambda t, x: x[0] - 1.5, 0)]),
}


@pytest.mark.parametrize("lean", [True, False])
@pytest.mark.parametrize("name", list(CASES))
def test_a_piece_is_solve_ivps(name, lean, monkeypatch):
    """lean: stepped by lsoda_piece itself (scipy's event search as this scipy has it); else through
    solve_ivp, as with a scipy whose event search moved or changed its signature."""
    import verifiers.lsoda_piece as piece

    if lean and piece.handle_events is None:
        pytest.skip("this scipy's event search is not the one lsoda_piece calls: every piece goes through solve_ivp")
    if not lean:
        monkeypatch.setattr(piece, "handle_events", None)
    fun, (a, b), x0, events = CASES[name]
    x0 = np.asarray(x0, float)
    ref = solve_ivp(fun, (a, b), x0, method="LSODA", dense_output=True, events=events(), **OPTS)
    got = lsoda_piece(fun, a, b, x0, events(), **OPTS)
    assert got.status == ref.status
    assert got.t == float(ref.t[-1]) and np.array_equal(got.y, ref.y[:, -1], equal_nan=True)
    assert got.fired == [len(te) > 0 for te in ref.t_events]
    grid = np.linspace(a, got.t, 97)
    assert np.array_equal(got.sol(grid), ref.sol(grid), equal_nan=True)
    if name == "turns NaN":  # NaN compares false: no event fires, as in solve_ivp
        assert got.status == 0 and got.fired == [False, False] and np.isnan(got.y).all()
    elif name in ("no event fires", "no events"):
        assert got.status == 0 and got.t == b
    else:
        assert got.status == 1 and any(got.fired)
    if name == "upward after a downward crossing":  # stopped at the rise, after x0 had fallen below 0.5
        assert got.t > 0.5 and abs(got.y[0] - 0.5) < 1e-9 and got.y[1] > 0 and got.sol(0.5 * got.t)[0] < 0.5
    if name == "zero at the start":
        assert got.t == a


@pytest.mark.parametrize("version", ["1.16.2", "1.18.0", "2.0.0rc1"])
def test_another_scipy_release_goes_through_solve_ivp(version, monkeypatch):
    """The loop repeated here is 1.17's: with another release (even one whose event search has the same
    parameters) every piece is solve_ivp's own."""
    import importlib

    import scipy

    import verifiers.lsoda_piece as piece

    monkeypatch.setattr(scipy, "__version__", version)
    try:
        assert importlib.reload(piece).handle_events is None
    finally:
        monkeypatch.undo()
        importlib.reload(piece)
    assert (piece.handle_events is not None) == scipy.__version__.startswith("1.17.")
