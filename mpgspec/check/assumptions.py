"""Checks of the assumptions Definition 1 makes about every primitive.

- setpoint_dynamics: x*(t) satisfies the closed loop, d/dt x* = f_cl(x*, t) (residual);
- setpoint_safe: x*(t) stays in C(t) over the domain (least h);
- roa_in_safe_set: E(t) lies inside C(t) (sampled points of E plus a local worst-case search; with
  contact constraints, on the contact manifold the constrained flows stay on);
- local_stability: eigenvalues of the closed-loop Jacobian at a fixed setpoint (Floquet
  multipliers of the orbit for periodic primitives, certify/monodromy.py);
- robot_limits (rigid bodies, only when it warns): input bounds, and with the joint_limits block
  joint velocity and position limits, that look like a URDF's placeholders and so bound nothing;
- switching_points (only when it warns): a loop whose switching points are too many to locate.

Periodic primitives whose state jumps (gaits under a contact schedule) are checked on the loop's
own discrete flow (RK4 steps and impacts, certify/hybrid_orbit.py): x*(t) by its orbit defect,
stability by the multipliers of the one-period map with the ground symmetry's neutral directions
set aside, and E on the contact manifold of the feet the schedule holds at each clock time.

Checks evaluate the loop after any motion profile has ended (s large, x_sw = x*). Each result
says how it was obtained: sampled checks are 'empirical', eigenvalue checks 'computed'.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..certify.hybrid_orbit import HybridFlow, orbit
from ..certify.hybrid_orbit import monodromy as hybrid_monodromy
from ..certify.monodromy import monodromy
from ..certify.problem import from_primitive
from ..compile.contacts import held_feet
from ..compile.primitive import CompiledPrimitive
from ..compile.rigidbody.symmetry import NEUTRAL
from ..spec.models import PrimitiveClass
from .evaluate import clock, f_cl, f_cl_many, h_active, h_many, least, offsets
from .roa_manifold import contact_projection as _contact_projection
from .roa_manifold import roa_on_contact_manifold

PLACEHOLDER_EFFORT = 1000.0  # N m: an input bound at least this large bounds nothing a leg can do
PLACEHOLDER_VELOCITY = 1000.0  # rad/s
PLACEHOLDER_POSITION = 9.0  # rad: beyond about 1.4 turns either way (URDFs write +-10 for "no limit")


@dataclass
class AssumptionCheck:
    """One check of one primitive: status pass, info (an expected note, e.g. a transient has no
    stability test), warn (a finding that can hurt) or fail, with the numbers behind it."""

    primitive: str
    name: str
    status: str
    level: str
    message: str
    numbers: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


HYBRID_DT = 0.001
"""Step of the discrete flow on which gaits are checked (that of `mpgspec gait` and the floquet verifier)."""


def _hybrid(p: CompiledPrimitive) -> bool:
    return p.cls is PrimitiveClass.PERIODIC and held_feet(p.contacts) is not None and p.jump is not None


def _hybrid_orbit(p: CompiledPrimitive) -> dict:
    """Orbit defect and reduced multipliers of a gait's discrete flow (computed once per primitive)."""
    if "hybrid_orbit" not in p.cache:
        W = np.asarray(p.W, float)
        flow = HybridFlow(p, HYBRID_DT)
        Xs, defect, least_h = orbit(flow, W)
        neutral = list(NEUTRAL) if p.system.model.n_base else []
        M, found = hybrid_monodromy(flow, Xs[:, 0], neutral)
        p.cache["hybrid_orbit"] = _orbit_record(defect, least_h, M, found)
    return p.cache["hybrid_orbit"]


def _orbit_record(defect: float, least_h: float, M: np.ndarray, found: dict) -> dict:
    """What the gait checks read of an orbit: its defect, least h, the reduced multipliers and the
    neutral ones by name."""
    return {"defect": defect, "least_h": least_h, "mu": np.linalg.eigvals(M),
            "neutral": {k: float(v["multiplier"]) for k, v in found.items()}}


