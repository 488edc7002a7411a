"""Empirical radius of E by simulation: the largest W-ball whose sampled starts all converge safely.

Start points lie on and inside W-spheres of radius r around x*(t0); each is simulated with fixed-step RK4
and passes if h >= 0 all along and it ends within conv * r of x*(t0 + horizon). Bisection on r
assumes that passing is monotone in r, and the final radius is re-tested with starts spread
through the whole ball. Nothing here is a proof, so the level is always 'empirical'.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from mpgspec.certify.problem import RoAProblem, RoAResult

from .roa_common import batch, bisect, inv_sqrt, linearise, rk4, rk4_flow, unit_sphere


@dataclass
class Simulator:
    """Batched closed loop f(x, t), safety h(x, t) and setpoint x*(t) over n columns."""

    f: ca.Function
    h: ca.Function | None
    x_star: ca.Function
    W: np.ndarray
    n: int
    horizon: float
    dt: float
    conv: float = 0.02

    def __post_init__(self):
        steps = max(int(np.ceil(self.horizon / self.dt - 1e-9)), 1)
        self.dt = self.horizon / steps
        has_h = self.h is not None and self.h.size1_out(0) > 0
        self._flow = rk4_flow(self.f, self.h if has_h else None, self.dt, steps, self.n)
        self._h = batch(self.h, self.n) if has_h else None
        self._xs = batch(self.x_star, self.n)
        self._Wi = inv_sqrt(self.W)

    def starts(self, r: float, t0: np.ndarray, rng: np.random.Generator, inside: float = 0.5) -> np.ndarray:
        """Columns x*(t0) + r W^-1/2 u, u on the unit sphere, a fraction `inside` uniform in the unit ball."""
        nx = len(self.W)
        u = unit_sphere(self.n, nx, rng)
        k = int(round(inside * self.n))
        u[:k] *= rng.random((k, 1)) ** (1 / nx)
        return self._xs(t0[None, :]) + r * (u @ self._Wi).T

    def run(self, x0: np.ndarray, t0: np.ndarray) -> dict:
        """Per column: final W-distance to x*(t0 + horizon) and min h along the way."""
        h0 = self._h(x0, t0[None, :]).min(axis=0) if self._h is not None else np.full(self.n, np.inf)
        xT, hmin = rk4(self._flow, x0, t0, h0)
        e = xT - self._xs((t0 + self.horizon)[None, :])
        dist = np.sqrt(np.einsum("ij,ik,kj->j", e, self.W, e))
        return {"dist": np.nan_to_num(dist, nan=np.inf), "hmin": hmin}

    def test(self, r: float, t0: np.ndarray, rng: np.random.Generator, inside: float = 0.5) -> tuple[bool, dict]:
        x0 = self.starts(r, t0, rng, inside)
        out = self.run(x0, t0)
        ok = (out["dist"] <= self.conv * r) & (out["hmin"] >= 0)
        return bool(ok.all()), {"r": r, "failed": int((~ok).sum()), "unsafe": int((out["hmin"] < 0).sum()),
                                "worst_final_dist": float(out["dist"].max())}


def search(sim: Simulator, phases, rng: np.random.Generator, o: dict) -> tuple[float, dict]:
    """Bisection on r (half the starts on the sphere, half inside the ball, as passing need not be
    monotone), then a check with all starts inside the ball, shrinking by 10% until it passes."""
    log: list[dict] = []

    def ok(r: float) -> bool:
        passed, info = sim.test(r, phases(), rng)
        log.append(info)
        return passed

    t0 = time.perf_counter()
    r, capped, calls = bisect(ok, 0.0, float(o.get("r0", 0.1)), float(o.get("r_max", 100.0)), o.get("rtol", 0.01),
                              grow=2.0)
    confirm = []
    for _ in range(int(o.get("confirm_rounds", 5))):
        if r <= 0:
            break
        passed, info = sim.test(r, phases(), rng, inside=1.0)
        confirm.append(info)
        if passed:
            break
        r *= float(o.get("confirm_shrink", 0.9))
    else:
        r = 0.0 if confirm else r
    sims = sim.n * (len(log) + len(confirm))
    return r, {"samples_per_radius": sim.n, "simulations": sims, "bisection": log, "confirm": confirm,
               "capped": capped, "horizon": sim.horizon, "dt": sim.dt, "conv": sim.conv,
               "time_s": time.perf_counter() - t0}


def defaults(A: np.ndarray, o: dict) -> tuple[float, float]:
    """Horizon of ~10 slowest time constants of the linearisation and an RK4 step resolving the fastest."""
    lam = np.linalg.eigvals(A)
    slow = -lam.real.max() if lam.real.max() < 0 else 0.1
    horizon = float(o.get("horizon", np.clip(10.0 / slow, 1.0, 200.0)))
    fast = max(np.abs(lam).max(), 1e-6)
    dt = float(o.get("dt", min(horizon / 200, 0.25 / fast)))
    return horizon, dt


class SamplingVerifier:
    name = "sampling"
    simulates = True  # rollouts only: sized on the executor's workers (certify/roa.py)
    description = "empirical radius: RK4 rollouts from W-spheres around x*, bisection on r"

    @staticmethod
    def is_installed() -> bool:
        return True

    def estimate(self, problem: RoAProblem, options: dict | None = None) -> RoAResult:
        o = dict(options or {})
        nx, xs = problem.nx, np.asarray(problem.x_star, float).ravel()
        x, t = ca.SX.sym("x", nx), ca.SX.sym("t")
        f = ca.Function("f", [x, t], [problem.f(x)])
        h = ca.Function("h", [x, t], [problem.h(x)]) if problem.h is not None else None
        A, _ = linearise(problem.f, xs)
        horizon, dt = defaults(A, o)
        n = int(o.get("samples", 256))
        sim = Simulator(f, h, ca.Function("xs", [t], [ca.DM(xs)]), problem.W, n, horizon, dt, o.get("conv", 0.02))
        rng = np.random.default_rng(o.get("seed", 0))
        r, ev = search(sim, lambda: np.zeros(n), rng, o)
        if not r > 0 or not np.isfinite(r):  # NaN or inf is no radius
            return RoAResult(0.0, "failed", self.name, ev, "no sampled radius converged safely")
        return RoAResult(r, "empirical", self.name, ev,
                         f"{ev['simulations']} rollouts: every start within r = {r:.4g} converged and stayed safe")


verifier = SamplingVerifier()
