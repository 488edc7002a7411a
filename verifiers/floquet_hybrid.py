"""Floquet multipliers and an empirical tube for periodic primitives whose state jumps (gaits).

The flow, its orbit defect and the monodromy of one period (with `neutral`, base_x, base_y, yaw
of a floating base on flat ground, on the reduced state, the neutral multipliers measured along
the symmetry's generators and reported by name) come from the core, mpgspec.certify.hybrid_orbit.
The tube radius of E is sized by batched rollouts from random phases (starts put on the contact
manifold of the feet held at that phase), so it is 'empirical'.
"""
from __future__ import annotations

import time

import numpy as np

from mpgspec.certify.hybrid_orbit import HybridFlow, monodromy, orbit
from mpgspec.certify.problem import PeriodicProblem, RoAResult
from mpgspec.compile.contacts import held_feet
from mpgspec.compile.rigidbody.symmetry import NEUTRAL

from .roa_common import bisect, unit_sphere


def estimate(problem: PeriodicProblem, o: dict, name: str) -> RoAResult:
    """The floquet verifier on a gait: orbit defect, reduced multipliers, then the tube radius."""
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
        return RoAResult(0.0, "failed", name, ev, f"the orbit is stable but no sampled tube converged safely within "
                         f"{tube['periods']} periods (roa.options.periods, periods_max)")
    parts = [f"{k} {v['multiplier']:.6f}" for k, v in found.items()]
    neutral_txt = f"; neutral {', '.join(parts)}" if parts else ""
    return RoAResult(r, "empirical", name, ev,
                     f"multipliers inside the unit circle (max |mu| = {rho:.3g}{neutral_txt}); "
                     f"{tube['simulations']} rollouts at random phases converged safely from W-distance {r:.4g}")


REDRAWS = 20
"""Rounds of drawing again the starts that fell outside C (some h < 0 at their phase: a swing foot drawn
below the ground just after lift-off); one still outside after them is kept, and fails."""

COLLAPSE = 0.1
"""A tube radius below this fraction of the first radius tried (option r0) counts as collapsed."""


def _size(flow: HybridFlow, problem: PeriodicProblem, Xs: np.ndarray, W: np.ndarray, rho: float, o: dict):
    """The tube radius over an adaptive number of periods.

    The first count is the least n with rho^n below conv/4, plus one (the linear transient decays by
    the largest multiplier). When the radius then collapses (below COLLAPSE of r0) and the starts
    that failed all stayed safe but had not yet converged, the transient outlasted the count (slow
    or non-normal multipliers): the count is doubled, up to `periods_max`, and the tube sized again.
    A count given as `periods` is used as is."""
    conv = float(o.get("conv", 0.05))
    first = max(2, int(np.ceil(np.log(conv / 4) / np.log(max(rho, 1e-12)))) + 1)
    periods = int(o.get("periods", first))
    cap = int(o.get("periods_max", max(4 * periods, 24))) if "periods" not in o else periods
    r, tube, _ = grow_periods(lambda n: _tube(flow, Xs, W, n, o), periods, cap, float(o.get("r0", 0.05)))
    return r, tube


def grow_periods(size, periods: int, cap: int, r0: float) -> tuple[float, dict, int]:
    """(r, tube, periods) of size(periods); while r collapses below COLLAPSE r0 and the starts that
    failed all stayed safe but had not yet converged, the periods double, up to cap. Each count
    tried is listed in tube["periods_tried"] when there was more than one."""
    tried = []
    while True:
        r, tube = size(periods)
        tried.append({"periods": periods, "radius": r})
        if r >= COLLAPSE * r0 or periods >= cap or not unconverged(tube["bisection"], r):
            break
        periods = min(2 * periods, cap)
    if len(tried) > 1:
        tube["periods_tried"] = tried
    return r, tube, periods