def seed_hybrid_orbit(p: CompiledPrimitive, evidence: dict) -> bool:
    """Take the orbit defect, least h and reduced monodromy the floquet verifier computed while sizing
    E (mpgspec.roa's evidence: exact floats, fresh or read back from the cache) as this primitive's,
    where it ran the same flow (step HYBRID_DT, the neutral directions _hybrid_orbit takes): the
    gait's one-period map is then not run again for Definition 1. Returns whether it was taken."""
    if not _hybrid(p) or "hybrid_orbit" in p.cache or not isinstance(evidence, dict):
        return False
    found = evidence.get("neutral")
    neutral = list(NEUTRAL) if p.system.model.n_base else []
    if (evidence.get("hybrid") is not True or evidence.get("dt") != HYBRID_DT or not isinstance(found, dict)
            or list(found) != neutral):
        return False
    try:
        M = np.array(evidence["monodromy"], float)
        if M.ndim != 2 or M.shape[0] != M.shape[1] or not np.isfinite(M).all():
            return False
        record = _orbit_record(float(evidence["orbit_defect"]), float(evidence["least_h_on_orbit"]), M, found)
    except (KeyError, TypeError, ValueError):
        return False
    p.cache["hybrid_orbit"] = record
    return True


def _event_transient(p: CompiledPrimitive) -> bool:
    return p.cls is PrimitiveClass.TRANSIENT and bool(getattr(p.system, "events", False)) and p.jump is not None


def _transient_defect(p: CompiledPrimitive) -> tuple[float, float]:
    """(largest ||x(t) - x*(t)||_W, its t) along the domain for the discrete flow with contact
    events from x*(t_0), switched in at t_0: the flow a transient's x*(t) must be (Definition 1)."""
    from ..oracle.flow import switched_flow

    W = np.asarray(p.W, float)
    t0, tf = p.domain
    n = int(round((tf - t0) / HYBRID_DT))
    X = switched_flow(p, p.x_star(t0), t0, HYBRID_DT, n)
    worst, at = 0.0, t0
    for i in range(1, n + 1):
        t = t0 + i * HYBRID_DT
        d = X[:, i] - p.x_star(t)
        r = float(np.sqrt(max(d @ W @ d, 0.0))) if np.isfinite(d).all() else np.inf
        if not r <= worst:
            worst, at = r, t
    return worst, at


def setpoint_dynamics(p: CompiledPrimitive, tol: float, n: int = 40) -> AssumptionCheck:
    """max_t |d/dt x*(t) - f_cl(x*(t), t)| by central differences of the setpoint; for gaits the
    orbit defect of the discrete flow (in E's norm), since x*(t) jumps at every touchdown, and for
    transients with contact events the defect of the discrete flow along the domain."""
    if _event_transient(p):
        d, at = _transient_defect(p)
        ok = np.isfinite(d) and d <= tol
        return AssumptionCheck(p.name, "setpoint_dynamics", "pass" if ok else "fail", "computed",
                               f"largest defect {d:.3g} at t = {at:.3g} (the discrete flow with contact events "
                               f"from x*(t_0) over the domain, dt {HYBRID_DT:g}, ||x - x*||_W; tolerance {tol:g})",
                               {"defect": d if np.isfinite(d) else None, "t": at, "tolerance": tol, "dt": HYBRID_DT})
    if _hybrid(p):
        d = _hybrid_orbit(p)["defect"]
        ok = np.isfinite(d) and d <= tol
        return AssumptionCheck(p.name, "setpoint_dynamics", "pass" if ok else "fail", "computed",
                               f"orbit defect {d:.3g} (one period of the discrete flow with impacts from x*(0), "
                               f"dt {HYBRID_DT:g}, largest ||x - x*||_W; tolerance {tol:g})",
                               {"orbit_defect": d if np.isfinite(d) else None, "tolerance": tol, "dt": HYBRID_DT})
    worst, at = 0.0, 0.0
    eps = 1e-6
    for t in clock(p, n):
        xs = p.x_star(t)
        dx = np.zeros_like(xs) if p.cls is PrimitiveClass.FIXED else (p.x_star(t + eps) - p.x_star(t - eps)) / (2 * eps)
        r = float(np.max(np.abs(dx - f_cl(p, xs, t))))
        if not np.isfinite(r) or r > worst:
            worst, at = r, float(t)
    ok = np.isfinite(worst) and worst <= tol
    return AssumptionCheck(p.name, "setpoint_dynamics", "pass" if ok else "fail", "computed",
                           f"max residual {worst:.3g} at t = {at:.3g} (tolerance {tol:g})",
                           {"max_residual": worst if np.isfinite(worst) else None, "t": at, "tolerance": tol})


