"""Rollouts of a target primitive's closed loop on a perturbed plant, and the adversarial disturbance.

The controller is the primitive's own (nominal parameters); the plant is the system's dynamics with
the uncertain parameters as inputs; a disturbance d(t), piecewise constant on `segments` pieces of
the horizon, is added to the saturated input. A rollout is judged as the oracle judges (Definition
4) on its samples: safe when the flow enters E_B before any h_B < -tol. Its margin is the least h
before entry (>= -tol: safe); without entry, the least h when it fell below -tol, else the best RoA
margin reached (<= 0), and -inf for a blow-up. These are sampled verdicts of chosen scenarios: evidence of robustness, not a proof.
"""
from __future__ import annotations

import dataclasses
import functools
import math

import casadi as ca
import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..compile.system import compile_analytic
from ..oracle.flow import rk4
from ..oracle.jit import compile_many, cse
from ..settings import OracleSettings
from .library import STEP_FLAGS


def plant(spec, names: list[str]) -> ca.Function:
    """(x, u, theta) -> xdot of the system with the parameters `names` as the entries of theta."""
    th = ca.SX.sym("theta", len(names))
    params = {**spec.system.parameters, **{n: th[i] for i, n in enumerate(names)}}
    sys = compile_analytic(dataclasses.replace(spec, system=spec.system.model_copy(update={"parameters": params})))
    return ca.Function("plant", [sys.x, sys.u, th], [sys.xdot])


def judge(H: np.ndarray, M: np.ndarray, n: int, tol: float) -> tuple[bool, float, int | None]:
    """(safe, margin, entry sample) of one rollout from its h (nh x N+1) and RoA margins (N+1), first n+1 samples."""
    H, M = H[:, : n + 1], M[: n + 1]
    hmin = H.min(axis=0) if H.shape[0] else np.full(M.shape, np.inf)
    bad = ~np.isfinite(hmin) | ~np.isfinite(M)
    if bad.any():  # a blow-up ends the rollout as unsafe
        k = int(np.argmax(bad))
        hmin, M = hmin[:k], M[:k]
        if not len(M):
            return False, -math.inf, None
    inside = np.flatnonzero(M > 0)
    if inside.size:
        k = int(inside[0])
        worst = float(hmin[: k + 1].min())
        if worst >= -tol:
            return True, worst, k
        return False, worst, k
    if bad.any():
        return False, -math.inf, None
    low = float(hmin.min())
    return False, (low if low < -tol else float(M.max())), None


def judge_flow(H: np.ndarray, n: int, tol: float) -> tuple[bool, float, int, int | None]:
    """(safe, least h, its sample, its row) of one rollout's h (nh x N+1) over its first n+1 samples,
    whatever its RoA margin: the flow from the setpoint stays in C (Definition 1's premise,
    re-checked). A non-finite value counts as -inf; without h the row is None."""
    H = H[:, : n + 1]
    if not H.size:
        return True, math.inf, 0, None
    Hf = np.where(np.isfinite(H), H, -np.inf)
    lows = Hf.min(axis=0)
    k = int(np.argmin(lows))
    return bool(lows[k] >= -tol), float(lows[k]), k, int(np.argmin(Hf[:, k]))


