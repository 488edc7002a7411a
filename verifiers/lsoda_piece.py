"""One piece of the reference backend's rollout: scipy's LSODA with terminal events and dense output.

`solve_ivp(fun, (a, b), x, method="LSODA", dense_output=True, events=...)` with every event terminal,
stepped here with the same solver, the same event search (scipy's `handle_events`: brentq on the step's
dense output) and the same solution object, so the numbers are solve_ivp's bit for bit (tested). What
it leaves out is solve_ivp's per-step bookkeeping for events that may fire many times (an array
comparison of every event's values after each step): here each step compares Python floats, which
is most of the time a rollout of a small system spends outside its right-hand side.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np
import scipy
from scipy.integrate import LSODA, OdeSolution, solve_ivp

_SIGNATURE = ["sol", "events", "active_events", "event_count", "max_events", "t_old", "t"]
_SCIPY = (1, 17)
"""The scipy release whose solve_ivp loop this module repeats (compared bit for bit in its tests): with
another, every piece goes through solve_ivp itself."""
try:  # scipy's own event search, so that a root is found as solve_ivp finds it
    from scipy.integrate._ivp.ivp import handle_events
    if (list(inspect.signature(handle_events).parameters) != _SIGNATURE
            or tuple(int(v) for v in scipy.__version__.split(".")[:2]) != _SCIPY):
        handle_events = None
except (ImportError, ValueError):  # pragma: no cover - a scipy that moved it: solve_ivp does the whole piece
    handle_events = None


@dataclass
class Piece:
    """t: the piece's last time (an event's root when one ended it); y: the state there; sol: the
    dense solution over [a, t] (without segments when the solver made no step: evaluate it only for
    t > a); status: solve_ivp's (0 reached b, 1 an event ended it, -1 the solver failed); fired: per
    event, whether it ended the piece."""
    t: float
    y: np.ndarray
    sol: OdeSolution | None
    status: int
    fired: list[bool]


def lsoda_piece(fun, a: float, b: float, x: np.ndarray, events: list, **options) -> Piece:
    """fun(t, x) from (a, x) towards b with LSODA (`options`: rtol, atol, max_step); every event
    terminal, with its `direction` attribute as solve_ivp reads it."""
    if handle_events is None or not all(getattr(e, "terminal", False) is True for e in events):
        sol = solve_ivp(fun, (a, b), x, method="LSODA", dense_output=True, events=events, **options)
        return Piece(float(sol.t[-1]), sol.y[:, -1], sol.sol, sol.status, [len(te) > 0 for te in sol.t_events])
    solver = LSODA(fun, a, x, b, vectorized=False, **options)
    direction = [float(getattr(e, "direction", 0)) for e in events]
    count, most = np.zeros(len(events)), np.ones(len(events))
    ts, interpolants = [a], []
    y_last = solver.y
    g = [e(a, solver.y) for e in events]
    status, fired = None, [False] * len(events)
    while status is None:
        solver.step()
        if solver.status == "finished":
            status = 0
        elif solver.status == "failed":
            status = -1
            break
        t_old, t, y = solver.t_old, solver.t, solver.y
        sol = solver.dense_output()
        interpolants.append(sol)
        g_new = [e(t, y) for e in events]
        active = [i for i, (g0, g1, d) in enumerate(zip(g, g_new, direction)) if _crossed(g0, g1, d)]
        if active:
            idx = np.asarray(active)
            count[idx] += 1
            roots_at, roots, terminate = handle_events(sol, events, idx, count, most, t_old, t)
            for i in roots_at:
                fired[int(i)] = True
            if terminate:
                status = 1
                t = roots[-1]
                y = sol(t)
        g = g_new
        if len(ts) > 1 and ts[-1] == t:
            interpolants.pop()
        else:
            ts.append(t)
            y_last = y
    return Piece(float(ts[-1]), np.asarray(y_last), OdeSolution(ts, interpolants, alt_segment=True), status, fired)


def _crossed(g0: float, g1: float, direction: float) -> bool:
    """scipy's find_active_events for one event: a zero crossed (or touched) in the event's direction."""
    up = g0 <= 0 and g1 >= 0
    down = g0 >= 0 and g1 <= 0
    return (up and direction > 0) or (down and direction < 0) or ((up or down) and direction == 0)
