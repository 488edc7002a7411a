"""Whether each primitive's region of attraction E is empty or collapsed (Definition 1).

Definition 1 gives every primitive a region E = {(x-x*)' W (x-x*) < r^2} that flows entering it
converge from; the graph's edges are claimed only into E. An empty E (r = 0: the verifier failed,
the orbit leaves C, ...) admits no transition, so the project's claims about that primitive are
vacuous: a FAIL. A verified E far smaller than its typical size is a WARN naming the option that
would size it again. The typical size is

- the radius the spec requests (`roa.radius`), when it gives one;
- else the safe set's own scale: the least W-distance from x*(t) to the boundary of C, to first
  order, r_C = min over t and safety functions i of h_i(x*(t)) / ||W^-1/2 grad h_i(x*(t))||
  (the largest W-ball around x* the linearised C admits; for robots with contacts E is checked on
  the contact manifold and may reach further, so this scale is conservative there).

E is collapsed when r < COLLAPSE * typical. A radius the spec gives (method 'given') is the
author's choice and is not compared, but an empty one is still a FAIL; a spec radius kept because
its verifier failed is a WARN.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..spec.models import PrimitiveClass
from .assumptions import AssumptionCheck
from .evaluate import S_SETTLED

COLLAPSE = 0.1
"""E is collapsed below this fraction of its typical size."""

FIXES = {
    "floquet": "roa.options.periods (more periods let a slow transient decay) or roa.options.conv",
    "lyapunov": "roa.options.degree: 4 or roa.options.region: level_set",
    "sos": "roa.options.degree: 4 or roa.options.region: level_set",
    "sampling": "roa.options.horizon (a longer horizon lets a slow transient decay) or roa.options.conv",
}


def _fix(method: str) -> str:
    return FIXES.get(method, f"the options of the {method} verifier (roa.options)")


def safe_set_scale(p: CompiledPrimitive, n: int = 24) -> float:
    """r_C: the least W-distance from x*(t) to the first-order boundary of C over n clock times
    (inf when no active safety function depends on a weighted state; 0 when x* leaves C)."""
    W = np.asarray(p.W, float)
    w, U = np.linalg.eigh(0.5 * (W + W.T))
    keep = w > 1e-12 * max(w.max(), 1e-300)
    Wi = (U[:, keep] / np.sqrt(w[keep])) @ U[:, keep].T  # unweighted states are not moved, as in E
    x, t, xs = ca.MX.sym("x", W.shape[0]), ca.MX.sym("t"), ca.MX.sym("xs", W.shape[0])
    hx = p.h(x, t, S_SETTLED, xs)
    J = ca.Function("dh", [x, t, xs], [hx, ca.jacobian(hx, x)])
    a, b = p.t_range
    times = [0.0] if p.cls is PrimitiveClass.FIXED else np.linspace(a, b, n, endpoint=False)
    best = float("inf")
    for tk in times:
        xk = np.array(p.setpoint(tk), float).ravel()
        h, G = (np.array(v, float) for v in J(xk, tk, xk))
        h = h.ravel()
        scale = np.linalg.norm(G @ Wi, axis=1)
        use = (h < INACTIVE / 2) & (scale > 1e-12)
        if use.any():
            best = min(best, float(np.min(np.maximum(h[use], 0.0) / scale[use])))
    return best


def _scale(p: CompiledPrimitive, memo) -> float:
    key = memo.key("safe_set_scale", p.digest()) if memo else None
    known = memo.get(key) if memo else None
    if known is None:
        known = safe_set_scale(p)
        if memo:
            memo.put(key, known)
    return float(known)


def region_size(p: CompiledPrimitive, rec, memo=None) -> AssumptionCheck | None:
    """FAIL for an empty E, WARN for a collapsed one, None otherwise (rec: the primitive's
    RoARecord, mpgspec.certify.roa; memo, optional, keeps the safe set's scale by content hash)."""
    r = float(p.radius)
    how = f"{rec.method} ({rec.level}): {rec.message}"
    if not r > 0:
        fix = "; try " + _fix(rec.method) if rec.method != "given" else "; give roa.radius > 0"
        return AssumptionCheck(p.name, "roa_size", "fail", rec.level,
                               f"E is empty (r = 0): no transition into {p.name} can be claimed. {how}{fix}",
                               {"radius": r, "method": rec.method})
    if rec.method == "given":
        return None
    if rec.level in ("given", "failed"):  # the verifier failed; E is the spec's radius, not verified
        return AssumptionCheck(p.name, "roa_size", "warn", rec.level,
                               f"E (r = {r:.4g}) is the spec's roa.radius, not verified: {how}; "
                               f"try {_fix(rec.method)}", {"radius": r, "method": rec.method})
    if rec.spec_radius:
        typical, basis = float(rec.spec_radius), "the radius the spec requests (roa.radius)"
    else:
        typical, basis = _scale(p, memo), "the safe set's scale (W-distance from x* to the linearised boundary of C)"
    if not (np.isfinite(typical) and typical > 0) or r >= COLLAPSE * typical:
        return None
    return AssumptionCheck(p.name, "roa_size", "warn", rec.level,
                           f"E is collapsed: r = {r:.4g} is below {COLLAPSE:g} of {basis}, {typical:.4g}; "
                           f"try {_fix(rec.method)}. {how}",
                           {"radius": r, "typical": typical, "fraction": COLLAPSE, "basis": basis,
                            "method": rec.method})
