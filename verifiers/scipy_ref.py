"""Reference oracle backend: scipy's LSODA at tight tolerances, judged on its dense output.

What it guarantees, and what not:
- it integrates each piece between the clock times where the safe set switches separately
  (rtol 1e-10, atol 1e-12, maximum step dt/2), so no window is stepped over, and stops at every
  crossing of a guard of the closed loop (a law's switch or kink, located by the solver's event
  search) to start a new piece just after it, so its error control never spans a kink;
- the dense solution is sampled every dt/4 (and at every switching time); each safety function is
  bounded between samples from its values and its rate along the flow at both ends, and its
  tolerance-based error estimate (10 (atol + rtol |x|) mapped through |dh/dx|) is subtracted, with
  the same three-valued judge as the compiled backend: safe only when every margin exceeds its
  error bound;
- the rate bound assumes that |dh/dt| within dt/4 does not exceed its larger end value (or the
  secant slope); a safety function with features narrower than that and no trace in its rate at
  the samples can still escape, as it can for any sampling method;
- it has no discrete part: systems whose state jumps (contact events, contact schedules) are
  refused with a message naming the missing capability.
It runs one rollout at a time from Python: slow, for cross-checks and benchmarks.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from mpgspec.compile.contacts import wrap_clock
from mpgspec.compile.numeric import numeric, numeric_map
from mpgspec.compile.primitive import INACTIVE, CompiledPrimitive
from mpgspec.oracle.backend import COMPILED
from mpgspec.oracle.evidence import OracleEvidence, Reason
from mpgspec.oracle.verdict import INCONCLUSIVE, Block, Carry, evidence, judge
from mpgspec.settings import OracleSettings
from verifiers.lsoda_piece import lsoda_piece
from verifiers.rk4 import margin_gain

RTOL, ATOL = 1e-10, 1e-12
SAMPLES_PER_STEP = 4
GUARD_STEP = 1e-12
"""After a guard's crossing the next piece starts this long after it (s), moved along the flow."""
MAX_CROSSINGS = 10000
"""More guard crossings than this in one rollout: inconclusive (a law that chatters)."""


