"""Default oracle backend: jit-compiled RK4 with batching, early termination and error-aware verdicts.

Rollouts run side by side in compiled chunks of K steps; a step never crosses a clock time where
the safe set or the contact mode switches. Each step reports the safety functions at both ends,
their rates along the flow and an integration error estimate (embedded third-order per step, or
step doubling: see mpgspec.oracle.integrator), from which the judge
(mpgspec.oracle.verdict) bounds what can hide between samples and in the integration error.
The judge runs inside the compiled chunk (mpgspec.oracle.judged): the running error sums, least
values and the decision ride in each rollout's state, so after a chunk of JUDGED_STEPS steps
Python reads the decision flags, keeps the state of the decided rollouts for their evidence and
refills their slots from the queue (RK4Runner(judged=False) hands every step's outputs to the
Python judge instead, as the oracle ran before). Inconclusive rollouts are run again with the
step halved, up to `settings.refinements` times.
"""
from __future__ import annotations

import math

import numpy as np

from mpgspec.compile.primitive import CompiledPrimitive
from mpgspec.oracle.backend import COMPILED, HYBRID
from mpgspec.oracle.evidence import OracleEvidence, Reason
from mpgspec.oracle.integrator import Chunk, build_chunk, build_first, start_states
from mpgspec.oracle.judged import LANES, JudgedChunk, build_judged_chunk, decided_evidence, prebuild
from mpgspec.oracle.verdict import ENVELOPE_STEPS, INCONCLUSIVE, Block, Carry, evidences, judge
from mpgspec.settings import OracleSettings

SIZES = (1, 4, 16, 64, 256)
JUDGED_STEPS = 16
"""Steps per judged chunk call: a decided rollout's slot waits at most this long for a new start point."""


def margin_gain(prim: CompiledPrimitive) -> float:
    """Bound on |d margin / dx|: the square root of W's largest eigenvalue (margin = r - ||dx||_W)."""
    W = np.asarray(prim.W, float)
    return float(np.sqrt(max(np.linalg.eigvalsh(W).max(), 0.0))) if W.size else 0.0


