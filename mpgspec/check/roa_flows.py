"""roa_invariant: flows from E's boundary stay in C and inside E (Definition 1's E within S).

A graph edge into B is claimed when B's flow enters E_B; Theorem 1 then relies on every flow from E_B
staying safe ever after, which a radius the spec gives (or a certificate of another model) does not
show. Here a fixed primitive's closed loop (the oracle's discrete flow: RK4 steps and jumps, the loop
after any motion profile has ended) is run from seeded samples of E's boundary, put on the contact
manifold of its feet for robots with contacts, over the horizon (in chunks: a run ends early once a
flow has left C or every flow is within 0.05 r of x*). Sampled, so 'empirical':

- fail: a flow left C (some h < -tol), blew up or its law found no input (its compiled step failed):
  E is not inside the implicit safe RoA S;
- warn: every flow stayed in C, but some ended outside E: E is not shown invariant;
- pass: every flow stayed in C and ended inside E; the message says how far from x* they ended (a
  legged robot's flows stop short of x* where the loop does not steer the feet back to where x*
  stands them: Definition 1's convergence to x* then holds only up to those directions).
"""
from __future__ import annotations

import numpy as np

from ..certify.hybrid_orbit import HybridFlow
from ..compile.numeric import by_column
from ..compile.primitive import CompiledPrimitive
from ..spec.models import PrimitiveClass
from .assumptions import HYBRID_DT, AssumptionCheck
from .roa_manifold import contact_projection
from .roa_samples import metric, sphere_offsets, weighted_distances

SAMPLES = 16
"""Starts on E's boundary."""

CHUNK = 0.1
"""Seconds of flow between two looks at the starts (a multiple of the step)."""

HORIZON = 2.5
"""Longest run (s) when the primitive has no horizon of its own."""

CONVERGED = 0.05
"""Flows within this fraction of r from x* have converged."""


def boundary_starts(p: CompiledPrimitive, n: int, seed: int) -> np.ndarray:
    """Columns on the W-sphere of radius r around x*(0), each put on the contact manifold of the
    primitive's feet (projected, pushed back to the sphere, projected again)."""
    xs = np.asarray(p.x_star(0.0), float).ravel()
    r = float(p.radius) * (1 - 1e-9)
    X = xs[:, None] + sphere_offsets(metric(p), r, n, np.random.default_rng(seed)).T
    project = contact_projection(p, metric(p))
    if project is None:
        return X
    for _ in range(2):
        X = np.asarray(project.many(X.T, xs, 0.0)[0], float).T
        X = xs[:, None] + (X - xs[:, None]) * (r / np.maximum(weighted_distances(p, X, xs), 1e-300))
    return np.asarray(project.many(X.T, xs, 0.0)[0], float).T


def _run_each(flow: HybridFlow, X: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One chunk of every flow; a flow whose compiled step fails (a law that finds no input, say) is left
    not finite: that flow's evidence, not the end of the check (compile/numeric.by_column)."""
    outs, _failed = by_column(lambda x, tt: flow.run(x, tt[0], 1), [X, t[None, :]])
    if outs is None:
        return np.full_like(X, np.nan), np.full(X.shape[1], np.nan)
    return outs[0], outs[1][0]


def roa_invariant(p: CompiledPrimitive, tol: float = 1e-9, samples: int = SAMPLES, seed: int = 0,
                  horizon: float | None = None) -> AssumptionCheck | None:
    """The check above for a fixed primitive with a non-empty E; None for other primitives."""
    if p.cls is not PrimitiveClass.FIXED or not float(p.radius) > 0:
        return None
    r = float(p.radius)
    T = float(horizon or p.horizon or HORIZON)
    flow = HybridFlow(p, HYBRID_DT, CHUNK, states=False)
    xs = np.asarray(p.x_star(0.0), float).ravel()
    X = boundary_starts(p, samples, seed)
    r0 = weighted_distances(p, X, xs)
    margin = lambda Y: np.array(p.roa_margin.map(Y.shape[1])(Y, 0.0), float).ravel()  # noqa: E731
    h0 = flow.least_h(X, np.zeros(samples))
    hmin, dist = h0.copy(), r0.copy()
    ran, chunks, stop = 0.0, max(1, int(round(T / CHUNK))), "horizon"
    for k in range(chunks):
        X, hk = _run_each(flow, X, np.full(samples, k * CHUNK))
        hmin = np.minimum(hmin, hk)
        ran = (k + 1) * CHUNK
        dist = weighted_distances(p, X, xs)
        if (hmin < -tol).any() or not np.isfinite(X).all():
            break
        if (dist <= CONVERGED * r).all():  # a slow drift is no evidence of rest: only this ends a run early
            stop = "converged"
            break
    unsafe = ~(hmin >= -tol) | ~np.isfinite(X).all(axis=0)
    outside = ~(margin(X) >= 0) & ~unsafe
    final = dist / r
    numbers = {"samples": samples, "seed": seed, "radius": r, "ran_s": ran, "horizon_s": T,
               "start_radius_min": float(r0.min() / r), "least_h": float(np.nanmin(hmin)) if np.isfinite(hmin).any()
               else None, "unsafe": int(unsafe.sum()), "outside_at_end": int(outside.sum()),
               "final_distance_max": float(np.nanmax(final)) if np.isfinite(final).any() else None,
               "final_distance_median": float(np.nanmedian(final)) if np.isfinite(final).any() else None,
               "contact_manifold": contact_projection(p, metric(p)) is not None}
    where = "on the contact manifold, " if numbers["contact_manifold"] else ""
    least_h = "no safety function" if numbers["least_h"] is None else f"least h {numbers['least_h']:.3g}"
    head = f"{samples} flows from E's boundary ({where}seed {seed}), {ran:.2g} s of {T:.2g} s"
    if unsafe.any():
        return AssumptionCheck(p.name, "roa_invariant", "fail", "empirical",
                               f"{head}: {int(unsafe.sum())} left C, blew up or found no input ({least_h}): E is not "
                               f"inside the safe region of attraction; shrink roa.radius", numbers)
    if outside.any():
        return AssumptionCheck(p.name, "roa_invariant", "warn", "empirical",
                               f"{head}: all stayed in C ({least_h}), {int(outside.sum())} "
                               f"ended outside E (up to {numbers['final_distance_max'] or np.inf:.3g} r): E is not shown "
                               f"invariant", numbers)
    far = numbers["final_distance_max"]
    numbers["stopped"] = stop
    feet = " (where the feet stand is not steered back)" if numbers["contact_manifold"] else ""
    how = (f"converging to x* (within {CONVERGED:g} r)" if stop == "converged" else
           f"up to {far:.2g} r from x* at the horizon, not converged to it{feet}")
    return AssumptionCheck(p.name, "roa_invariant", "pass", "empirical",
                           f"{head}: all stayed in C ({least_h}) and inside E, {how}", numbers)