class RobustRollout:
    """Batched rollouts into one target primitive under (theta, d, start error) scenarios."""

    BATCH = 128
    CHUNK = 100  # steps per compiled call; rollouts stop once decided
    GRAD_FLAGS = STEP_FLAGS  # the push gradient's gcc flags (a rigid body's: its gradient-only code)
    libs: tuple = ()  # compiled libraries the step calls (the robot's dynamics), linked in

    def __init__(self, prim: CompiledPrimitive, plant_fn, dist_inputs: list[int], segments: int,
                 settings: OracleSettings, horizon: float, duration: float | None = None, gradient: bool = True):
        self.prim, self.settings, self.gradient = prim, settings, gradient  # the push gradient: only for a search
        self.K = segments
        dt = settings.dt
        self.N = max(1, int(math.ceil(horizon / dt - 1e-9)))
        self.dt = dt
        # steps under the disturbance (its `duration`, else the horizon), cut into K pieces; K: none
        na = self.N if duration is None else min(self.N, max(1, int(math.ceil(duration / dt - 1e-9))))
        n = np.arange(self.N)
        self.seg = np.where(n < na, np.minimum((n * self.K) // na, self.K - 1), self.K)
        step, first, self.nth, self.nd, self.nhold = self._loop(prim, plant_fn, dist_inputs, dt)
        self._step, self._first = step, first
        nx = prim.system.nx
        x0, t0, s0 = ca.MX.sym("x0", nx), ca.MX.sym("t0"), ca.MX.sym("s0")
        TH, D = ca.MX.sym("theta", self.nth), ca.MX.sym("D", self.nd, self.K)
        name = f"robust_{prim.digest()[:16]}_{self.N}_{self.K}_{na}"
        f0 = first(x0, t0, s0, TH, D[:, 0] if self.nd else ca.MX(0, 1))
        self.nh = f0[0].shape[0] - 1
        self.nz = step.size1_in(0)
        zc, Dc = ca.MX.sym("z", self.nz), ca.MX.sym("Dc", self.nd, self.CHUNK)
        zL, outs_c = step.mapaccum("robust_chunk", self.CHUNK)(zc, Dc)
        fns = [ca.Function(name + "_first", [x0, t0, s0, TH, D], [ca.vertcat(*f0)]),
               ca.Function(name + "_chunk", [zc, Dc], [ca.vertcat(zL[:, -1], ca.vec(outs_c))])]
        self.searchable = bool(gradient and self.nd and self.nhold == 0)  # a push gradient exists (built on first use)
        self._name = name
        fns = [cse(fn) for fn in fns]
        if settings.jit:  # the two libraries compile side by side
            fns = compile_many(fns, STEP_FLAGS, libs=self.libs)
        self.first, self.chunk = fns
        self._maps: dict[tuple, ca.Function] = {}

    def _loop(self, prim: CompiledPrimitive, plant_fn: ca.Function, dist_inputs: list[int], dt: float):
        """(step (z, d) -> (z next, [h; RoA margin] at it), first (x0, t0, s0, theta, d) -> ([h; margin],
        hold), nth, nd, hold size) for z = [x; t; s; x_sw; theta; hold]."""
        nx, nu = prim.system.nx, prim.system.nu
        nth, nd = plant_fn.size1_in(2), len(dist_inputs)
        Bd = np.zeros((nu, nd))
        for k, i in enumerate(dist_inputs):
            Bd[i, k] = 1.0
        x, t, s = ca.SX.sym("x", nx), ca.SX.sym("t"), ca.SX.sym("s")
        xsw, th, d = ca.SX.sym("xsw", nx), ca.SX.sym("th", nth), ca.SX.sym("d", nd)

        def f(xx, tt, ss):
            u = prim.control(xx, tt, ss, xsw)[1]
            return plant_fn(xx, u + ca.mtimes(ca.DM(Bd), d) if nu else u, th)

        xn, _ = rk4(f, x, (t, s), dt)
        out = ca.vertcat(prim.h(xn, t + dt, s + dt, xsw), prim.roa_margin(xn, t + dt))
        z = ca.vertcat(x, t, s, xsw, th)
        step = cse(ca.Function("robust_step", [z, d], [ca.vertcat(xn, t + dt, s + dt, xsw, th), out]))
        first = cse(ca.Function("robust_first", [x, t, s, th, d], [ca.vertcat(prim.h(x, t, s, x),
                                                                           prim.roa_margin(x, t)), ca.SX(0, 1)]))
        return step, first, nth, nd, 0

    @functools.cached_property
    def grad(self) -> ca.Function | None:
        """(z, Dc, lz, lo) -> [d/dz; vec(d/dDc)] of lz' z_L + <lo, outs> over one chunk from z: the chunk's
        adjoint, through which gradients runs the reverse sweep chunk by chunk back from the sample it
        differentiates (so a gradient costs the steps up to that sample, not the horizon); in reverse
        mode, compiled on first use (most targets' searches end before it is needed), None where no
        gradient goes through the law."""
        if not self.searchable:
            return None
        step, _ = self._reverse
        L = self.CHUNK
        zc, Dc = ca.MX.sym("z", self.nz), ca.MX.sym("Dc", self.nd, L)
        lz, lo = ca.MX.sym("lz", self.nz), ca.MX.sym("lo", self.nh + 1, L)
        zL, outs = step.mapaccum("robust_acc", L)(zc, Dc)
        obj = ca.dot(lz, zL[:, -1]) + ca.dot(lo, outs)
        fn = cse(ca.Function(self._name + "_grad", [zc, Dc, lz, lo],
                             [ca.vertcat(ca.gradient(obj, zc), ca.vec(ca.gradient(obj, Dc)))]))
        if self.settings.jit:
            fn = compile_many([fn], self.GRAD_FLAGS, libs=self.libs)[0]
        return fn

    @functools.cached_property
    def grad_first(self) -> ca.Function:
        """(x0, t0, theta, d0, w) -> d(w' [h; RoA margin] at switch-in)/d d0: the first sample's own
        dependence on the push (its ground forces), for a sample at switch-in; in CasADi's virtual
        machine (one column at a time, the first sample only)."""
        _, first = self._reverse
        x0, t0 = ca.MX.sym("x0", self.prim.system.nx), ca.MX.sym("t0")
        TH, d0, w = ca.MX.sym("theta", self.nth), ca.MX.sym("d0", self.nd), ca.MX.sym("w", self.nh + 1)
        y0 = first(x0, t0, 0, TH, d0)[0]
        return ca.Function(self._name + "_grad_first", [x0, t0, TH, d0, w], [ca.gradient(ca.dot(w, y0), d0)])

    @functools.cached_property
    def _reverse(self) -> tuple[ca.Function, ca.Function]:
        """_reverse_parts, built once (grad and grad_first share them)."""
        return self._reverse_parts()

    def _reverse_parts(self) -> tuple[ca.Function, ca.Function]:
        """(step, first) with reverse derivatives, for the gradient: here the step's own."""
        return self._step, self._first

    def _map(self, fn: ca.Function, n: int) -> ca.Function:
        key = (fn.name(), n)
        if key not in self._maps:
            self._maps[key] = fn.map(n)
        return self._maps[key]

    def _call(self, fn: ca.Function, n: int, args: list[np.ndarray]) -> np.ndarray:
        """fn on n columns, in mapped batches of at most BATCH (the last one as wide as what is left:
        no column is computed twice), called through a FunctionBuffer on numpy arrays (column-major,
        no DM copies)."""
        if not n:
            return np.zeros((fn.size1_out(0), 0))
        widths = [a.shape[1] // n if a.size else 0 for a in args]
        out = None
        for start in range(0, n, self.BATCH):
            m = min(self.BATCH, n - start)
            F = self._map(fn, m)
            cols = np.arange(start, start + m)
            ins = []
            for a, w in zip(args, widths):
                sel = a[:, (cols[:, None] * w + np.arange(w)).ravel()] if w else a
                ins.append(np.asfortranarray(sel, dtype=float).ravel(order="F"))
            res = np.zeros(F.nnz_out(0))
            buf, ev = F.buffer()
            for i, a in enumerate(ins):
                buf.set_arg(i, memoryview(a))
            buf.set_res(0, memoryview(res))
            ev()
            rows, per = F.size1_out(0), F.size2_out(0) // m
            if out is None:
                out = np.zeros((rows, n * per))
            out[:, start * per:(start + m) * per] = res.reshape(rows, m * per, order="F")
        return out

    def run(self, X0: np.ndarray, T0: np.ndarray, TH: np.ndarray, D: np.ndarray,
            limit: np.ndarray | None = None, tol: float = 0.0, until_entry: bool = True,
            s0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Samples (n, nh + 1, N + 1) of n rollouts and the index of each one's last computed sample;
        X0 (n, nx), T0 (n,), TH (n, nth), D (n, nd, K).

        A rollout stops at the chunk where it is decided (entered E, unless not `until_entry`; h < -tol
        or a non-finite value) or reaches its `limit` steps; its later samples are NaN. s0: the time
        since switch-in at the start (events recorded in the state's clocks count when it is large).
        """
        Y, last, _ = self.run_groups(X0, T0, TH, D, limit, tol, until_entry, s0)
        return Y, last

    def run_groups(self, X0: np.ndarray, T0: np.ndarray, TH: np.ndarray, D: np.ndarray,
                   limit: np.ndarray | None = None, tol: float = 0.0, until_entry: bool = True,
                   s0: float = 0.0, groups: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """run, where rollouts with the same entry of `groups` (n,) are one decision (a cell's
        scenarios: robust only if every one is safe): once one of them is unsafe (h < -tol or a
        non-finite value), the others stop at the end of that chunk, undecided. Also returns which
        rollouts were so stopped (n,) bool. A rollout's samples do not depend on the others in the
        call; the chunks start at fixed steps, so what stops depends on its group only."""
        n, nh, N, L = len(X0), self.nh, self.N, self.CHUNK
        limit = np.full(n, N) if limit is None else np.minimum(np.asarray(limit, int), N)
        Y = np.full((n, nh + 1, N + 1), np.nan)
        D = np.asarray(D, float).reshape(n, self.nd, self.K)
        f0, Z = self._start(X0, T0, TH, D, s0)
        Y[:, :, 0] = f0[: nh + 1].T
        last = np.zeros(n, int)
        D = np.concatenate([D, np.zeros((n, self.nd, 1))], axis=2)  # segment K: no disturbance

        def hits(y, upto):  # (decided, unsafe) within the samples up to index `upto` of y
            k = np.arange(y.shape[2])[None, :] <= upto[:, None]
            bad = ((y[:, :nh] < -tol).any(axis=1) | ~np.isfinite(y).all(axis=1)) & k
            hit = bad | (y[:, nh] > 0) & k if until_entry else bad
            return hit.any(axis=1), bad.any(axis=1)

        cut = np.zeros(n, bool)

        def stop_groups(done, unsafe, idx):  # rollouts still running in a group that one just lost
            if groups is None or not unsafe.any():
                return done
            lost = np.isin(groups[idx], groups[idx[unsafe]])
            cut[idx[lost & ~done]] = True
            return done | lost

        groups = None if groups is None else np.asarray(groups)
        h0, u0 = hits(Y[:, :, :1], np.zeros(n, int))
        idx0 = np.arange(n)
        active = idx0[~stop_groups(h0 | (limit <= 0), u0, idx0)]
        for c0 in range(0, N, L):
            if not active.size:
                break
            na, take = len(active), min(L, N - c0)
            out = self._call(self.chunk, na, [Z[:, active], self._chunk_d(D, active, self._segments(c0))])
            Z[:, active] = out[: self.nz]
            Yc = out[self.nz:].reshape(nh + 1, L, na, order="F")[:, :take].transpose(2, 0, 1)
            Y[active, :, c0 + 1: c0 + 1 + take] = Yc
            last[active] = c0 + take
            upto = limit[active] - c0 - 1  # index of the rollout's last sample within this chunk
            hit, unsafe = hits(Yc, upto)
            active = active[~stop_groups(hit | (upto <= take - 1), unsafe, active)]
        return Y, last, cut

    def gradients(self, X0, T0, TH, D, rows, ks) -> np.ndarray:
        """d Y[row, k] / d D (n, nd, K) of n rollouts, one (row, k) sample each: the chunk starts up to
        each sample's chunk by the forward chunks, then the reverse sweep through the chunks' adjoints
        (grad) from that chunk back to switch-in."""
        n, nh, L, nd = len(X0), self.nh, self.CHUNK, self.nd
        rows, ks = np.asarray(rows, int), np.asarray(ks, int)
        if ks.size and (ks.min() < 0 or ks.max() > self.N):
            raise ValueError(f"samples must lie in 0..{self.N}, not {ks.min()}..{ks.max()}")
        D = np.asarray(D, float).reshape(n, nd, self.K)
        G = np.zeros((n, nd, self.K))
        f0, Z0 = self._start(X0, T0, TH, D, 0.0)
        at0 = np.flatnonzero(ks == 0)  # the sample at switch-in: the first sample's own dependence on d
        for q in at0:
            w = np.zeros(nh + 1)
            w[rows[q]] = 1.0
            G[q, :, 0] = np.asarray(self.grad_first(X0[q], T0[q], self._th(TH[q:q + 1], 1), D[q, :, 0], w)).ravel()
        last = np.where(ks > 0, (ks - 1) // L, -1)  # the chunk holding each sample
        if last.max(initial=-1) < 0:
            return G
        Dx = np.concatenate([D, np.zeros((n, nd, 1))], axis=2)  # segment K: no disturbance
        seg = [self._segments(c0) for c0 in range(0, L * (last.max() + 1), L)]
        Zs = [Z0]
        for c in range(last.max()):  # forward: the state at the start of each chunk that is needed
            on = np.flatnonzero(last > c)
            Z = np.full_like(Zs[0], np.nan)
            Z[:, on] = self._call(self.chunk, len(on), [Zs[c][:, on], self._chunk_d(Dx, on, seg[c])])[: self.nz]
            Zs.append(Z)
        lz = np.zeros((self.nz, n))
        for c in range(last.max(), -1, -1):  # reverse: from each sample's chunk back to switch-in
            on = np.flatnonzero(last >= c)
            lo = np.zeros((nh + 1, L, n))
            here = on[last[on] == c]
            lo[rows[here], (ks[here] - 1) % L, here] = 1.0
            out = self._call(self.grad, len(on), [Zs[c][:, on], self._chunk_d(Dx, on, seg[c]), lz[:, on],
                                                  lo[:, :, on].transpose(0, 2, 1).reshape(nh + 1, len(on) * L)])
            lz[:, on] = out[: self.nz]
            gD = out[self.nz:].reshape(nd, L, len(on), order="F")
            for j in np.flatnonzero(seg[c] < self.K):  # each step's push is its segment's
                G[on, :, seg[c][j]] += gD[:, j].T
        return G

    def _start(self, X0, T0, TH, D, s0: float) -> tuple[np.ndarray, np.ndarray]:
        """(first's outputs, z at switch-in) of n rollouts: [h; RoA margin; hold] at switch-in and
        z = [x; t; s; x_sw; theta; hold], s0 the time since switch-in."""
        n = len(X0)
        S0 = np.full((1, n), float(s0))
        f0 = self._call(self.first, n, [X0.T, T0[None, :], S0, self._th(TH, n), self._d(D, n)])
        return f0, np.vstack([X0.T, T0[None, :], S0, X0.T, self._th(TH, n), f0[self.nh + 1:]])

    def _segments(self, c0: int) -> np.ndarray:
        """The disturbance segment of each step of the chunk starting at step c0 (past the horizon: the last step's)."""
        return self.seg[np.minimum(np.arange(c0, c0 + self.CHUNK), self.N - 1)]

    def _chunk_d(self, Dx: np.ndarray, on: np.ndarray, seg: np.ndarray) -> np.ndarray:
        """The pushes (nd, columns x CHUNK) of rollouts `on` over one chunk whose steps have segments `seg`."""
        if not self.nd:
            return np.zeros((0, len(on) * self.CHUNK))
        return Dx[on][:, :, seg].transpose(1, 0, 2).reshape(self.nd, len(on) * self.CHUNK)

    def _th(self, TH, n):
        return np.asarray(TH, float).reshape(n, -1).T if self.nth else np.zeros((0, n))

    def _d(self, D, n):
        return np.asarray(D, float).transpose(1, 0, 2).reshape(self.nd, n * self.K) if self.nd else np.zeros((0, 0))
