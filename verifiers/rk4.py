"""Default oracle backend: jit-compiled fixed-step RK4 with batching and early termination.

Rollouts run side by side in compiled chunks of K steps. After each chunk, rollouts that entered
E or left C are retired and their slots refilled from the queue, so no work is spent past a
decision. Verdicts are then checked against a run with a step `refine` times finer, and the finer
answer is kept wherever the two disagree.
"""
from __future__ import annotations

import numpy as np

from mpgspec.compile.primitive import INACTIVE, CompiledPrimitive
from mpgspec.oracle.evidence import OracleEvidence, Reason
from mpgspec.oracle.integrator import Chunk, build_chunk
from mpgspec.settings import OracleSettings

SIZES = (1, 4, 16, 64, 256)


class RK4Runner:
    """Evaluates O_B(x0, t_B) for batches of start points of one primitive."""

    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings, dt: float | None = None):
        self.prim = prim
        self.s = settings
        self.dt = dt or settings.dt
        self.chunk: Chunk = build_chunk(prim, self.dt, settings.chunk, settings.jit, settings.jit_flags)
        self._fine: RK4Runner | None = None

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
        """Rollouts in slots of one batch; the bookkeeping of every chunk is vectorised over slots."""
        prim, ch, dt = self.prim, self.chunk, self.dt
        nh, nu, K = ch.nh, ch.nu, ch.K
        tol = self.s.h_tolerance
        lo, hi = prim.system.u_lo, prim.system.u_hi
        n = len(x0s)
        nsteps = np.ceil(np.asarray(horizons, float) / dt - 1e-9).astype(int)
        results: list[OracleEvidence | None] = [None] * n
        Zall = np.vstack([x0s.T, np.asarray(t0s, float)[None, :], np.zeros((1, n)), x0s.T])
        cap = min(self.s.batch, SIZES[-1])
        slots = _Slots(Zall.shape[0], nh, nu)
        qpos, ar = 0, np.arange(K)
        while qpos < n or slots.ids.size:
            if qpos < n and slots.ids.size < cap:
                take = np.arange(qpos, min(n, qpos + cap - slots.ids.size))
                qpos += take.size
                slots.add(Zall[:, take], take)
            m = slots.ids.size
            size = next(sz for sz in SIZES if sz >= m)
            Z = slots.Z if size == m else np.concatenate([slots.Z, np.repeat(slots.Z[:, :1], size - m, axis=1)], axis=1)
            try:
                Zf, out = ch.run(Z)
            except Exception as err:  # a crash is the evidence of the calls in this batch
                for b in range(m):
                    results[slots.ids[b]] = OracleEvidence(0, Reason.ERROR, slots.steps[b] * dt, message=str(err)[:500])
                slots.keep(np.zeros(m, bool), slots.Z)
                continue
            Zf, out = Zf[:, :m], out[:, :m, :]
            H, M, U = out[:nh], out[nh], out[nh + 1:]
            # a step is judged on its own outputs; a non-finite end state fails the chunk's last step
            finite = np.isfinite(out).all(axis=0)
            finite[:, -1] &= np.isfinite(Zf).all(axis=0)
            limit = np.minimum(K, nsteps[slots.ids] - slots.steps + 1)  # evaluations left, s = T included
            valid = ar[None, :] < limit[:, None]
            bad = ((H < -tol).any(axis=0) | ~finite) & valid
            enter = (M > 0) & valid
            has_b, has_e = bad.any(axis=1), enter.any(axis=1)
            kb = np.where(has_b, bad.argmax(axis=1), K)
            ke = np.where(has_e, enter.argmax(axis=1), K)
            upto = ar[None, :] < np.minimum(np.minimum(kb, ke) + 1, limit)[:, None]  # steps before the decision
            if nh:
                slots.min_h = np.minimum(slots.min_h, np.where(upto[None] & (H < INACTIVE / 2), H, np.inf).min(axis=2))
            slots.best_m = np.maximum(slots.best_m, np.where(upto & ~np.isnan(M), M, -np.inf).max(axis=1))
            if nu:
                A = np.abs(U)
                slots.peak = np.maximum(slots.peak, np.where(upto[None] & ~np.isnan(A), A, 0.0).max(axis=2))
                slots.sat |= (((U < lo[:, None, None]) | (U > hi[:, None, None])) & upto[None]).any(axis=(0, 2))
            left = has_b & (~has_e | (kb <= ke))  # C is checked before E at the same sample
            entered = ~left & has_e
            horizon = ~left & ~has_e & (slots.steps + K > nsteps[slots.ids])
            done = left | entered | horizon
            for b in np.flatnonzero(done):
                i = slots.ids[b]
                if left[b]:
                    k = slots.steps[b] + kb[b]
                    ev = (OracleEvidence(0, Reason.INTEGRATION_FAILED, k * dt,
                                         message=_non_finite(out[:, b, kb[b]], nh, kb[b] == K - 1 and
                                                             not np.isfinite(Zf[:, b]).all()))
                          if not finite[b, kb[b]] else
                          OracleEvidence(0, Reason.LEFT_C, k * dt, violated=prim.h_names[int(np.argmin(H[:, b, kb[b]]))]))
                elif entered[b]:
                    k = slots.steps[b] + ke[b]
                    ev = OracleEvidence(1, Reason.ENTERED_E, k * dt, t_enter=k * dt)
                else:
                    k = nsteps[i]
                    ev = OracleEvidence(0, Reason.HORIZON, k * dt)
                ev.steps = int(k)
                ev.min_margins = {nm: (float(v) if np.isfinite(v) else None) for nm, v in zip(prim.h_names, slots.min_h[:, b])}
                ev.best_roa_margin = float(slots.best_m[b])
                ev.peak_input = [float(v) for v in slots.peak[:, b]]
                ev.saturated = bool(slots.sat[b])
                results[i] = ev
            slots.keep(~done, Zf, K)
        return results  # type: ignore[return-value]


