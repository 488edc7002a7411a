"""Floquet stability of a periodic primitive's orbit and an empirical tube radius around it.

The monodromy matrix Phi(T) comes from RK4 on the state and its variational equation
Phi' = df/dx(x, t) Phi, started on the orbit at x*(t0). Its eigenvalues are the Floquet
multipliers; the orbit is locally exponentially stable when all lie inside the unit circle (for
an autonomous loop, the trivial multiplier 1 along the orbit is set aside). The radius of E is
then sized by simulation at random phases, as in sampling.py, so it is 'empirical'.
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

from mpgspec.oracle.flow import rk4

from .roa_common import PeriodicProblem, RoAResult
from .sampling import Simulator, search


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


class FloquetVerifier:
    name = "floquet"
    description = "Floquet multipliers of the tracked orbit (monodromy by RK4 on the variational equation); " \
                  "tube radius by rollouts at random phases"

    @staticmethod
    def is_installed() -> bool:
        return True

    def estimate(self, problem: PeriodicProblem, options: dict | None = None) -> RoAResult:
        o = dict(options or {})
        if getattr(problem, "source", None) is not None:  # the state jumps: the discrete flow's own map
            from .floquet_hybrid import estimate

            return estimate(problem, o, self.name)
        t_start = time.perf_counter()
        T = float(problem.period)
        m = monodromy(problem, float(o.get("t0", 0.0)), int(o.get("steps", 2000)))
        if not (np.isfinite(m["Phi"]).all() and np.isfinite(m["x_end"]).all() and np.isfinite(m["orbit_defect"])):
            return RoAResult(0.0, "failed", self.name, {"verdict": "non-finite monodromy", "period": T,
                                                         "orbit_defect": m["orbit_defect"]},
                             "the variational equation along x*(t) gave inf or NaN (the closed loop or its "
                             "Jacobian is not finite on the orbit)")
        mu = np.linalg.eigvals(m["Phi"])
        trivial = None
        if m["autonomous"]:
            trivial = int(np.argmin(np.abs(mu - 1)))
        rest = np.delete(mu, trivial) if trivial is not None else mu
        rho = float(np.abs(rest).max(initial=0.0))
        tol = float(o.get("tol", 1e-6))
        ev = {"multipliers": [[z.real, z.imag] for z in mu], "multiplier_moduli": np.abs(mu),
              "spectral_radius": rho, "trivial_multiplier": trivial, "monodromy": m["Phi"],
              "orbit_defect": m["orbit_defect"], "autonomous": m["autonomous"], "period": T,
              "steps_per_period": int(o.get("steps", 2000))}
        if m["orbit_defect"] > float(o.get("orbit_tol", 1e-3)):
            ev["verdict"] = "x*(t) is not a solution"
            return RoAResult(0.0, "failed", self.name, ev, f"the flow from x*(t0) leaves the orbit by "
                             f"{m['orbit_defect']:.3g}: x*(t) is not a trajectory of the closed loop")
        if not rho < 1 - tol:
            ev["verdict"] = "not exponentially stable"
            return RoAResult(0.0, "failed", self.name, ev, f"Floquet multiplier of modulus {rho:.6g} >= 1 - {tol:g}")
        ev["verdict"] = "orbitally exponentially stable" if m["autonomous"] else "locally exponentially stable"
        n = int(o.get("samples", 256))
        conv = float(o.get("conv", 0.02))
        periods = int(o.get("periods", np.clip(np.ceil(np.log(conv / 4) / np.log(max(rho, 1e-12))) + 1, 2, 20)))
        sim = Simulator(problem.f, problem.h, problem.x_star, problem.W, n, periods * T,
                        float(o.get("dt", T / int(o.get("steps_per_period", 200)))), conv)
        rng = np.random.default_rng(o.get("seed", 0))
        r, tube = search(sim, lambda: T * rng.random(n), rng, o)
        ev.update(tube=tube, periods=periods, time_s=time.perf_counter() - t_start)
        if not r > 0 or not np.isfinite(r):  # NaN or inf is no radius
            why = "; an autonomous loop keeps a phase shift, so starts off the orbit need not converge to x*(t)" \
                if m["autonomous"] else ""
            return RoAResult(0.0, "failed", self.name, ev, f"orbit is stable but no sampled tube converged safely{why}")
        return RoAResult(r, "empirical", self.name, ev,
                         f"multipliers inside the unit circle (max |mu| = {rho:.3g}); {tube['simulations']} "
                         f"rollouts at random phases converged safely from W-distance {r:.4g}")


verifier = FloquetVerifier()