def setpoint_safe(p: CompiledPrimitive, tol: float, n: int = 40) -> AssumptionCheck:
    """min_t min_i h_i(x*(t), t) over the domain."""
    ts = clock(p, n)
    mins = least(h_many(p, np.array([p.x_star(t) for t in ts]), ts))
    worst, at = np.inf, 0.0
    for t, m in zip(ts, mins):
        if m < worst:
            worst, at = float(m), float(t)
    ok = worst >= -tol
    return AssumptionCheck(p.name, "setpoint_safe", "pass" if ok else "fail", "empirical",
                           f"least h on the setpoint {worst:.3g} at t = {at:.3g}",
                           {"min_h": worst if np.isfinite(worst) else None, "t": at})


def roa_in_safe_set(p: CompiledPrimitive, tol: float, samples: int = 400, seed: int = 0,
                    radius: float | None = None) -> AssumptionCheck:
    """Sample E's boundary (where h is smallest for convex C) and refine the worst point locally.

    With contact constraints the flows stay on the contact manifold (feet on the ground and still),
    so E is checked where they can reach it: points of E, on its boundary and inside, are projected
    onto the manifold of the primitive's contact mode and h is evaluated there. `radius` overrides
    the primitive's radius of E (a narrower stretch of E(t) before touchdowns keeps its ratio), and the clock
    times include one in each such stretch.
    """
    rng = np.random.default_rng(seed)
    W = np.asarray(p.W)
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])  # maps unit vectors of the weighted norm to state offsets
    r = (p.radius if radius is None else radius) * (1 - 1e-9)
    project = _contact_projection(p, W)
    if project is not None:
        return _manifold_check(p, tol, samples, r, **roa_on_contact_manifold(p, samples, rng, W, L, r, project))
    worst, arg = np.inf, None
    for t in clock(p, 8):
        xs = p.x_star(t)
        d = rng.normal(size=(samples, L.shape[1]))
        d = r * float(p.radius_scale(t)) * d / np.linalg.norm(d, axis=1, keepdims=True)
        for k, m in enumerate(least(h_many(p, offsets(xs, L, d), t))):
            if m < worst:
                worst, arg = float(m), (t, d[k])
    if arg is not None:
        t, d0 = arg
        xs = p.x_star(t)

        def obj(z):
            z = r * float(p.radius_scale(t)) * z / max(np.linalg.norm(z), 1e-12)
            h = h_active(p, xs + L @ z, t)
            return float(h.min()) if h.size else 0.0

        from scipy.optimize import minimize  # imported when used: scipy's start-up is a process's slowest
        res = minimize(obj, d0, method="Nelder-Mead", options={"maxiter": 400, "xatol": 1e-6, "fatol": 1e-9})
        worst = min(worst, float(res.fun))
    ok = worst >= -tol
    return AssumptionCheck(p.name, "roa_in_safe_set", "pass" if ok else "fail", "empirical",
                           f"least h on the boundary of E {worst:.3g} ({samples} samples per clock time + local search)",
                           {"min_h": worst if np.isfinite(worst) else None, "samples": samples})


def _manifold_check(p, tol, samples, r, worst, raw_worst, dist, spread, feet) -> AssumptionCheck:
    """The result of roa_in_safe_set on the contact manifold: least h, and how far the projection
    moved the samples (distance to the manifold and the projected radius, in ||.||_W)."""
    ok = worst >= -tol
    dist = np.asarray(dist) if dist else np.zeros(1)
    numbers = {"min_h": worst if np.isfinite(worst) else None, "samples": samples, "interior_samples": samples,
               "contacts": sorted(feet), "projected": len(spread),
               "projection_distance_max": float(dist.max()), "projection_distance_median": float(np.median(dist)),
               "projected_radius_max": float(max(spread, default=0.0)) / r if r > 0 else 0.0,
               "min_h_unprojected": raw_worst if np.isfinite(raw_worst) else None}
    return AssumptionCheck(p.name, "roa_in_safe_set", "pass" if ok else "fail", "empirical",
                           f"least h on E, checked on the contact manifold, {worst:.3g} ({samples} samples per clock "
                           f"time on the boundary of E and {samples} inside, projected onto the manifold (distance in "
                           f"||.||_W max {numbers['projection_distance_max']:.3g}, median "
                           f"{numbers['projection_distance_median']:.3g}) + local search; least h before projection "
                           f"{raw_worst:.3g})", numbers)