def _non_finite(out: np.ndarray, nh: int, end_state: bool) -> str:
    """Which output of a step was NaN or infinite."""
    if np.isfinite(out).all():
        return "non-finite state" if end_state else "non-finite output"
    parts = [name for name, part in (("safety function", out[:nh]), ("RoA margin", out[nh:nh + 1]),
                                     ("input or state", out[nh + 1:])) if not np.isfinite(part).all()]
    return "non-finite " + " and ".join(parts)


class _Slots:
    """Per-slot state of the rollouts in flight: augmented state, job index, steps done, evidence so far."""

    def __init__(self, nz: int, nh: int, nu: int):
        self.Z = np.zeros((nz, 0))
        self.ids = np.zeros(0, int)
        self.steps = np.zeros(0, int)
        self.min_h = np.zeros((nh, 0))
        self.best_m = np.zeros(0)
        self.peak = np.zeros((nu, 0))
        self.sat = np.zeros(0, bool)

    def add(self, Z: np.ndarray, ids: np.ndarray) -> None:
        k = ids.size
        self.Z = np.concatenate([self.Z, Z], axis=1)
        self.ids = np.concatenate([self.ids, ids])
        self.steps = np.concatenate([self.steps, np.zeros(k, int)])
        self.min_h = np.concatenate([self.min_h, np.full((self.min_h.shape[0], k), np.inf)], axis=1)
        self.best_m = np.concatenate([self.best_m, np.full(k, -np.inf)])
        self.peak = np.concatenate([self.peak, np.zeros((self.peak.shape[0], k))], axis=1)
        self.sat = np.concatenate([self.sat, np.zeros(k, bool)])

    def keep(self, mask: np.ndarray, Z_next: np.ndarray, advance: int = 0) -> None:
        """Retire the slots not in mask; the kept ones move on to Z_next, `advance` steps later."""
        self.Z = Z_next[:, mask]
        self.ids, self.steps = self.ids[mask], self.steps[mask] + advance
        self.min_h, self.best_m = self.min_h[:, mask], self.best_m[mask]
        self.peak, self.sat = self.peak[:, mask], self.sat[mask]


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
