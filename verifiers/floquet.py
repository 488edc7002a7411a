"""Floquet stability of a periodic primitive's orbit and an empirical tube radius around it.

The monodromy matrix Phi(T) and its Floquet multipliers come from the core
(mpgspec.certify.monodromy); the orbit is locally exponentially stable when all lie inside the
unit circle (for an autonomous loop, the trivial multiplier 1 along the orbit is set aside). The
radius of E is then sized by simulation at random phases, as in sampling.py, so it is 'empirical'.
"""
from __future__ import annotations

import time

import numpy as np

from mpgspec.certify.monodromy import monodromy
from mpgspec.certify.problem import PeriodicProblem, RoAResult

from .floquet_hybrid import grow_periods
from .floquet_hybrid import estimate as estimate_hybrid
from .sampling import Simulator, search


class FloquetVerifier:
    name = "floquet"
    simulates = True  # rollouts only: sized on the executor's workers (certify/roa.py)
    description = "Floquet multipliers of the tracked orbit (monodromy by RK4 on the variational equation); " \
                  "tube radius by rollouts at random phases"

    @staticmethod
    def is_installed() -> bool:
        return True

    def estimate(self, problem: PeriodicProblem, options: dict | None = None) -> RoAResult:
        o = dict(options or {})
        if getattr(problem, "source", None) is not None:  # the state jumps: the discrete flow's own map
            return estimate_hybrid(problem, o, self.name)
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
        r, tube, periods = _size(problem, rho, o)
        ev.update(tube=tube, periods=periods, time_s=time.perf_counter() - t_start)
        if not r > 0 or not np.isfinite(r):  # NaN or inf is no radius
            why = "; an autonomous loop keeps a phase shift, so starts off the orbit need not converge to x*(t)" \
                if m["autonomous"] else ""
            return RoAResult(0.0, "failed", self.name, ev,
                             f"orbit is stable but no sampled tube converged safely within {periods} periods "
                             f"(roa.options.periods, periods_max){why}")
        return RoAResult(r, "empirical", self.name, ev,
                         f"multipliers inside the unit circle (max |mu| = {rho:.3g}); {tube['simulations']} "
                         f"rollouts at random phases converged safely from W-distance {r:.4g}")


def _size(problem: PeriodicProblem, rho: float, o: dict) -> tuple[float, dict, int]:
    """The tube radius over an adaptive number of periods: first the least n with rho^n below
    conv/4, plus one (at most 20); doubled, up to `periods_max`, while the radius collapses (below
    COLLAPSE of r0) and the starts that failed all stayed safe but had not yet converged. A count
    given as `periods` is used as is."""
    T = float(problem.period)
    n = int(o.get("samples", 256))
    conv = float(o.get("conv", 0.02))
    periods = int(o.get("periods", np.clip(np.ceil(np.log(conv / 4) / np.log(max(rho, 1e-12))) + 1, 2, 20)))
    cap = int(o.get("periods_max", max(4 * periods, 24))) if "periods" not in o else periods
    dt = float(o.get("dt", T / int(o.get("steps_per_period", 200))))

    def size(k: int):
        sim = Simulator(problem.f, problem.h, problem.x_star, problem.W, n, k * T, dt, conv)
        rng = np.random.default_rng(o.get("seed", 0))
        return search(sim, lambda: T * rng.random(n), rng, o)

    return grow_periods(size, periods, cap, float(o.get("r0", 0.1)))


verifier = FloquetVerifier()
