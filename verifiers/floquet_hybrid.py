"""Floquet multipliers and an empirical tube for periodic primitives whose state jumps (gaits).

The flow is the oracle's own discrete one: RK4 steps of dt from clock times on the dt grid (every
contact switch lies on it), each followed by the primitive's jump (quaternion renormalised,
plastic impact of feet that join the contact mode). The monodromy is the derivative of one
period of that map by central differences; with `neutral` (base_x, base_y, yaw of a floating
base on flat ground) it is taken on the reduced state, and the neutral multipliers are measured
along the symmetry's generators and reported by name. The tube radius of E is sized by batched
rollouts from random phases (starts put on the contact manifold of the feet held at that phase),
so it is 'empirical'.
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

from .roa_common import PeriodicProblem, RoAResult, bisect, unit_sphere
from mpgspec.compile.contacts import Schedule, held_feet

FD = 1e-6
S_LONG = 1e6  # time since switch-in: long after any motion profile


class HybridFlow:
    """Compiled steps, periods and tubes of a compiled primitive's discrete flow."""

    def __init__(self, prim, dt: float):
        from mpgspec.oracle.flow import LEFT, rk4_jump
        from mpgspec.oracle.integrator import compile_cached

        self.prim, self.dt = prim, float(dt)
        T = float(prim.period)
        self.steps = int(round(T / dt))
        if abs(self.steps * dt - T) > 1e-9 or any(abs(b / dt - round(b / dt)) > 1e-6 for b in prim.boundaries):
            raise ValueError(f"the period and switching times must be multiples of dt = {dt:g}")
        nx = prim.system.nx
        xs0 = np.array(prim.setpoint(0.0), float).ravel()
        z = ca.MX.sym("z", nx + 2)  # [x; t; min h so far]
        x, t, m = z[:nx], z[nx], z[nx + 1]
        f = lambda xx, tt: prim.f_cl(xx, tt, S_LONG, xs0)  # noqa: E731
        k = lambda xx, tt: prim.control(xx, tt, S_LONG, xs0)[1]  # noqa: E731
        h = self.dt
        xn = rk4_jump(f, k, prim.jump, x, t, h, LEFT if isinstance(prim.contacts, Schedule) else 0.0)
        hv = prim.h(xn, t + h, S_LONG, xs0)
        mn = ca.fmin(m, ca.mmin(hv)) if hv.shape[0] else m
        body = ca.Function("hybrid_body", [z], [ca.vertcat(xn, t + h, mn)])
        zz = ca.MX.sym("z", nx + 2)  # one compiled Function: a period, every step's state out
        self.period_fn = compile_cached(ca.Function("hybrid_period", [zz], [body.mapaccum(self.steps)(zz)]),
                                        ("-O1",))

    def states(self, x0: np.ndarray, t0: float = 0.0) -> np.ndarray:
        """[x; t; least h] after each step of one period from x0 at clock t0 (columns)."""
        return np.array(self.period_fn(np.concatenate([x0, [t0, np.inf]])), float)

    def run(self, X0: np.ndarray, t0: np.ndarray, periods: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """End states and least h of rollouts from the columns of X0 at clocks t0."""
        n, N = X0.shape[1], self.steps
        Z = np.vstack([X0, t0[None, :], np.full((1, n), np.inf)])
        fn = self.period_fn.map(n)
        for _ in range(periods):
            Z = np.array(fn(Z), float)[:, N - 1::N]
        return Z[:-2], Z[-1]


def orbit(flow: HybridFlow, W: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(x* on the step grid of one period, orbit defect, least h along it): x*(t) must be a
    trajectory of the loop's own discrete flow, step by step; the defect is the largest W-distance
    between a step from x*(t_k) and x*(t_k+1)."""
    x_star = flow.prim.setpoint.map(flow.steps + 1)
    ts = np.arange(flow.steps + 1) * flow.dt
    Xs = np.array(x_star(ts[None, :]), float)
    Z = flow.states(Xs[:, 0])
    E = Z[:-2] - Xs[:, 1:]
    return Xs, float(np.sqrt(np.einsum("ij,ik,kj->j", E, W, E)).max()), float(Z[-1, -1])


def monodromy(flow: HybridFlow, x0: np.ndarray, neutral: list[str]) -> tuple[np.ndarray, dict]:
    """The one-period derivative at x0 (clock 0): reduced if `neutral` names the ground symmetry."""
    sys = flow.prim.system
    if neutral:
        from mpgspec.compile.rigidbody.symmetry import reduced_monodromy

        return reduced_monodromy(sys, lambda X: flow.run(X, np.zeros(X.shape[1]))[0], x0, neutral, FD)
    nx = sys.nx
    E = np.eye(nx)
    XT, _ = flow.run(np.hstack([x0[:, None] + FD * E, x0[:, None] - FD * E]), np.zeros(2 * nx))
    return (XT[:, :nx] - XT[:, nx:]) / (2 * FD), {}


def estimate(problem: PeriodicProblem, o: dict, name: str) -> RoAResult:
    from mpgspec.compile.rigidbody.symmetry import NEUTRAL

    t_start = time.perf_counter()
    prim = problem.source
    T, dt = float(problem.period), float(o.get("dt", 0.001))
    neutral = list(o.get("neutral", []))
    bad = [n for n in neutral if n not in NEUTRAL]
    if bad or (neutral and not getattr(prim.system, "is_rigid_body", False)):
        return RoAResult(0.0, "failed", name, {"neutral": neutral},
                         f"neutral directions must be among {', '.join(NEUTRAL)} of a floating base; got {bad or neutral}")
    flow = HybridFlow(prim, dt)
    W = problem.W
    Xs, defect, least_h = orbit(flow, W)
    ev = {"period": T, "dt": dt, "orbit_defect": defect, "least_h_on_orbit": least_h, "hybrid": True}
    if not np.isfinite(defect) or defect > float(o.get("orbit_tol", 1e-3)):
        ev["verdict"] = "x*(t) is not a solution"
        return RoAResult(0.0, "failed", name, ev, f"the flow from x*(0) leaves the orbit by {defect:.3g} in the "
                         "W metric: x*(t) is not a trajectory of the closed loop (regenerate the gait table?)")
    if not least_h >= 0:
        ev["verdict"] = "orbit not safe"
        return RoAResult(0.0, "failed", name, ev, f"the orbit itself leaves C (least h {least_h:.3g})")
    M, found = monodromy(flow, Xs[:, 0], neutral)
    mu = np.linalg.eigvals(M)
    mu = mu[np.argsort(-np.abs(mu))]
    rho = float(np.abs(mu).max(initial=0.0))
    ev.update(multipliers=[[float(v.real), float(v.imag)] for v in mu], multiplier_moduli=np.abs(mu),
              spectral_radius=rho, neutral=found, monodromy=M, reduced=bool(neutral))
    tol = float(o.get("tol", 1e-6))
    if not rho < 1 - tol:
        ev["verdict"] = "not exponentially stable"
        return RoAResult(0.0, "failed", name, ev, f"Floquet multiplier of modulus {rho:.6g} >= 1 - {tol:g}")
    ev["verdict"] = "orbitally exponentially stable" + (" up to the ground symmetry" if neutral else "")
    r, tube = _size(flow, problem, Xs, W, rho, o)
    ev.update(tube=tube, time_s=time.perf_counter() - t_start)
    if not r > 0:
        return RoAResult(0.0, "failed", name, ev, "the orbit is stable but no sampled tube converged safely")
    parts = [f"{k} {v['multiplier']:.6f}" for k, v in found.items()]
    neutral_txt = f"; neutral {', '.join(parts)}" if parts else ""
    return RoAResult(r, "empirical", name, ev,
                     f"multipliers inside the unit circle (max |mu| = {rho:.3g}{neutral_txt}); "
                     f"{tube['simulations']} rollouts at random phases converged safely from W-distance {r:.4g}")


def _size(flow: HybridFlow, problem: PeriodicProblem, Xs: np.ndarray, W: np.ndarray, rho: float, o: dict):
    """Bisection on r: starts x*(t0) + r W^-1/2 u at random phases on the dt grid, put on the contact
    manifold of the feet held at t0, must stay in C and end within conv r of the orbit."""
    prim = flow.prim
    sys = prim.system
    n = int(o.get("samples", 48))
    conv = float(o.get("conv", 0.05))
    periods = int(o.get("periods", max(2, int(np.ceil(np.log(conv / 4) / np.log(max(rho, 1e-12)))) + 1)))
    rng = np.random.default_rng(o.get("seed", 0))
    w, U = np.linalg.eigh(0.5 * (W + W.T))
    keep = w > 1e-12 * max(w.max(), 1e-300)
    Wi = (U[:, keep] / np.sqrt(w[keep])) @ U[:, keep].T  # pseudo-inverse root: unweighted states are not moved
    held = held_feet(prim.contacts)
    log = []

    def starts(r):
        k = rng.integers(0, flow.steps, n)
        u = unit_sphere(n, W.shape[0], rng)
        u[: n // 2] *= rng.random((n // 2, 1)) ** (1 / W.shape[0])
        X0 = Xs[:, k] + r * (u @ Wi).T
        if held is not None:
            X0 = np.stack([sys.project_to_contacts(X0[:, j], held(k[j] * flow.dt), W) for j in range(n)], 1)
        return X0, k * flow.dt

    def ok(r):
        X0, t0 = starts(r)
        XT, hmin = flow.run(X0, t0, periods)
        ks = np.round(t0 / flow.dt).astype(int)
        E = XT - Xs[:, ks]
        dist = np.sqrt(np.einsum("ij,ik,kj->j", E, W, E))
        d0 = X0 - Xs[:, ks]
        r0 = np.sqrt(np.einsum("ij,ik,kj->j", d0, W, d0))
        good = np.isfinite(dist) & (dist <= conv * np.maximum(r0, 1e-12)) & (hmin >= 0)
        log.append({"r": r, "failed": int((~good).sum()), "unsafe": int((hmin < 0).sum()),
                    "worst_final_dist": float(np.nanmax(dist)) if np.isfinite(dist).any() else float("inf")})
        return bool(good.all())

    t0 = time.perf_counter()
    r, capped, calls = bisect(ok, 0.0, float(o.get("r0", 0.05)), float(o.get("r_max", 2.0)), float(o.get("rtol", 0.05)),
                              grow=2.0)
    return r, {"samples_per_radius": n, "simulations": n * len(log), "bisection": log, "capped": capped,
               "periods": periods, "dt": flow.dt, "conv": conv, "time_s": time.perf_counter() - t0,
               "starts": "projected onto the contact manifold of the feet held at their phase" if held else "as drawn"}
