"""Checks of the assumptions Definition 1 makes about every primitive.

- setpoint_dynamics: x*(t) satisfies the closed loop, d/dt x* = f_cl(x*, t) (residual);
- setpoint_safe: x*(t) stays in C(t) over the domain (least h);
- roa_in_safe_set: E(t) lies inside C(t) (sampled points of E plus a local worst-case search);
- local_stability: eigenvalues of the closed-loop Jacobian at a fixed setpoint (Floquet
  multipliers of the orbit for periodic primitives come from the floquet verifier).

Checks evaluate the loop after any motion profile has ended (s large, x_sw = x*). Each result
says how it was obtained: sampled checks are 'empirical', eigenvalue checks 'computed'.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import minimize

from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..spec.models import PrimitiveClass

S_SETTLED = 1e3  # time since switch-in at which every motion profile has finished


@dataclass
class AssumptionCheck:
    """One check of one primitive: status pass, warn or fail, with the numbers behind it."""

    primitive: str
    name: str
    status: str
    level: str
    message: str
    numbers: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def _clock(p: CompiledPrimitive, n: int) -> np.ndarray:
    a, b = p.t_range
    return np.zeros(1) if p.cls is PrimitiveClass.FIXED else np.linspace(a, b, n, endpoint=False)


def _f(p, x, t):
    return np.array(p.f_cl(x, t, S_SETTLED, x)).ravel()


def _h(p, x, t):
    v = np.array(p.h(x, t, S_SETTLED, x)).ravel()
    return v[np.abs(v) < INACTIVE / 2]


def setpoint_dynamics(p: CompiledPrimitive, tol: float, n: int = 40) -> AssumptionCheck:
    """max_t |d/dt x*(t) - f_cl(x*(t), t)| by central differences of the setpoint."""
    worst, at = 0.0, 0.0
    eps = 1e-6
    for t in _clock(p, n):
        xs = p.x_star(t)
        dx = np.zeros_like(xs) if p.cls is PrimitiveClass.FIXED else (p.x_star(t + eps) - p.x_star(t - eps)) / (2 * eps)
        r = float(np.max(np.abs(dx - _f(p, xs, t))))
        if not np.isfinite(r) or r > worst:
            worst, at = r, float(t)
    ok = np.isfinite(worst) and worst <= tol
    return AssumptionCheck(p.name, "setpoint_dynamics", "pass" if ok else "fail", "computed",
                           f"max residual {worst:.3g} at t = {at:.3g} (tolerance {tol:g})",
                           {"max_residual": worst if np.isfinite(worst) else None, "t": at, "tolerance": tol})


def setpoint_safe(p: CompiledPrimitive, tol: float, n: int = 40) -> AssumptionCheck:
    """min_t min_i h_i(x*(t), t) over the domain."""
    worst, at = np.inf, 0.0
    for t in _clock(p, n):
        h = _h(p, p.x_star(t), t)
        if h.size and h.min() < worst:
            worst, at = float(h.min()), float(t)
    ok = worst >= -tol
    return AssumptionCheck(p.name, "setpoint_safe", "pass" if ok else "fail", "empirical",
                           f"least h on the setpoint {worst:.3g} at t = {at:.3g}",
                           {"min_h": worst if np.isfinite(worst) else None, "t": at})


def roa_in_safe_set(p: CompiledPrimitive, tol: float, samples: int = 400, seed: int = 0) -> AssumptionCheck:
    """Sample E's boundary (where h is smallest for convex C) and refine the worst point locally."""
    rng = np.random.default_rng(seed)
    nx = p.system.nx
    W = p.info.get("roa_W")
    W = np.eye(nx) if W is None else np.asarray(W)
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])  # maps unit vectors of the weighted norm to state offsets
    r = p.radius * (1 - 1e-9)
    worst, arg = np.inf, None
    for t in _clock(p, 8):
        xs = p.x_star(t)
        d = rng.normal(size=(samples, L.shape[1]))
        d = r * d / np.linalg.norm(d, axis=1, keepdims=True)
        for k in range(samples):
            h = _h(p, xs + L @ d[k], t)
            if h.size and h.min() < worst:
                worst, arg = float(h.min()), (t, d[k])
    if arg is not None:
        t, d0 = arg
        xs = p.x_star(t)

        def obj(z):
            z = r * z / max(np.linalg.norm(z), 1e-12)
            h = _h(p, xs + L @ z, t)
            return float(h.min()) if h.size else 0.0

        res = minimize(obj, d0, method="Nelder-Mead", options={"maxiter": 400, "xatol": 1e-6, "fatol": 1e-9})
        worst = min(worst, float(res.fun))
    ok = worst >= -tol
    return AssumptionCheck(p.name, "roa_in_safe_set", "pass" if ok else "fail", "empirical",
                           f"least h on the boundary of E {worst:.3g} ({samples} samples per clock time + local search)",
                           {"min_h": worst if np.isfinite(worst) else None, "samples": samples})


def local_stability(p: CompiledPrimitive, rel_tol: float = 1e-6) -> AssumptionCheck:
    """Fixed primitives: eigenvalues of d f_cl / dx at x* (central differences of the compiled loop).

    Directions that E does not weigh (for example a robot's position on flat ground) may be
    neutral; those eigenvalues give 'warn', not 'fail'.
    """
    if p.cls is PrimitiveClass.PERIODIC:
        return floquet_stability(p)
    if p.cls is not PrimitiveClass.FIXED:
        return AssumptionCheck(p.name, "local_stability", "warn", "none",
                               "no stability test for transient primitives (finite domain)", {})
    xs = p.x_star(0.0)
    nx = xs.size
    A = np.zeros((nx, nx))
    for i in range(nx):
        e = np.zeros(nx)
        e[i] = 1e-6
        A[:, i] = (_f(p, xs + e, 0.0) - _f(p, xs - e, 0.0)) / 2e-6
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
    from verifiers.floquet import monodromy
    from verifiers.roa_common import from_primitive

    m = monodromy(from_primitive(p))
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


def check_primitive(p: CompiledPrimitive, h_tol: float = 1e-9, dyn_tol: float = 1e-3) -> list[AssumptionCheck]:
    """All assumption checks of one primitive, in the order of Definition 1."""
    return [setpoint_dynamics(p, dyn_tol), setpoint_safe(p, h_tol), roa_in_safe_set(p, h_tol), local_stability(p)]