class ScipyRunner:
    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings, dt: float | None = None):
        self.prim, self.s = prim, settings
        self.dt = dt or settings.dt
        self.c_margin = margin_gain(prim)
        loop = prim.loop_raw or prim.loop
        a = loop.mx_in() if not loop.is_a("SXFunction") else loop.sx_in()
        x, t, s = a[0], a[1], a[2]
        xdot, hv, u_raw, u = loop.call(a)
        delta = (ca.SX if loop.is_a("SXFunction") else ca.MX).sym("delta", x.shape[0])
        arg = ca.vertcat(x, t, s)
        hdot = ca.jtimes(hv, arg, ca.vertcat(xdot, ca.DM([1.0, 1.0])))
        dh = ca.mtimes(ca.fabs(ca.jacobian(hv, x)), delta)
        self.sample = ca.Function("sample", a + [delta], [hv, hdot, dh, u_raw, u])
        self._samples = numeric_map(self.sample, shared=(3,))  # x_sw: one value for every sample
        self._margins = numeric_map(prim.roa_margin)
        self._fine: ScipyRunner | None = None
        # the solver calls these thousands of times per rollout: on numpy buffers, no DM conversions
        self.f_cl, self.margin = numeric(prim.f_cl), numeric(prim.roa_margin)
        self.guards = numeric(prim.guards.fn) if prim.guards.fn is not None else None

    def evaluate(self, x0s, t0s, horizons, level: int = 0) -> list[OracleEvidence]:
        x0s, t0s = np.atleast_2d(np.asarray(x0s, float)), np.atleast_1d(np.asarray(t0s, float))
        T = np.broadcast_to(np.asarray(horizons, float), (len(t0s),))
        ev = [self.one(x0, float(t0), float(h)) for x0, t0, h in zip(x0s, t0s, T)]
        idx = [i for i, e in enumerate(ev) if e.status == INCONCLUSIVE and e.reason is not Reason.ERROR]
        if idx and level < self.s.refinements:
            if self._fine is None:
                self._fine = ScipyRunner(self.prim, self.s, dt=self.dt / 2)
            for i, f in zip(idx, self._fine.evaluate(x0s[idx], t0s[idx], T[idx], level + 1)):
                f.refined = True
                ev[i] = f
        return ev

    def _cuts(self, t0: float, T: float) -> list[float]:
        """Times since switch-in, in (0, T), at which the clock crosses a switching time."""
        p, out = self.prim, []
        for b in p.boundaries:
            if p.period is None:
                if 0 < b - t0 < T:
                    out.append(b - t0)
            else:
                n = np.ceil((t0 - b) / p.period + 1e-12)
                v = b + n * p.period - t0
                while v < T:
                    if v > 0:
                        out.append(v)
                    v += p.period
        return sorted(set(out))

    def one(self, x0: np.ndarray, t0: float, T: float) -> OracleEvidence:
        f_cl, margin = self.f_cl, self.margin

        def rhs(s, x):
            return f_cl(x, t0 + s, s, x0)[0]

        def enter(s, x):  # inside E by more than the margin's error estimate (as the judge asks)
            err = self.c_margin * np.linalg.norm(_tolerance_error(x))
            return float(margin(x, t0 + s)[0][0]) - 2 * err - 1e-9

        enter.terminal, enter.direction = True, 1
        events = [enter, *self._guard_events(t0, x0)]
        edges = [0.0, *self._cuts(t0, T), T]
        ts, xs = [np.zeros(1)], [x0[:, None]]
        x, status, crossings = x0.copy(), 0, 0
        if enter(0.0, x0) <= 0:
            for a, b in zip(edges, edges[1:]):
                while b - a > 1e-12:
                    try:
                        piece = lsoda_piece(rhs, a, b, x, events, rtol=RTOL, atol=ATOL, max_step=self.dt / 2)
                    except Exception as err:
                        return OracleEvidence(0, Reason.ERROR, a, message=str(err)[:500])
                    end = piece.t
                    n = max(1, int(np.ceil((end - a) / (self.dt / SAMPLES_PER_STEP) - 1e-9)))
                    grid = np.linspace(a, end, n + 1)[1:]
                    Y = piece.sol(grid) if piece.sol is not None and end > a else piece.y[:, None]
                    ts.append(grid)
                    xs.append(Y)
                    x = Y[:, -1]
                    status = piece.status
                    if status != 1 or piece.fired[0] or not np.isfinite(x).all():
                        break  # the piece's end, E entered, a failure
                    crossings += 1  # a guard crossed: the next piece starts just after it, on its new branch
                    if crossings > MAX_CROSSINGS:
                        return OracleEvidence(0, Reason.INCONCLUSIVE, end, status="inconclusive",
                                              message=f"more than {MAX_CROSSINGS} guard crossings (a law that chatters)")
                    a, status = end + GUARD_STEP, 0
                    x = x + GUARD_STEP * rhs(end, x)
                if status != 0 or not np.isfinite(x).all():
                    break
        s = np.concatenate(ts)
        X = np.concatenate(xs, axis=1)
        return self._judge(X, s, t0, T, x0, status == -1)

    def _guard_events(self, t0: float, x0: np.ndarray) -> list:
        """One terminal event per guard of the closed loop (compile/guards.py): the solver stops where
        a law switches or kinks and starts a new piece there, so that its error control never spans
        a kink."""
        fn = self.guards
        if fn is None:
            return []
        events = []
        for j in range(len(self.prim.guards)):
            def ev(s, x, j=j):
                return float(fn(x, t0 + s, s, x0)[0][j])
            ev.terminal, ev.direction = True, 0
            events.append(ev)
        return events

    def _judge(self, X: np.ndarray, s: np.ndarray, t0: float, T: float, x0: np.ndarray, failed: bool) -> OracleEvidence:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            return self._judge_arrays(X, s, t0, T, x0, failed)

    def _judge_arrays(self, X, s, t0, T, x0, failed) -> OracleEvidence:
        p = self.prim
        N = s.size
        delta = _tolerance_error(np.nan_to_num(X, nan=np.inf))
        H, D, DH, UR, U = (v.T for v in self._samples(X.T, (t0 + s)[:, None], s[:, None], x0, delta.T))
        M = self._margins(X.T, (t0 + s)[:, None])[0].ravel()
        nh = H.shape[0]
        K = max(N - 1, 1)
        step = np.diff(s) if N > 1 else np.zeros(1)
        mid = s[:-1] + step / 2 if N > 1 else s[:1]
        act = _active(p, t0 + mid)  # (nh, K)
        i0, i1 = np.arange(K), np.minimum(np.arange(K) + 1, N - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            L = np.maximum(np.maximum(np.abs(D[:, i0]), np.abs(D[:, i1])),
                           np.abs(H[:, i1] - H[:, i0]) / np.where(step > 0, step, np.inf))
            lb = (H[:, i0] + H[:, i1]) / 2 - L * step / 2
        eh = np.nan_to_num(DH, nan=np.inf, posinf=np.inf)  # error estimates at each sample (not accumulated:
        en = np.linalg.norm(np.nan_to_num(delta, nan=np.inf), axis=0)  # the judge gets them as increments)
        finite = np.isfinite(H[:, i0]).all(axis=0) & np.isfinite(lb).all(axis=0) & np.isfinite(X[:, i0]).all(axis=0)
        if failed:
            finite[-1] = False
        # the last sample is judged as the start of a zero-length step
        s_k = s[i0] if N > 1 else s
        dt_k = step if N > 1 else np.zeros(1)
        if N > 1:
            s_k, dt_k = np.append(s_k, s[-1]), np.append(dt_k, 0.0)
            lb = np.concatenate([lb, H[:, -1:]], axis=1)
            act = np.concatenate([act, _active(p, t0 + s[-1:])], axis=1)
            i0 = np.append(i0, N - 1)
            finite = np.append(finite, np.isfinite(X[:, -1]).all() and np.isfinite(H[:, -1]).all() and not failed)
        hs = np.where(act, H[:, i0], INACTIVE)
        lbs = np.where(act, lb, INACTIVE)
        steps_err = np.diff(eh, axis=1, append=eh[:, -1:]) if nh else np.zeros((0, i0.size))
        steps_en = np.diff(en, append=en[-1])
        blk = Block(hs[:, None], lbs[:, None], steps_err[:, None, :i0.size], M[i0][None], steps_en[None, :i0.size],
                    s_k[None], dt_k[None], UR[:, i0][:, None], U[:, i0][:, None], finite[None])
        c = Carry(nh, UR.shape[0], 1)
        c.eh[:, 0] = eh[:, 0] if nh else 0.0
        c.en[0] = en[0]
        d = judge(blk, c, np.array([T]), self.s.h_tolerance, self.c_margin, p.system.u_lo, p.system.u_hi)
        if not d.done[0]:  # solver stopped before T (failure): what was seen is all there is
            d.done[0], d.kind[0], d.k[0] = True, "non_finite" if failed else "horizon", i0.size - 1
        ev = evidence(p, blk, c, d, 0, t0, self.c_margin, "solver failed" if failed else "")
        ev.steps = int(N)
        return ev


def _tolerance_error(x: np.ndarray) -> np.ndarray:
    """Error allowed on each state by the solver's tolerances, with a factor 10 for its accumulation."""
    return 10 * (ATOL + RTOL * np.abs(x))


def _active(p: CompiledPrimitive, t: np.ndarray) -> np.ndarray:
    """(nh, len(t)): is each safety function's window active at clock t (wrapped for periodic primitives)."""
    tc = wrap_clock(t, p.period)
    rows = [np.ones_like(tc, bool) if w is None else (tc >= w[0]) & (tc < w[1]) for w in p.windows]
    return np.array(rows, bool).reshape(len(p.windows), tc.size)


class ScipyBackend:
    """The `scipy` entry point (an OracleBackend): it has no discrete part; it calls compiled code (COMPILED)."""

    name = "scipy"
    description = "scipy LSODA at rtol 1e-10 with the same error-aware judge (reference, slow; no jump maps)"
    capabilities = frozenset({COMPILED})

    @staticmethod
    def is_installed() -> bool:
        return True

    @staticmethod
    def runner(prim: CompiledPrimitive, settings: OracleSettings) -> ScipyRunner:
        return ScipyRunner(prim, settings)


backend = ScipyBackend()
