"""The project's goal sequence under sampled uncertainty: how often it stays safe in each mode.

Each of `runs` seeded runs draws the plant's parameters and the start error uniformly from their
boxes and a disturbance that is piecewise constant over `hold` seconds, uniform in its bounds. The
same draws are run naive (switch at each command), through the nominal graph and through the robust
graph (the switching rules of mpgspec.execute.sequence: leave a primitive only after its flow
entered E, at a verified t_A, switching in at the verified t_B). All runs of a mode advance
together, one mapped RK4 step per active primitive.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..oracle.integrator import compile_cached
from ..spec.models import PrimitiveClass

HOLD = 0.5
"""Seconds the sampled disturbance holds each value."""


def _step(prim: CompiledPrimitive, plant_fn: ca.Function, Bd: np.ndarray, dt: float) -> ca.Function:
    """(z = [x; clock; s; x_sw], theta, d) -> (z after one RK4 step, h, RoA margin) on the perturbed plant."""
    nx = prim.system.nx
    x, t, s, xsw = ca.SX.sym("x", nx), ca.SX.sym("t"), ca.SX.sym("s"), ca.SX.sym("xsw", nx)
    th, d = ca.SX.sym("th", plant_fn.size1_in(2)), ca.SX.sym("d", Bd.shape[1])

    def f(xx, tt, ss):
        u = prim.control(xx, tt, ss, xsw)[1]
        return plant_fn(xx, u + ca.mtimes(ca.DM(Bd), d) if prim.system.nu else u, th)

    k1 = f(x, t, s)
    k2 = f(x + dt / 2 * k1, t + dt / 2, s + dt / 2)
    k3 = f(x + dt / 2 * k2, t + dt / 2, s + dt / 2)
    k4 = f(x + dt * k3, t + dt, s + dt)
    xn = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    z = ca.vertcat(x, t, s, xsw)
    return ca.Function(f"dstep_{prim.digest()[:16]}", [z, th, d],
                       [ca.vertcat(xn, t + dt, s + dt, xsw), prim.h(xn, t + dt, s + dt, xsw),
                        prim.roa_margin(xn, t + dt)])


def _start_clock(p: CompiledPrimitive) -> float:
    return p.domain[0] if p.cls is PrimitiveClass.TRANSIENT else 0.0


class _Bound:
    """A mapped Function called through a FunctionBuffer bound once to numpy arrays (column-major)."""

    def __init__(self, F: ca.Function):
        self.buf, self.ev = F.buffer()
        self.ins = [np.zeros(F.size_in(i), order="F") for i in range(F.n_in())]
        self.outs = [np.zeros(F.size_out(i), order="F") for i in range(F.n_out())]
        for i, a in enumerate(self.ins):
            self.buf.set_arg(i, memoryview(a.reshape(-1, order="F")))
        for i, a in enumerate(self.outs):
            self.buf.set_res(i, memoryview(a.reshape(-1, order="F")))

    def __call__(self, *args):
        for a, v in zip(self.ins, args):
            a[...] = v
        self.ev()
        return [o.copy() for o in self.outs]


class DisturbedSequences:
    """Seeded draws of the uncertainty and the sequence run under them, in any mode."""

    def __init__(self, prims, plant_fn, dist_idx, bound, unc, settings, seq, runs: int, seed: int):
        self.prims, self.settings, self.seq, self.n = prims, settings, seq, runs
        sys = next(iter(prims.values())).system
        nu, nd = sys.nu, len(dist_idx)
        Bd = np.zeros((nu, nd))
        for k, i in enumerate(dist_idx):
            Bd[i, k] = 1.0
        rng = np.random.default_rng(seed)
        names = list(unc.parameters)
        lo = np.array([unc.parameters[p].range[0] for p in names])
        hi = np.array([unc.parameters[p].range[1] for p in names])
        self.theta = (lo + rng.random((runs, len(names))) * (hi - lo)).T  # nth x n
        self.err = np.zeros((sys.nx, runs))
        for s, b in unc.initial_state.items():
            self.err[sys.state_names.index(s)] = rng.uniform(-b, b, runs)
        self.steps = int(round(seq.duration / settings.dt))
        pieces = int(np.ceil(seq.duration / HOLD)) + 1
        self.dist = rng.uniform(-1, 1, (pieces, nd, runs)) * np.asarray(bound, float).reshape(1, nd, 1)
        self.fns = {}
        for name, p in prims.items():
            fn = _step(p, plant_fn, Bd, settings.dt)
            fn = compile_cached(fn, settings.jit_flags) if settings.jit else fn
            self.fns[name] = _Bound(fn.map(runs))

    def run(self, graph, table, mode: str) -> dict:
        """Safe fraction, per-run outcome and the switches made per edge of one mode ('naive' or
        'graph' with the given graph)."""
        prims, st, seq, n = self.prims, self.settings, self.seq, self.n
        dt, tol = st.dt, st.h_tolerance
        nx = next(iter(prims.values())).system.nx
        cur = [seq.start] * n
        c0 = _start_clock(prims[seq.start])
        x0 = prims[seq.start].x_star(c0)[:, None] + self.err
        Z = np.vstack([x0, np.full((1, n), c0), np.zeros((1, n)), x0])
        safe, conv = np.ones(n, bool), np.zeros(n, bool)
        first = [None] * n
        goal, cmd = [seq.start] * n, 0
        cur_a = np.array(cur, dtype=object)
        taken: dict[tuple[str, str], int] = {}  # switches per edge over all runs
        trans = {n: p.cls is PrimitiveClass.TRANSIENT for n, p in prims.items()}
        for k in range(self.steps):
            t = (k + 1) * dt
            d = self.dist[min(int(k * dt / HOLD), len(self.dist) - 1)]
            Znew, M, bad = np.empty_like(Z), np.empty(n), np.zeros(n, bool)
            for name in set(cur):
                cols = cur_a == name
                zf, h, m = self.fns[name](Z, self.theta, d)
                Znew[:, cols], M[cols] = zf[:, cols], m.ravel()[cols]
                hc = h[:, cols]
                bad[cols] = ~np.isfinite(zf[:nx, cols]).all(axis=0) | (hc < -tol).any(axis=0) | \
                    ~np.isfinite(hc).all(axis=0)
            Z = Znew
            for r in np.flatnonzero(bad & safe):
                first[r] = {"t": t, "primitive": cur[r]}
            safe &= ~bad
            conv |= M > 0
            new_goal = None
            while cmd < len(seq.commands) and seq.commands[cmd].t <= t - dt + 1e-12:
                new_goal = seq.commands[cmd].goal
                cmd += 1
            if new_goal is not None:
                goal = [new_goal] * n
            clocks = Z[nx]
            for r in range(n):
                p = prims[cur[r]]
                if not (new_goal is not None and mode == "naive" or trans[cur[r]] and clocks[r] >= p.domain[1] - 1e-9
                        or mode != "naive" and conv[r] and goal[r] != cur[r] and not trans[cur[r]]):
                    continue
                clk = clocks[r]
                to = None
                if mode == "naive" and new_goal is not None and new_goal != cur[r]:
                    to = (new_goal, _start_clock(prims[new_goal]))
                elif trans[cur[r]] and clk >= p.domain[1] - 1e-9:
                    tr = graph.edge(cur[r], p.next) if graph is not None else None
                    tb = tr.switch_clock(p.domain[1]) if tr is not None else None
                    if mode != "naive" and tb is None:
                        if safe[r]:
                            first[r] = {"t": t, "primitive": cur[r], "unverified_hand_over": p.next}
                        safe[r] = False
                    to = (p.next, tb if tb is not None and mode != "naive" else _start_clock(prims[p.next]))
                elif mode != "naive" and goal[r] != cur[r] and conv[r] and not trans[cur[r]]:
                    nxt = (table.get(cur[r]) or {}).get(goal[r])
                    tr = graph.edge(cur[r], nxt) if nxt and nxt != cur[r] else None
                    if tr is not None:
                        c = clk - p.period * np.floor(clk / p.period + 1e-9) if p.period else clk
                        c = 0.0 if p.cls is PrimitiveClass.FIXED else c
                        j = int(np.argmin(np.abs(tr.t_A - c)))
                        if abs(tr.t_A[j] - c) <= dt / 2 + 1e-12 and tr.best_t_B[j] is not None:
                            to = (nxt, tr.best_t_B[j])
                if to is not None:
                    taken[(cur[r], to[0])] = taken.get((cur[r], to[0]), 0) + 1
                    cur[r], conv[r] = to[0], False
                    cur_a[r] = to[0]
                    Z[nx:, r] = np.concatenate([[to[1], 0.0], Z[:nx, r]])
        return {"safe_fraction": float(safe.mean()), "safe_runs": int(safe.sum()), "runs": n,
                "first_violation": [f for f in first if f is not None][:5], "final": cur,
                "switches": [{"from": a, "to": b, "count": c} for (a, b), c in sorted(taken.items())]}


def sequence_under_uncertainty(spec, prims, settings, graphs: dict, runs: int, seed: int) -> dict:
    """The project's goal sequence in `runs` seeded draws of its uncertainty, run naive and through
    each graph of `graphs` (mode -> (graph, lookup table)) on the same draws; per mode the safe
    fraction, the safe runs and the first violations."""
    from .rollout import plant

    unc, sys = spec.project.uncertainty, next(iter(prims.values())).system
    dist = unc.disturbance
    dist_idx = [sys.input_names.index(u) for u in dist.inputs] if dist is not None else []
    bound = np.broadcast_to(np.asarray(dist.bound, float), (len(dist_idx),)) if dist is not None else np.zeros(0)
    ds = DisturbedSequences(prims, plant(spec, list(unc.parameters)), dist_idx, bound, unc, settings,
                            spec.project.sequence, runs, seed)
    modes = {"naive": ds.run(None, {}, "naive")}
    modes.update({m: ds.run(g, table, "graph") for m, (g, table) in graphs.items()})
    return {"runs": runs, "seed": seed, "disturbance_hold_s": HOLD, "modes": modes}
