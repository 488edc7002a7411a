"""Reference oracle backend: scipy's solve_ivp (LSODA) with terminal events on h and on E.

Adaptive, tolerance-controlled and event-located, but driven from Python one rollout at a time;
the benchmark's baseline and a cross-check for the compiled backends.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from mpgspec.compile.primitive import INACTIVE, CompiledPrimitive
from mpgspec.oracle.evidence import OracleEvidence, Reason
from mpgspec.settings import OracleSettings


class ScipyRunner:
    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings, rtol: float = 1e-8, atol: float = 1e-10):
        self.prim, self.s, self.rtol, self.atol = prim, settings, rtol, atol

    def evaluate(self, x0s, t0s, horizons) -> list[OracleEvidence]:
        return [self.one(np.asarray(x0, float), float(t0), float(T)) for x0, t0, T in zip(x0s, t0s, horizons)]

    def one(self, x0: np.ndarray, t0: float, T: float) -> OracleEvidence:
        p, tol = self.prim, self.s.h_tolerance
        nh = len(p.h_names)

        def rhs(s, x):
            return np.asarray(p.f_cl(x, t0 + s, s, x0)).ravel()

        def hv(s, x):
            return np.asarray(p.h(x, t0 + s, s, x0)).ravel()

        def margin(s, x):
            return float(p.roa_margin(x, t0 + s))

        events = []
        for i in range(nh):
            ev = (lambda i: lambda s, x: hv(s, x)[i] + tol)(i)
            ev.terminal, ev.direction = True, -1
            events.append(ev)
        enter = lambda s, x: margin(s, x)
        enter.terminal, enter.direction = True, 1
        events.append(enter)
        h0 = hv(0.0, x0)
        if nh and (h0 < -tol).any():
            return OracleEvidence(0, Reason.LEFT_C, 0.0, violated=p.h_names[int(np.argmin(h0))], method="simulated")
        if margin(0.0, x0) > 0:
            return OracleEvidence(1, Reason.ENTERED_E, 0.0, t_enter=0.0)
        try:
            sol = solve_ivp(rhs, (0.0, T), x0, method="LSODA", events=events, rtol=self.rtol, atol=self.atol)
        except Exception as err:
            return OracleEvidence(0, Reason.ERROR, 0.0, message=str(err)[:500])
        if sol.status == -1 or not np.isfinite(sol.y).all():
            bad = np.flatnonzero(~np.isfinite(sol.y).all(axis=0))
            t_bad = float(sol.t[bad[0]]) if bad.size else float(sol.t[-1])
            return OracleEvidence(0, Reason.INTEGRATION_FAILED, t_bad, message=sol.message if sol.status == -1
                                  else "non-finite state")
        hits = [(float(te[0]), i) for i, te in enumerate(sol.t_events) if len(te)]
        mins = np.min([np.where(np.abs(hv(s, x)) < INACTIVE / 2, hv(s, x), np.inf) for s, x in zip(sol.t, sol.y.T)],
                      axis=0) if nh else []
        mm = {n: float(v) for n, v in zip(p.h_names, mins)}
        if not hits:
            return OracleEvidence(0, Reason.HORIZON, T, min_margins=mm, steps=len(sol.t))
        ts, i = min(hits)
        if i == nh:
            return OracleEvidence(1, Reason.ENTERED_E, ts, t_enter=ts, min_margins=mm, steps=len(sol.t))
        return OracleEvidence(0, Reason.LEFT_C, ts, violated=p.h_names[i], min_margins=mm, steps=len(sol.t))


class ScipyBackend:
    name = "scipy"
    description = "scipy solve_ivp LSODA with terminal events (reference, slow)"

    @staticmethod
    def is_installed() -> bool:
        return True

    @staticmethod
    def runner(prim: CompiledPrimitive, settings: OracleSettings) -> ScipyRunner:
        return ScipyRunner(prim, settings)


backend = ScipyBackend()
