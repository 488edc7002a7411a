"""Numerics shared by the region-of-attraction verifiers: linearisation, quadratic Lyapunov
functions, W-balls, batched rollouts and the bisection on the radius.

The contract they implement (RoAProblem, PeriodicProblem, RoAResult and the levels of evidence)
is the core's: mpgspec.certify.problem.
"""
from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np
import scipy.linalg as sla

from mpgspec.oracle.flow import rk4 as rk4_step


def validate_gram(Q: np.ndarray, tol: float) -> tuple[bool, float]:
    """A Gram matrix passes when its symmetric part has min eigenvalue >= -tol."""
    Q = np.asarray(Q, float)
    if Q.size == 0:
        return True, float("inf")
    if not np.all(np.isfinite(Q)):
        return False, float("nan")
    e = float(np.linalg.eigvalsh(0.5 * (Q + Q.T)).min())
    return e >= -tol, e


def linearise(f: ca.Function, x_star: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A = df/dx at x_star and the equilibrium defect f(x_star)."""
    x = ca.SX.sym("x", f.size1_in(0))
    fx = f(x)
    J = ca.Function("J", [x], [ca.jacobian(fx, x), fx])
    A, f0 = J(x_star)
    return np.array(A, float), np.array(f0, float).ravel()


def lyapunov_P(A: np.ndarray, Q: np.ndarray | None = None) -> np.ndarray:
    """P solving A'P + PA = -Q (Q = I by default), symmetrised."""
    Q = np.eye(len(A)) if Q is None else np.asarray(Q, float)
    P = sla.solve_continuous_lyapunov(A.T, -Q)
    return 0.5 * (P + P.T)


def ball_radius(P: np.ndarray, rho: float, W: np.ndarray) -> float:
    """Largest r with {y'Wy < r^2} inside {y'Py <= rho}: sqrt(rho / lambda_max(W^-1/2 P W^-1/2))."""
    if rho <= 0:
        return 0.0
    Wi = inv_sqrt(W)
    return float(np.sqrt(rho / np.linalg.eigvalsh(Wi @ P @ Wi).max()))


def inv_sqrt(W: np.ndarray) -> np.ndarray:
    w, U = np.linalg.eigh(0.5 * (W + W.T))
    return (U / np.sqrt(w)) @ U.T


def unit_sphere(n: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """n points uniform on the unit sphere in R^dim, one per row."""
    u = rng.standard_normal((n, dim))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def batch(fn: ca.Function, n: int) -> Callable[..., np.ndarray]:
    """Evaluate fn column-wise on n columns; returns its first output as an array."""
    m = fn.map(n)
    return lambda *a: np.array(m(*a), float)


def rk4_flow(f: ca.Function, h: ca.Function | None, dt: float, steps: int, n: int) -> ca.Function:
    """Batched RK4 flow: (z0) -> z after `steps` steps, z = [x; t; min h so far], one column per rollout.

    f and h take (x, t); the whole horizon is one folded CasADi Function, so a batch is one call.
    """
    nx = f.size1_in(0)
    x, t, m = ca.SX.sym("x", nx), ca.SX.sym("t"), ca.SX.sym("m")
    xn, _ = rk4_step(f, x, (t,), dt)
    mn = ca.fmin(m, ca.mmin(h(xn, t + dt))) if h is not None else m
    step = ca.Function("rk4_step", [ca.vertcat(x, t, m)], [ca.vertcat(xn, t + dt, mn)])
    return step.fold(steps).map(n)


def rk4(flow: ca.Function, x0: np.ndarray, t0: np.ndarray, h0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Final states (nx x N) and min h along each rollout of an rk4_flow, from x0 with h(x0) = h0."""
    z = np.array(flow(np.vstack([x0, t0[None, :], h0[None, :]])), float)
    x, hmin = z[:-2], z[-1]
    bad = ~np.isfinite(x).all(axis=0) | np.isnan(hmin)
    hmin[bad] = -np.inf
    return x, hmin


def bisect(ok: Callable[[float], bool], lo: float, hi: float, cap: float, rtol: float = 1e-3,
           max_iter: int = 60, grow: float = 4.0) -> tuple[float, bool, int]:
    """Largest value in [lo, cap] passing `ok`, assuming monotonicity; lo must pass or be 0.

    hi is the first guess: it is multiplied by `grow` while it passes. Returns (value, capped, calls).
    """
    calls, hi = 0, min(hi, cap)
    while hi < cap:
        calls += 1
        if not ok(hi):
            break
        lo, hi = hi, min(grow * hi, cap)
    else:
        calls += 1
        if ok(cap):
            return cap, True, calls
    floor = 1e-9 * hi
    while hi - lo > rtol * hi and hi > floor and calls < max_iter:
        mid = 0.5 * (lo + hi)
        calls += 1
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo, False, calls