class RK4Runner:
    """Evaluates O_B(x0, t_B) for batches of start points of one primitive."""

    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings, dt: float | None = None,
                 judged: bool | None = None):
        self.prim = prim
        self.s = settings
        self.dt = dt or settings.dt
        # step doubling estimates the margin's error directly; local estimates are state norms
        self.c_margin = 1.0 if settings.error == "doubling" else margin_gain(prim)
        # the judge runs inside the compiled chunk (judged.py) unless asked not to or the judge's
        # blocks (settings.chunk) are no multiple of a chunk of 8 or more steps
        K = math.gcd(JUDGED_STEPS, settings.chunk)
        self.judged = K % LANES == 0 if judged is None else judged
        if self.judged:
            self.chunk: Chunk | JudgedChunk = build_judged_chunk(
                prim, self.dt, K, settings.chunk, settings.h_tolerance, self.c_margin, settings.jit,
                settings.jit_flags, doubling=settings.error == "doubling")
        else:
            self.chunk = build_chunk(prim, self.dt, settings.chunk, settings.jit, settings.jit_flags,
                                     error=settings.error)
        self._fine: RK4Runner | None = None
        self._maps: dict = {}

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray, horizon: np.ndarray | float,
                 level: int = 0) -> list[OracleEvidence]:
        """Verdicts and evidence for each row of x0s started at clock t0s; inconclusive ones refined."""
        x0s, t0s = np.atleast_2d(x0s), np.atleast_1d(t0s)
        T = np.broadcast_to(horizon, (len(t0s),))
        ev = self._run(x0s, t0s, T)
        idx = [i for i, e in enumerate(ev) if e.status == INCONCLUSIVE and e.reason is not Reason.ERROR]
        if not idx or level >= self.s.refinements:
            return ev
        if self._fine is None:
            self._fine = RK4Runner(self.prim, self.s, dt=self.dt / 2, judged=self.judged)
        fine = self._fine.evaluate(x0s[idx], t0s[idx], T[idx], level + 1)
        for i, f in zip(idx, fine):
            f.refined = True
            ev[i] = f
        return ev

    def _first_map(self, n: int):
        """build_first mapped over n start points, called through a FunctionBuffer bound to numpy
        arrays (remembered per n): z (columns) -> (h, RoA margin, u_raw, u) as arrays."""
        if n not in self._maps:
            F = build_first(self.prim, self.dt, self.s.jit).map(n, "serial")
            buf, ev = F.buffer()
            zin, outs = np.zeros(F.nnz_in(0)), [np.zeros(F.nnz_out(i)) for i in range(F.n_out())]
            buf.set_arg(0, memoryview(zin))
            for i, o in enumerate(outs):
                buf.set_res(i, memoryview(o))

            shapes = [(F.size1_out(i), F.size2_out(i)) for i in range(F.n_out())]

            def call(Z, buf=buf, ev=ev, zin=zin, outs=outs, shapes=shapes):
                zin.reshape(Z.shape, order="F")[:] = Z
                ev()
                if buf.ret():
                    raise RuntimeError("the first-sample evaluation failed")
                return [o.reshape(sh, order="F").copy() for o, sh in zip(outs, shapes)]
            self._maps[n] = call
        return self._maps[n]

    def _first(self, Zall: np.ndarray, T: np.ndarray, t0s: np.ndarray, results: list) -> np.ndarray:
        """Judge every start point's first sample in one vectorised call; returns those still open.

        Many of Algorithm 1's start points are decided there (inside E, or outside C, at once),
        so they never take a slot in a compiled chunk.
        """
        n = Zall.shape[1]
        try:
            nz = 2 * self.prim.system.nx + 2
            H, M, UR, U = self._first_map(n)(Zall[:nz])
        except Exception:  # judged with the chunks instead
            return np.arange(n)
        nh, nu = len(self.prim.h_names), self.prim.system.nu
        H, UR, U = H.reshape(nh, n, 1), UR.reshape(nu, n, 1), U.reshape(nu, n, 1)
        zero = np.zeros((n, 1))
        blk = Block(H, H, np.zeros((nh, n, 1)), M.reshape(n, 1), zero, zero, zero, UR, U,
                    np.isfinite(H).all(axis=0) & np.isfinite(M.reshape(n, 1)) & np.isfinite(U).all(axis=0))
        carry = Carry(nh, nu, n)
        d = judge(blk, carry, T, self.s.h_tolerance, self.c_margin, self.prim.system.u_lo, self.prim.system.u_hi)
        decided = np.flatnonzero(d.done & np.isin(d.kind, ("safe", "left_C")))
        for b, ev in zip(decided, evidences(self.prim, blk, carry, d, decided, t0s[decided], self.c_margin)):
            results[b] = ev
        return np.flatnonzero(~np.isin(np.arange(n), decided))

    def _run(self, x0s: np.ndarray, t0s: np.ndarray, horizons: np.ndarray) -> list[OracleEvidence]:
        """Rollouts in slots of one batch: judged inside the compiled chunk, or (judged=False) by the
        Python judge, vectorised over slots."""
        if self.judged:
            return self._run_judged(x0s, t0s, np.asarray(horizons, float))
        return self._run_python(x0s, t0s, horizons)

    def _run_judged(self, x0s: np.ndarray, t0s: np.ndarray, T: np.ndarray) -> list[OracleEvidence]:
        """Slots of [z; J] advanced by short judged chunks; after each, the decided slots' J become
        evidence and free slots take the next start points."""
        ch: JudgedChunk = self.chunk  # type: ignore[assignment]
        t0s = np.asarray(t0s, float)
        results: list[OracleEvidence | None] = [None] * len(x0s)
        Zstart = start_states(self.prim, x0s, t0s, self.s.error == "doubling")
        order = self._first(Zstart, T, t0s, results)
        queue = np.vstack([Zstart[:, order], ch.lay.start(T[order])])
        done_row = ch.nz + ch.lay.slice("done").start
        kind_row = ch.nz + ch.lay.slice("kind").start
        cap, n, qpos = min(self.s.batch, SIZES[-1]), order.size, 0
        Z, ids = queue[:, :0], np.zeros(0, int)
        rows: list[np.ndarray] = []
        Js: list[np.ndarray] = []
        while qpos < n or ids.size:
            if qpos < n and ids.size < cap:
                take = min(n, qpos + cap - ids.size)
                Z, ids = np.hstack([Z, queue[:, qpos:take]]), np.concatenate([ids, np.arange(qpos, take)])
                qpos = take
            try:
                Z = ch.run(Z)
            except Exception:  # a crash is the evidence of the calls that crash, each run alone
                Z, errors = _alone_judged(ch, Z)
                for b, err in errors.items():
                    results[order[ids[b]]] = OracleEvidence(0, Reason.ERROR, 0.0, status="inconclusive",
                                                            message=str(err)[:500])
                ok = ~np.isin(np.arange(ids.size), list(errors))
                Z, ids = Z[:, ok], ids[ok]
            done = Z[done_row] > 0.5
            broken = done & ~np.isfinite(Z[kind_row])  # decided on nothing: a failed evaluation's leftovers
            for b in np.flatnonzero(broken):
                results[order[ids[b]]] = OracleEvidence(0, Reason.ERROR, 0.0, status="inconclusive",
                                                        message=BROKEN_JUDGE)
            if done.any():
                keep = np.flatnonzero(~done)
                done &= ~broken
                rows.append(ids[done])
                Js.append(Z[ch.nz:, done])
                Z, ids = Z[:, keep], ids[keep]
        if rows:  # evidence of every decided rollout in one go
            rows_ = order[np.concatenate(rows)]
            for i, ev in zip(rows_, decided_evidence(ch, np.hstack(Js), t0s[rows_], self.c_margin)):
                results[i] = ev
        return results  # type: ignore[return-value]

    def _run_python(self, x0s: np.ndarray, t0s: np.ndarray, horizons: np.ndarray) -> list[OracleEvidence]:
        """Rollouts in slots of one batch; the bookkeeping of every chunk is vectorised over slots."""
        prim, ch = self.prim, self.chunk
        r, K = ch.rows, ch.K
        lo, hi = prim.system.u_lo, prim.system.u_hi
        T = np.asarray(horizons, float)
        results: list[OracleEvidence | None] = [None] * len(x0s)
        Zall = ch.start(x0s, t0s)
        order = self._first(Zall, T, np.asarray(t0s, float), results)
        Zall = Zall[:, order]
        n = order.size
        cap = min(self.s.batch, SIZES[-1])
        Z, ids = np.zeros((Zall.shape[0], 0)), np.zeros(0, int)
        carry = Carry(r.nh, r.nu)
        qpos = 0
        while qpos < n or ids.size:
            if qpos < n and ids.size < cap:
                take = np.arange(qpos, min(n, qpos + cap - ids.size))
                qpos += take.size
                Z, ids = np.concatenate([Z, Zall[:, take]], axis=1), np.concatenate([ids, take])
                carry.extend(take.size)
            m = ids.size
            size = next(sz for sz in SIZES if sz >= m)
            Zp = Z if size == m else np.concatenate([Z, np.repeat(Z[:, :1], size - m, axis=1)], axis=1)
            try:
                Zf, out = ch.run(Zp)
                Zf, out = Zf[:, :m], out[:, :m, :]
            except Exception:  # a crash is the evidence of the calls that crash, each run alone
                Zf, out, errors = _alone(ch, Z)
                for b, err in errors.items():
                    results[order[ids[b]]] = OracleEvidence(0, Reason.ERROR, 0.0, status="inconclusive",
                                                            message=str(err)[:500])
                ok = ~np.isin(np.arange(m), list(errors))
                Z, ids, Zf, out = Z[:, ok], ids[ok], Zf[:, ok], out[:, ok, :]
                carry.keep(ok)
                m = ids.size
                if not m:
                    continue
            finite = np.isfinite(out).all(axis=0)
            end_ok = np.isfinite(Zf).all(axis=0)
            finite[:, -1] &= end_ok
            blk = Block(out[r.h], out[r.lb], out[r.dh], out[r.margin], out[r.err], out[r.s], out[r.dt],
                        out[r.u_raw], out[r.u], finite, out[r.ds] if r.doubling else None, ENVELOPE_STEPS * self.dt)
            d = judge(blk, carry, T[order[ids]], self.s.h_tolerance, self.c_margin, lo, hi)
            done = np.flatnonzero(d.done)
            msgs = {int(b): _non_finite(out[:, b, int(d.k[b])], r, int(d.k[b]) == K - 1 and not end_ok[b])
                    for b in done if d.kind[b] == "non_finite"}
            rows = order[ids[done]]
            for i, ev in zip(rows, evidences(prim, blk, carry, d, done, np.asarray(t0s, float)[rows], self.c_margin, msgs)):
                results[i] = ev
            keep = ~d.done
            Z, ids = Zf[:, keep], ids[keep]
            carry.keep(keep)
        return results  # type: ignore[return-value]


