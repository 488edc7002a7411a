"""Default oracle backend: jit-compiled fixed-step RK4 with batching and early termination.

Rollouts run side by side in compiled chunks of K steps. After each chunk, rollouts that entered
E or left C are retired and their slots refilled from the queue, so no work is spent past a
decision. Verdicts are then checked against a run with a step `refine` times finer, and the finer
answer is kept wherever the two disagree.
"""
from __future__ import annotations

import math

import numpy as np

from mpgspec.compile.primitive import INACTIVE, CompiledPrimitive
from mpgspec.oracle.evidence import OracleEvidence, Reason
from mpgspec.oracle.integrator import Chunk, build_chunk, initial_state
from mpgspec.settings import OracleSettings

SIZES = (1, 4, 16, 64, 256)


class _Job:
    __slots__ = ("i", "steps", "min_h", "best_m", "peak", "sat")

    def __init__(self, i: int, nh: int, nu: int):
        self.i = i
        self.steps = 0
        self.min_h = np.full(nh, np.inf)
        self.best_m = -np.inf
        self.peak = np.zeros(nu)
        self.sat = False


class RK4Runner:
    """Evaluates O_B(x0, t_B) for batches of start points of one primitive."""

    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings, dt: float | None = None):
        self.prim = prim
        self.s = settings
        self.dt = dt or settings.dt
        self.chunk: Chunk = build_chunk(prim, self.dt, settings.chunk, settings.jit, settings.jit_flags)
        self._fine: RK4Runner | None = None

    def horizon_steps(self, horizon: float) -> int:
        return int(math.ceil(horizon / self.dt - 1e-9))

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray, horizon: np.ndarray | float) -> list[OracleEvidence]:
        """Verdicts and evidence for each row of x0s started at clock t0s."""
        ev = self._run(np.atleast_2d(x0s), np.atleast_1d(t0s), np.broadcast_to(horizon, (len(t0s),)))
        if self.s.check == "none" or self.s.refine <= 1:
            return ev
        idx = [i for i, e in enumerate(ev) if self.s.check == "all" or e.verdict == 1]
        if not idx:
            return ev
        if self._fine is None:
            self._fine = RK4Runner(self.prim, self.s.replace(check="none", chunk=self.s.chunk * self.s.refine),
                                   dt=self.dt / self.s.refine)
        fine = self._fine._run(np.atleast_2d(x0s)[idx], np.atleast_1d(t0s)[idx],
                               np.broadcast_to(horizon, (len(t0s),))[idx])
        for i, f in zip(idx, fine):
            f.checked = True
            if f.verdict != ev[i].verdict:
                f.refined = True
                ev[i] = f
            else:
                ev[i].checked = True
        return ev

    def _run(self, x0s: np.ndarray, t0s: np.ndarray, horizons: np.ndarray) -> list[OracleEvidence]:
        prim, ch, dt = self.prim, self.chunk, self.dt
        nh, nu, K = ch.nh, ch.nu, ch.K
        tol = self.s.h_tolerance
        lo, hi = prim.system.u_lo, prim.system.u_hi
        n = len(x0s)
        nsteps = [self.horizon_steps(h) for h in horizons]
        results: list[OracleEvidence | None] = [None] * n
        queue = list(range(n - 1, -1, -1))
        active: list[_Job] = []
        Z = np.zeros((ch.fn.size1_in(0), 0))
        cap = min(self.s.batch, SIZES[-1])
        while queue or active:
            new = []
            while queue and len(active) + len(new) < cap:
                j = _Job(queue.pop(), nh, nu)
                new.append(j)
            if new:
                Zn = np.stack([initial_state(prim, x0s[j.i], t0s[j.i]) for j in new], axis=1)
                Z = np.concatenate([Z, Zn], axis=1)
                active.extend(new)
            m = len(active)
            size = next(s for s in SIZES if s >= m)
            Zp = Z if size == m else np.concatenate([Z, np.repeat(Z[:, :1], size - m, axis=1)], axis=1)
            try:
                Zf, out = ch.run(Zp)
            except Exception as err:  # a crash is the evidence of the calls in this batch
                for j in active:
                    results[j.i] = OracleEvidence(0, Reason.ERROR, j.steps * dt, message=str(err)[:500])
                active, Z = [], Z[:, :0]
                continue
            Zf, out = Zf[:, :m], out[:, :m, :]
            H, M, U = out[:nh], out[nh], out[nh + 1:]
            # a step is judged on its own outputs; a non-finite end state fails the chunk's last step
            finite = np.isfinite(out).all(axis=0)
            finite[:, -1] &= np.isfinite(Zf).all(axis=0)
            bad = (H < -tol).any(axis=0) | ~finite
            enter = M > 0
            keep = []
            for b, j in enumerate(active):
                limit = min(K, nsteps[j.i] - j.steps + 1)  # evaluations left, including s = T
                kb = _first(bad[b, :limit])
                ke = _first(enter[b, :limit])
                stop = min(kb if kb is not None else K, ke if ke is not None else K)
                upto = min(stop + 1, limit)
                hb = H[:, b, :upto]
                act = hb < INACTIVE / 2
                if nh:
                    j.min_h = np.minimum(j.min_h, np.where(act, hb, np.inf).min(axis=1))
                if upto:
                    mb = M[b, :upto]
                    j.best_m = max(j.best_m, float(np.nanmax(mb)) if np.isfinite(mb).any() else -np.inf)
                    ub = U[:, b, :upto]
                    if nu:
                        j.peak = np.maximum(j.peak, np.nanmax(np.abs(ub), axis=1))
                        j.sat = j.sat or bool(((ub < lo[:, None]) | (ub > hi[:, None])).any())
                done = None
                if kb is not None and (ke is None or kb <= ke):
                    k = j.steps + kb
                    if not finite[b, kb]:
                        done = OracleEvidence(0, Reason.INTEGRATION_FAILED, k * dt, message="non-finite state")
                    else:
                        viol = int(np.argmin(H[:, b, kb]))
                        done = OracleEvidence(0, Reason.LEFT_C, k * dt, violated=prim.h_names[viol])
                elif ke is not None:
                    k = j.steps + ke
                    done = OracleEvidence(1, Reason.ENTERED_E, k * dt, t_enter=k * dt)
                elif j.steps + K > nsteps[j.i]:
                    k = nsteps[j.i]
                    done = OracleEvidence(0, Reason.HORIZON, k * dt)
                if done is None:
                    j.steps += K
                    keep.append(b)
                    continue
                done.steps = k
                done.min_margins = {nm: (float(v) if np.isfinite(v) else None)
                                    for nm, v in zip(prim.h_names, j.min_h)}
                done.best_roa_margin = float(j.best_m)
                done.peak_input = [float(p) for p in j.peak]
                done.saturated = j.sat
                results[j.i] = done
            active = [active[b] for b in keep]
            Z = Zf[:, keep]
        return results  # type: ignore[return-value]


def _first(mask: np.ndarray):
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


class RK4Backend:
    """Entry point object: name, capabilities and a factory of runners."""

    name = "rk4"
    description = "jit-compiled fixed-step RK4, batched, early termination, step-halving check"

    @staticmethod
    def is_installed() -> bool:
        return True

    @staticmethod
    def runner(prim: CompiledPrimitive, settings: OracleSettings) -> RK4Runner:
        return RK4Runner(prim, settings)


backend = RK4Backend()
