"""The monodromy of a periodic closed loop without jumps: Phi(t0 + T, t0) of x' = f(x, t).

Phi comes from RK4 on the state and its variational equation Phi' = df/dx(x, t) Phi, started on
the orbit at x*(t0). Its eigenvalues are the Floquet multipliers: the orbit is locally
exponentially stable when all lie inside the unit circle (for an autonomous loop, the trivial
multiplier 1 along the orbit is set aside). The assumption checks (check/assumptions.py) and the
floquet verifier read it.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..oracle.flow import rk4
from .problem import PeriodicProblem


def monodromy(problem: PeriodicProblem, t0: float = 0.0, steps: int = 2000) -> dict:
    """Phi(t0 + T, t0), the end state and the largest W-distance of the trajectory from x*(t)."""
    n, T = problem.nx, float(problem.period)
    x, t, Phi, d = ca.SX.sym("x", n), ca.SX.sym("t"), ca.SX.sym("Phi", n, n), ca.SX.sym("d")
    fx = problem.f(x, t)
    J = ca.jacobian(fx, x)
    F = ca.Function("F", [x, Phi, t], [fx, ca.mtimes(J, Phi)])
    h = T / steps
    (xn, Pn), _ = rk4(lambda xP, tt: F(*xP, tt), (x, Phi), (t,), h)
    e = xn - problem.x_star(t + h)
    dn = ca.fmax(d, ca.sqrt(ca.mtimes([e.T, ca.DM(problem.W), e])))
    z = ca.vertcat(x, ca.vec(Phi), t, d)
    step = ca.Function("var_step", [z], [ca.vertcat(xn, ca.vec(Pn), t + h, dn)])
    z0 = np.concatenate([np.array(problem.x_star(t0), float).ravel(), np.eye(n).ravel(order="F"), [t0, 0.0]])
    zT = np.array(step.fold(steps)(z0), float).ravel()
    return {"Phi": zT[n:n + n * n].reshape(n, n, order="F"), "x_end": zT[:n], "orbit_defect": float(zT[-1]),
            "autonomous": not ca.depends_on(fx, t)}
