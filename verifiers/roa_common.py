"""Shared types and numerics of the region-of-attraction verifiers.

A verifier sizes the explicit safe region of attraction E = {(x-x*)' W (x-x*) < r^2} of one
primitive (Definition 1), which the paper otherwise picks by hand. Every verifier returns a
RoAResult whose `level` says how much the radius can be trusted.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import casadi as ca
import numpy as np
import scipy.linalg as sla

from mpgspec.oracle.flow import rk4 as rk4_step

LEVELS = ("certified", "empirical", "given", "failed")

@dataclass
class RoAProblem:
    """Autonomous closed loop xdot = f(x) of a fixed primitive with equilibrium x_star and h(x) >= 0 safe."""

    f: ca.Function
    x_star: np.ndarray
    h: ca.Function | None = None
    weights: np.ndarray | None = None
    name: str = ""

    @property
    def nx(self) -> int:
        return int(np.size(self.x_star))

    @property
    def W(self) -> np.ndarray:
        return metric(self.weights, self.nx)


@dataclass
class PeriodicProblem:
    """Time-varying closed loop xdot = f(x, t) tracking the T-periodic orbit x_star(t)."""

    f: ca.Function
    x_star: ca.Function
    period: float
    h: ca.Function | None = None  # (x, t) -> safety functions
    weights: np.ndarray | None = None
    name: str = ""
    source: object = None  # the compiled primitive, for loops whose state jumps (contact schedules)

    @property
    def nx(self) -> int:
        return int(self.f.size1_in(0))

    @property
    def W(self) -> np.ndarray:
        return metric(self.weights, self.nx)


@dataclass
class RoAResult:
    """Radius r of E in the W metric, how it was obtained, and JSON-serialisable evidence."""

    radius: float
    level: str
    method: str
    evidence: dict = field(default_factory=dict)
    message: str = ""

    def __post_init__(self):
        if self.level not in LEVELS:
            raise ValueError(f"level must be one of {LEVELS}, got {self.level!r}")
        self.radius = float(self.radius)
        self.evidence = jsonable(self.evidence)

    def to_dict(self) -> dict:
        return {"radius": self.radius, "level": self.level, "method": self.method,
                "evidence": self.evidence, "message": self.message}


def jsonable(v):
    """Evidence values as plain lists, floats, ints, bools and strings."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else str(float(v))
    if isinstance(v, complex):
        return [v.real, v.imag]
    if v is None or isinstance(v, str):
        return v
    return str(v)


def metric(weights: np.ndarray | None, nx: int) -> np.ndarray:
    """The SPD matrix W of E from a weight vector, a matrix, or None (identity)."""
    if weights is None:
        return np.eye(nx)
    w = np.asarray(weights, float)
    return np.diag(w) if w.ndim == 1 else w


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


def weakest(*levels: str) -> str:
    """The least trusted of several levels."""
    order = {"failed": 0, "empirical": 1, "given": 2, "certified": 3}
    return min(levels, key=order.__getitem__)


def from_primitive(prim, weights: np.ndarray | None = None, s: float = 1e6) -> RoAProblem | PeriodicProblem:
    """The RoA problem of a compiled primitive (duck-typed CompiledPrimitive) with x_sw = x*(0).

    s is the time since switch-in, by default long after any motion profile has finished, so the
    loop tracks x* itself and a fixed primitive's loop is autonomous. Transient primitives have
    no RoA problem here.
    """
    cls = getattr(prim.cls, "value", prim.cls)
    nx = prim.f_cl.size1_in(0)
    x, t = ca.SX.sym("x", nx), ca.SX.sym("t")
    xs0 = np.array(prim.setpoint(0.0), float).ravel()
    if cls == "fixed":
        return RoAProblem(ca.Function("f", [x], [prim.f_cl(x, 0.0, s, xs0)]), xs0,
                          ca.Function("h", [x], [prim.h(x, 0.0, s, xs0)]), weights, prim.name)
    if cls == "periodic":
        return PeriodicProblem(ca.Function("f", [x, t], [prim.f_cl(x, t, s, xs0)]), prim.setpoint,
                               float(prim.period), ca.Function("h", [x, t], [prim.h(x, t, s, xs0)]), weights,
                               prim.name, prim if getattr(prim, "hybrid", False) else None)
    raise ValueError(f"no region-of-attraction problem for a {cls} primitive")
