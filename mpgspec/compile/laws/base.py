"""What every control law sees (ControlContext) and the cubic motion profile of eq. (7)."""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from ..contacts import ContactPlan
from ..exprs import ExprCompiler
from ..system import CompiledSystem


@dataclass
class ControlContext:
    """Symbols available to a control law."""

    sys: CompiledSystem
    t: ca.SX  # primitive clock
    s: ca.SX  # time since switch-in
    x_sw: ca.SX  # state at switch-in
    x_star: ca.SX  # x*(t)
    x_star_dot: ca.SX  # d/dt x*(t)
    x_star_fn: ca.Function  # t -> x*(t)
    env: dict
    ec: ExprCompiler
    fixed: bool
    xdot: ca.SX | None = None  # open-loop xdot(x, u) of the primitive's dynamics mode
    plan: ContactPlan | None = None  # which feet the dynamics hold, and when (None: no feet); a law
    # asks it for the loop's set (plan.feet) and for the mode at the clock (plan.mode(frames, t))
    info: dict = field(default_factory=dict)
    sampled: object | None = None  # hold.SampledLaw: set by a law the oracle solves at a control rate


def cubic_profile(s, duration: float, p0, v0, pf, vf):
    """Eq. (7): cubic from (p0, v0) at s = 0 to (pf, vf) at s = duration; held outside [0, duration]."""
    th = duration
    c0, c1 = p0, v0
    c2 = (3 * (pf - p0) - (2 * v0 + vf) * th) / th**2
    c3 = (2 * (p0 - pf) + (v0 + vf) * th) / th**3
    sc = ca.fmin(ca.fmax(s, 0), th)
    pos = c0 + c1 * sc + c2 * sc**2 + c3 * sc**3
    vel = c1 + 2 * c2 * sc + 3 * c3 * sc**2
    after = s > th
    return ca.if_else(after, pf, pos), ca.if_else(after, vf, vel)