def _alone(ch, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """Advance each column of Z in a chunk call of its own (after a batch failed): the outputs of
    those that run, NaN for the others, and the error of each column that fails."""
    Zf, outs, errors = np.full(Z.shape, np.nan), [], {}
    for b in range(Z.shape[1]):
        try:
            zf, out = ch.run(Z[:, b:b + 1])
            Zf[:, b] = zf[:, 0]
        except Exception as err:
            errors[b] = err
            out = None
        outs.append(out)
    shape = next((o.shape for o in outs if o is not None), None)
    if shape is None:
        return Zf, np.zeros((0, Z.shape[1], 0)), errors
    return Zf, np.concatenate([o if o is not None else np.full(shape, np.nan) for o in outs], axis=1), errors


BROKEN_JUDGE = ("the compiled rollout left its judge's decision non-finite: an evaluation inside it (e.g. an "
                "optimisation-based control law) failed")
"""The evidence of a rollout marked decided whose decision is NaN (a call that failed without reporting it)."""


def _alone_judged(ch, Z: np.ndarray) -> tuple[np.ndarray, dict]:
    """Advance each column of Z in a judged chunk call of its own (after a batch failed)."""
    Zf, errors = np.full(Z.shape, np.nan), {}
    for b in range(Z.shape[1]):
        try:
            Zf[:, b] = ch.run(Z[:, b:b + 1])[:, 0]
        except Exception as err:
            errors[b] = err
    return Zf, errors


def _non_finite(out: np.ndarray, r, end_state: bool) -> str:
    """Which output of a step was NaN or infinite."""
    if np.isfinite(out).all():
        return "non-finite state" if end_state else "non-finite output"
    parts = [name for name, part in (("safety function", out[r.h]), ("RoA margin", out[r.margin:r.margin + 1]),
                                     ("input", out[r.u_raw]), ("state", out[r.lb.start:r.lb.stop]))
             if not np.isfinite(part).all()]
    return "non-finite " + " and ".join(parts or ["state"])


class RK4Backend:
    """The `rk4` entry point (an OracleBackend): it runs jump maps and compiled code (HYBRID, COMPILED)."""

    name = "rk4"
    description = "jit-compiled RK4, batched, early termination, error-aware three-valued verdicts"
    capabilities = frozenset({HYBRID, COMPILED})

    @staticmethod
    def is_installed() -> bool:
        return True

    @staticmethod
    def runner(prim: CompiledPrimitive, settings: OracleSettings) -> RK4Runner:
        return RK4Runner(prim, settings)

    @staticmethod
    def prebuild(prims: list[CompiledPrimitive], settings: OracleSettings) -> None:
        """The judged chunks RK4Runner builds first, of every primitive at once (gcc side by side)."""
        K = math.gcd(JUDGED_STEPS, settings.chunk)
        if settings.jit and K % LANES == 0:
            doubling = settings.error == "doubling"
            margins = {p.name: 1.0 if doubling else margin_gain(p) for p in prims}
            prebuild(prims, settings.dt, K, settings.chunk, settings.h_tolerance, margins, tuple(settings.jit_flags),
                     doubling)


backend = RK4Backend()
