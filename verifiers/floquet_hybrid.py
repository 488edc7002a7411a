"""Floquet multipliers and an empirical tube for periodic primitives whose state jumps (gaits).

The flow, its orbit defect and the monodromy of one period (with `neutral`, base_x, base_y, yaw
of a floating base on flat ground, on the reduced state, the neutral multipliers measured along
the symmetry's generators and reported by name) come from the core, mpgspec.certify.hybrid_orbit.
The tube radius of E is sized by batched rollouts from seeded starts scaled to each radius tried, at
phases over the period and, densely, in the last moments before each contact change (starts put on the
contact manifold of the feet held at their phase), so it is 'empirical'.
"""
from __future__ import annotations

import time
from collections import Counter

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
    flow = HybridFlow(prim, dt, stretch=2 * window_steps(float(o.get("window", 0.02)), dt))  # through and as far beyond
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
    bound = f"; {tube['bounded_by']['text']}" if tube.get("bounded_by") else ""
    return RoAResult(r, "empirical", name, ev,
                     f"multipliers inside the unit circle (max |mu| = {rho:.3g}{neutral_txt}); "
                     f"{tube['simulations']} rollouts ({tube['before_changes']} starts a radius before contact changes) "
                     f"stayed safe and converged from W-distance {r:.4g}{bound}")


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
    return placed(prim, dt, Xs, Wi, r, _directions(m, W.shape[0], rng), k, W), k