def largest_radius_in_safe_set(p: CompiledPrimitive, tol: float = 1e-9, r_max: float | None = None,
                               rel_tol: float = 1e-3, **kw) -> float:
    """The largest radius of E, up to r_max (default: the primitive's), for which roa_in_safe_set
    passes, by bisection with the same samples at every radius."""
    hi = p.radius if r_max is None else r_max
    if roa_in_safe_set(p, tol, radius=hi, **kw).status == "pass":
        return float(hi)
    lo = 0.0
    while hi - lo > rel_tol * hi:
        mid = 0.5 * (lo + hi)
        if roa_in_safe_set(p, tol, radius=mid, **kw).status == "pass":
            lo = mid
        else:
            hi = mid
    return float(lo)


def local_stability(p: CompiledPrimitive, rel_tol: float = 1e-6) -> AssumptionCheck:
    """Fixed primitives: eigenvalues of d f_cl / dx at x* (central differences of the compiled loop).

    Directions that E does not weigh (for example a robot's position on flat ground) may be
    neutral; those eigenvalues give 'warn', not 'fail'.
    """
    if _hybrid(p):
        return hybrid_stability(p)
    if p.cls is PrimitiveClass.PERIODIC:
        return floquet_stability(p)
    if p.cls is not PrimitiveClass.FIXED:
        return AssumptionCheck(p.name, "local_stability", "info", "none",
                               "no stability test for transient primitives (finite domain)", {})
    xs = p.x_star(0.0)
    nx = xs.size
    E = np.diag(np.full(nx, 1e-6))  # row i: the step along x_i
    F = f_cl_many(p, np.concatenate([xs + E, xs - E]), 0.0)
    A = np.ascontiguousarray(((F[:nx] - F[nx:]) / 2e-6).T)  # row-major, as norms and eigvals read it
    if not np.isfinite(A).all():
        return AssumptionCheck(p.name, "local_stability", "fail", "computed",
                               "closed-loop Jacobian at x* is not finite (inf/NaN)", {"max_real": None, "eigenvalues": []})
    ev = np.linalg.eigvals(A)
    tol = rel_tol * max(1.0, float(np.linalg.norm(A)))  # below this, finite differences cannot tell the sign
    re = ev.real.max()
    unstable = int((ev.real > tol).sum())
    neutral = int((np.abs(ev.real) <= tol).sum())
    status = "fail" if unstable else "warn" if neutral else "pass"
    return AssumptionCheck(p.name, "local_stability", status, "computed",
                           f"max Re(eig) {re:.3g}; {unstable} unstable, {neutral} neutral (|Re| <= {tol:.2g}) of {nx}",
                           {"max_real": float(re), "neutral_band": tol, "unstable": unstable, "neutral": neutral,
                            "eigenvalues": [[float(z.real), float(z.imag)] for z in ev]})


def floquet_stability(p: CompiledPrimitive, tol: float = 1e-6) -> AssumptionCheck:
    """Periodic primitives: Floquet multipliers of the orbit (monodromy from the variational equation)."""
    m = monodromy(from_primitive(p))
    if not np.isfinite(m["Phi"]).all():
        return AssumptionCheck(p.name, "local_stability", "fail", "computed",
                               "monodromy matrix is not finite (inf/NaN along x*(t))",
                               {"max_abs_multiplier": None, "multipliers": [], "orbit_defect": None})
    mu = np.linalg.eigvals(m["Phi"])
    if m["autonomous"] and mu.size:  # the multiplier along the orbit is 1 by construction
        mu_rest = np.delete(mu, int(np.argmin(np.abs(mu - 1))))
    else:
        mu_rest = mu
    mags = np.abs(mu_rest)
    worst = float(mags.max()) if mags.size else 0.0
    status = "pass" if worst < 1 - tol else "fail"
    return AssumptionCheck(p.name, "local_stability", status, "computed",
                           f"max |Floquet multiplier| {worst:.3g} over period {p.period:.4g}"
                           + (" (orbitally, one multiplier at 1 set aside)" if m["autonomous"] else ""),
                           {"max_abs_multiplier": worst, "multipliers": [[float(z.real), float(z.imag)] for z in mu],
                            "orbit_defect": m["orbit_defect"]})