def unconverged(log: list[dict], r: float) -> bool:
    """Whether the starts that failed at the least failing radius above r all stayed safe (so
    failed only by not yet converging)."""
    above = [e for e in log if e["r"] > r and e["failed"]]
    if not above:
        return False
    least = min(above, key=lambda e: e["r"])
    return least["unsafe"] == 0


def inverse_root(W: np.ndarray) -> np.ndarray:
    """W^-1/2 on W's range (pseudo-inverse root): a step r W^-1/2 u has W-norm r |u| and does not move
    the states W does not weigh."""
    w, U = np.linalg.eigh(0.5 * (W + W.T))
    keep = w > 1e-12 * max(w.max(), 1e-300)
    return (U[:, keep] / np.sqrt(w[keep])) @ U[:, keep].T


def sphere_starts(prim, dt: float, Xs: np.ndarray, W: np.ndarray, Wi: np.ndarray, r: float, m: int,
                  rng: np.random.Generator, steps: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(states, step indices) of m starts x*(t_k) + r Wi u at phase steps k drawn from [steps[0], steps[1]):
    the first half of the u inside the unit ball (uniform in volume), the rest on its sphere; each put on the
    contact manifold of the feet the primitive holds at its phase."""
    k = rng.integers(steps[0], steps[1], m)
    u = unit_sphere(m, W.shape[0], rng)
    u[: m // 2] *= rng.random((m // 2, 1)) ** (1 / W.shape[0])
    X0 = Xs[:, k] + r * (u @ Wi).T
    held = held_feet(prim.contacts)
    if held is not None:
        X0 = np.stack([prim.system.project_to_contacts(X0[:, j], held(k[j] * dt), W) for j in range(m)], 1)
    return X0, k


def _tube(flow: HybridFlow, Xs: np.ndarray, W: np.ndarray, periods: int, o: dict):
    """Bisection on r: starts x*(t0) + r W^-1/2 u at random phases on the dt grid, put on the contact
    manifold of the feet held at t0, must stay in C and end within conv r of the orbit after
    `periods` periods. A start drawn outside C (some h < 0 at its phase, such as a swing foot below
    the ground just after lift-off) is drawn again: the oracle takes a rollout into E only at a sample
    where it judged every h >= -tol (tol: its h_tolerance), so E needs to hold only where C does."""
    prim = flow.prim
    n = int(o.get("samples", 48))
    conv = float(o.get("conv", 0.05))
    rng = np.random.default_rng(o.get("seed", 0))
    Wi = inverse_root(W)
    tol = float(o.get("oracle_h_tolerance", 0.0))  # the oracle's: it judges h >= -tol safe
    redrawn = [0]
    log = []

    def draw(r, m):
        return sphere_starts(prim, flow.dt, Xs, W, Wi, r, m, rng, (0, flow.steps))

    def starts(r):
        X0, k = draw(r, n)
        out = ~(flow.least_h(X0, k * flow.dt) >= -tol)  # outside C: drawn again (E is entered only in C)
        for _ in range(REDRAWS):
            if not out.any():
                break
            redrawn[0] += int(out.sum())
            X1, k1 = draw(r, int(out.sum()))
            X0[:, out], k[out] = X1, k1
            out[out] = ~(flow.least_h(X1, k1 * flow.dt) >= -tol)
        return X0, k * flow.dt

    def decided(X, hmin):  # a start already left C or blew up: this radius fails whatever follows
        return bool((hmin < 0).any() or not np.isfinite(X).all())

    def ok(r):
        X0, t0 = starts(r)
        XT, hmin, ran = flow.run_until(X0, t0, periods, decided)
        if ran < periods:
            bad = (hmin < 0) | ~np.isfinite(XT).all(axis=0)
            log.append({"r": r, "failed": int(bad.sum()), "unsafe": int((hmin < 0).sum()), "stopped_after_periods": ran})
            return False
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
               "starts": ("projected onto the contact manifold of the feet held at their phase"
                          if held_feet(prim.contacts) is not None else "as drawn") + ", inside C",
               "redrawn_outside_c": redrawn[0]}