def _directions(m: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """m unit-ball directions (rows): the first half inside the ball (uniform in volume), the rest on its sphere."""
    u = unit_sphere(m, n, rng)
    u[: m // 2] *= rng.random((m // 2, 1)) ** (1 / n)
    return u


def radius_scale(prim, t: np.ndarray) -> np.ndarray:
    """E(t)'s radius over r at clocks t: smaller before a touchdown when the spec narrows it there
    (roa.before_touchdown), else 1."""
    scale = getattr(prim, "radius_scale", None)
    return np.asarray(scale(t), float) * np.ones(np.shape(t)) if scale is not None else np.ones(np.shape(t))


def placed(prim, dt: float, Xs: np.ndarray, Wi: np.ndarray, r: float, u: np.ndarray, k: np.ndarray,
           W: np.ndarray) -> np.ndarray:
    """States x*(t_k) + r(t_k) Wi u (r(t) = r, or less before a touchdown: radius_scale), each put on the
    contact manifold of the feet held at its phase."""
    X0 = Xs[:, k] + r * radius_scale(prim, k * dt)[None, :] * (u @ Wi).T
    held = held_feet(prim.contacts)
    if held is not None:  # the starts of each set of held feet at once (each as it would be alone)
        sets = [tuple(held(j * dt)) for j in k]
        for feet in set(sets):
            cols = [j for j, f in enumerate(sets) if f == feet]
            X0[:, cols] = prim.system.project_to_contacts_many(X0[:, cols].T, feet, W).T
    return X0


def contact_changes(prim, dt: float, steps: int) -> np.ndarray:
    """Steps k of one period where the feet held by the schedule change (a touchdown or a lift-off at k)."""
    held = held_feet(prim.contacts)
    if held is None:
        return np.zeros(0, int)
    sets = [set(held(k * dt)) for k in range(steps)]
    return np.array([k for k in range(steps) if sets[k] != sets[k - 1]], int)


def window_steps(window: float, dt: float) -> int:
    """Steps of the window before a contact change where a gait's tube puts its dense starts (at least one)."""
    return max(1, int(round(window / dt)))


def before_changes(prim, dt: float, steps: int, m: int, window: float, rng: np.random.Generator) -> np.ndarray:
    """m phase steps in the last `window` seconds before a scheduled contact change (none for a loop whose
    contacts never change), and before each stretch where E(t) narrows (roa.before_touchdown): where a gait's
    tube is thinnest, a swing foot a little low or late there touches the ground early or misses its
    touchdown, and a foot just planted is loaded as the other pair lifts."""
    changes = contact_changes(prim, dt, steps)
    narrow = [int(round(lo / dt)) % steps for lo, _hi in getattr(prim, "narrow", ())]
    if narrow:  # E(t) narrows before a touchdown: the full radius is thinnest just before it does
        changes = np.unique(np.r_[changes, narrow]).astype(int)
    if not changes.size:
        return np.zeros(0, int)
    w = window_steps(window, dt)
    return rng.choice(np.unique(np.concatenate([(c - np.arange(1, w + 1)) % steps for c in changes])), m)


LOCATE = 8
"""Failing starts of the least radius that failed whose exit from C the sizing locates (one period each)."""


def bounded_by(flow: HybridFlow, r: float, X: np.ndarray, k: np.ndarray, periods: int) -> dict:
    """What bounds the tube: for up to LOCATE of the starts that failed at r (the least radius that failed), the
    safety function at which each first leaves C within a period, its value, its clock and its place against
    the next scheduled contact change (seconds, negative before it); a start that stays in C for the period
    failed later or by not converging within `periods` periods."""
    changes = contact_changes(flow.prim, flow.dt, flow.steps)
    exits, later = [], 0
    for j in range(min(LOCATE, X.shape[1])):
        e = flow.first_exit(X[:, j], float(k[j] * flow.dt))
        if e is None:
            later += 1
            continue
        if changes.size:  # the step that ended at e["t"] against the next change at or after it
            p = int(round(e["t"] / flow.dt)) % flow.steps
            nxt = changes[changes >= p]
            c = int(nxt[0]) if nxt.size else int(changes[0]) + flow.steps
            e["from_change_s"] = round((p - c) * flow.dt, 9)
        exits.append(e)
    funcs = Counter(e["h"] for e in exits).most_common()
    out = {"r": r, "failed": int(X.shape[1]), "located": len(exits), "exits": exits,
           "functions": dict(funcs), "not_in_c_within_a_period": later}
    out["text"] = bounded_text(out, periods)
    return out


def bounded_text(b: dict, periods: int) -> str:
    """One sentence on what bounds the tube, from bounded_by's record."""
    seen = min(LOCATE, b["failed"])
    parts = []
    if b["exits"]:
        names = ", ".join(h if c == 1 else f"{h} ({c})" for h, c in b["functions"].items())
        where = [e["from_change_s"] for e in b["exits"] if "from_change_s" in e]
        when = ""
        if where:
            lo, hi = round(min(where) * 1e3), round(max(where) * 1e3)
            span = f"{-hi}" if lo == hi else f"{-hi}-{-lo}"
            when = (f", {span} ms before a scheduled contact change" if hi < 0 else
                    ", at a scheduled contact change" if lo == 0 == hi else f", {lo:+d} to {hi:+d} ms from a contact change")
        parts.append(f"{len(b['exits'])} of {seen} left C at {names}{when}")
    if b["not_in_c_within_a_period"]:
        parts.append(f"{b['not_in_c_within_a_period']} of {seen} stayed in C for a period (left it later or did not "
                     f"converge within {periods} periods)")
    more = f" (the first {seen} of {b['failed']} located)" if b["failed"] > seen else ""
    return f"bounded where starts at r = {b['r']:.4g} fail{more}: " + "; ".join(parts)


def _tube(flow: HybridFlow, Xs: np.ndarray, W: np.ndarray, periods: int, o: dict):
    """Bisection on r with one set of starts scaled to each radius (so a radius fails whenever a smaller one
    did, up to the contact projection), x*(t_k) + r W^-1/2 u, each put on the contact manifold of the feet
    held at its phase:
    Where the spec narrows E(t) before the touchdowns (roa.before_touchdown), a start's radius there is r times
    that ratio, and the search sizes r with the ratio kept.
    - `samples` starts at phases over the whole period, half inside the ball and half on its sphere, run
      `periods` periods: they must stay in C and end within conv r of the orbit (r, not each start's own
      distance: one deep inside the ball need not contract further than the sphere's);
    - `window_samples` starts on the sphere at phases in the last `window` seconds before a contact change
      (a touchdown or a lift-off), run through it and `window` beyond (2 window in all): they must stay in C;
      past the change the first set vouches for the rest. The failures there are rare (a swing foot a little
      low or late: about 1 in 100 of them at 0.01 on the A1's walks), so they need many starts; the short
      run keeps them cheap, and they go first: a radius they fail needs no full periods.
    Then up to `confirm_rounds` fresh sets of both at the radius found, `confirm_shrink` (0.9) times it after
    each that fails (as the sampling verifier confirms its radius); none passing leaves no radius.
    A start outside C at its radius (some h < -tol there, such as a swing foot below the ground just after
    lift-off) is left out at that radius: the oracle takes a rollout into E only at a sample where it judged
    every h >= -tol (tol: its h_tolerance), so E needs to hold only where C does."""
    prim = flow.prim
    n, window = int(o.get("samples", 48)), float(o.get("window", 0.02))
    conv = float(o.get("conv", 0.05))
    rng = np.random.default_rng(o.get("seed", 0))
    Wi = inverse_root(W)
    tol = float(o.get("oracle_h_tolerance", 0.0))  # the oracle's: it judges h >= -tol safe
    n_near = int(o.get("window_samples", 512))
    log, confirm, rollouts, least_fail = [], [], [0], [None]

    def draw():  # phases and directions: over the period, then before contact changes
        near = before_changes(prim, flow.dt, flow.steps, n_near, window, rng)
        k = np.concatenate([rng.integers(0, flow.steps, n), near])
        return k, np.vstack([_directions(n, W.shape[0], rng), unit_sphere(near.size, W.shape[0], rng)])

    def decided(X, hmin):  # a start already left C or blew up: this radius fails whatever follows
        return bool((hmin < 0).any() or not np.isfinite(X).all())

    def passes(r, starts, into):
        k, u = starts
        X0 = placed(prim, flow.dt, Xs, Wi, r, u, k, W)
        inside = flow.least_h(X0, k * flow.dt) >= -tol
        entry = {"r": r, "outside_c": int((~inside).sum())}
        near = inside.copy()
        near[:n] = False
        if near.any():  # first the cheap and telling ones: through the change and `window` beyond
            rollouts[0] += int(near.sum())
            XT, hmin = flow.run_stretch(X0[:, near], k[near] * flow.dt)
            bad = ~(hmin >= 0) | ~np.isfinite(XT).all(axis=0)
            entry["failed_before_changes"] = int(bad.sum())
            if bad.any():
                into.append({**entry, "failed": int(bad.sum()), "unsafe": int((hmin < 0).sum())})
                failed(r, X0[:, near][:, bad], k[near][bad])
                return False
        inside[n:] = False
        X0, ks = X0[:, inside], k[inside]
        rollouts[0] += int(inside.sum())
        XT, hmin, ran = flow.run_until(X0, ks * flow.dt, periods, decided)
        if ran < periods:
            bad = (hmin < 0) | ~np.isfinite(XT).all(axis=0)
            into.append({**entry, "failed": int(bad.sum()), "unsafe": int((hmin < 0).sum()), "stopped_after_periods": ran})
            failed(r, X0[:, bad], ks[bad])
            return False
        E = XT - Xs[:, ks]  # whole periods later: the same phase
        dist = np.sqrt(np.einsum("ij,ik,kj->j", E, W, E))
        good = np.isfinite(dist) & (dist <= conv * r * radius_scale(prim, ks * flow.dt)) & (hmin >= 0)
        into.append({**entry, "failed": int((~good).sum()), "unsafe": int((hmin < 0).sum()),
                     "worst_final_dist": float(np.nanmax(dist)) if np.isfinite(dist).any() else float("inf")})
        if not good.all():
            failed(r, X0[:, ~good], ks[~good])
        return bool(good.all())

    def failed(r, X, k):  # the failing starts of the least radius that failed: what bounds the tube
        if least_fail[0] is None or r < least_fail[0][0]:
            least_fail[0] = (r, X, k)

    t_start = time.perf_counter()
    starts = draw()
    r, capped, calls = bisect(lambda r: passes(r, starts, log), 0.0, float(o.get("r0", 0.05)),
                              float(o.get("r_max", 2.0)), float(o.get("rtol", 0.05)), grow=2.0)
    shrink = float(o.get("confirm_shrink", 0.9))
    for _ in range(int(o.get("confirm_rounds", 5))):  # fresh starts at the radius found, smaller until they pass
        if r <= 0 or passes(r, draw(), confirm):
            break
        r *= shrink
    else:
        r = 0.0 if confirm else r
    held = held_feet(prim.contacts) is not None
    near = int(starts[0].size - n)
    bounded = bounded_by(flow, *least_fail[0], periods) if least_fail[0] is not None else None
    return r, {"samples_per_radius": n, "before_changes": near, "window_s": window,
               **({"bounded_by": bounded} if bounded else {}),
               "simulations": rollouts[0], "bisection": log,
               "confirm": confirm, "capped": capped, "periods": periods, "dt": flow.dt, "conv": conv,
               "time_s": time.perf_counter() - t_start,
               "starts": "the same starts scaled to each radius" + (", projected onto the contact manifold of the "
                                                                     "feet held at their phase" if held else "")
               + f", inside C; then fresh ones at the radius found, {shrink:g} times it until they pass (confirm_rounds)"}