def hybrid_stability(p: CompiledPrimitive, tol: float = 1e-6) -> AssumptionCheck:
    """Gaits: multipliers of the one-period map of the discrete flow, reduced by the ground symmetry
    (base x, y and yaw, whose multipliers are 1 on flat ground and are reported apart)."""
    o = _hybrid_orbit(p)
    mags = np.abs(o["mu"])
    worst = float(mags.max()) if mags.size and np.isfinite(mags).all() else float("inf")
    status = "pass" if worst < 1 - tol else "fail"
    neutral = ", ".join(f"{k} {v:.6f}" for k, v in o["neutral"].items())
    return AssumptionCheck(p.name, "local_stability", status, "computed",
                           f"max |Floquet multiplier| {worst:.3g} over period {p.period:.4g} (discrete flow with impacts"
                           + (f"; neutral {neutral}" if neutral else "") + ")",
                           {"max_abs_multiplier": worst if np.isfinite(worst) else None,
                            "multipliers": [[float(z.real), float(z.imag)] for z in o["mu"]],
                            "neutral": o["neutral"], "orbit_defect": o["defect"]})


def robot_limits(p: CompiledPrimitive) -> AssumptionCheck | None:
    """A WARN naming the joints whose limits look like placeholders (None when none do): input bounds
    of |u| >= 1000 N m (the URDF's efforts when system.torque_limit is not given) and, when the
    primitive uses the joint_limits block, velocity limits >= 1000 rad/s and positions |q| >= 9 rad."""
    sys = p.system
    if not getattr(sys, "is_rigid_body", False):
        return None
    m = sys.model
    found = {"torque": [n for n, u in zip(m.joint_names, sys.u_hi) if u >= PLACEHOLDER_EFFORT]}
    if any(str(h).startswith("qdot_max[") for h in p.h_names):
        lo, hi = m.position_limits
        found["velocity"] = [n for n, v in zip(m.joint_names, m.velocity_limits) if v >= PLACEHOLDER_VELOCITY]
        found["position"] = [n for n, a, b in zip(m.joint_names, lo, hi)
                             if max(abs(a), abs(b)) >= PLACEHOLDER_POSITION]
    found = {k: v for k, v in found.items() if v}
    if not found:
        return None
    what = "; ".join(f"{k} of {', '.join(v[:4])}{' ...' if len(v) > 4 else ''}" for k, v in found.items())
    fix = (["system.torque_limit"] if "torque" in found else []) + (
        ["the robot's real limits in the URDF, or safety functions of your own"]
        if {"velocity", "position"} & set(found) else [])
    return AssumptionCheck(p.name, "robot_limits", "warn", "computed",
                           f"limits that look like URDF placeholders bound nothing ({what}): give "
                           + " and ".join(fix),
                           {"placeholders": found, "thresholds": {"torque": PLACEHOLDER_EFFORT,
                                                                  "velocity": PLACEHOLDER_VELOCITY,
                                                                  "position": PLACEHOLDER_POSITION}})


def switching_points(p: CompiledPrimitive) -> AssumptionCheck | None:
    """A WARN when the loop's switching points were too many, or the loop too large, to be located
    (compile/guards.py): its rollouts then step across kinks as if the loop were smooth, and their
    error estimates do not bound the error there (None otherwise)."""
    g = p.guards
    if g.exposed or "more than" not in g.why:
        return None
    return AssumptionCheck(p.name, "switching_points", "warn", "computed",
                           f"the closed loop's switching points are not located ({g.why}): its rollouts step "
                           "across them as if it were smooth, so their error estimates are not bounds there",
                           {"why": g.why})


def check_primitive(p: CompiledPrimitive, h_tol: float = 1e-9, dyn_tol: float = 1e-3) -> list[AssumptionCheck]:
    """All assumption checks of one primitive, in the order of Definition 1 (and robot_limits and
    switching_points when they warn)."""
    extra = [c for c in (robot_limits(p), switching_points(p)) if c is not None]
    return [setpoint_dynamics(p, dyn_tol), setpoint_safe(p, h_tol), roa_in_safe_set(p, h_tol), local_stability(p),
            *extra]
