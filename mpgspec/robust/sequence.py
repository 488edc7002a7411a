"""The project's goal sequence under sampled uncertainty: how often it stays safe in each mode.

Each of `runs` seeded runs draws the plant's parameters and the start error uniformly from their
boxes and a disturbance uniform in its bounds: an input disturbance (or a push without a duration) is
on throughout, piecewise constant over HOLD seconds; a push with a `duration` is the one the robust
cells withstand, on for `duration` seconds after every switch-in (the start included), piecewise
constant over its `segments`, a fresh draw at each switch-in, and off in between. The same draws are run naive (switch
at each command), through the nominal graph and through the robust graph (the switching rules of
mpgspec.execute.sequence: leave a primitive only after its flow entered E, at a verified t_A,
switching in at the verified t_B). All runs of a mode advance together, one mapped step per
active primitive; a run ends at its first unsafe sample (or a failed control law, its evidence).
Rigid bodies step as the robust rollouts do (mpgspec.robust.rigid: contact schedules and events,
a sampled law held between solves).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..compile.contacts import grid_clock
from ..compile.numeric import by_column
from ..compile.primitive import CompiledPrimitive
from ..execute.crosscheck.executor import ExecutorPlan
from ..oracle.flow import rk4
from ..oracle.jit import compile_many, cse
from ..oracle.executors import InProcess
from ..oracle.joint import Map, run
from ..oracle.tasks import Failed
from ..spec.models import PrimitiveClass
from .library import STEP_FLAGS

HOLD = 0.5
"""Seconds a disturbance that is on throughout holds each value."""

PUSHES = 64
"""Pushes drawn per run (a run that switches in more often reuses them in turn)."""


def _step(prim: CompiledPrimitive, plant_fn: ca.Function, Bd: np.ndarray, dt: float) -> ca.Function:
    """(z = [x; clock; s; x_sw], theta, d) -> (z after one RK4 step, h, RoA margin) on the perturbed plant."""
    nx = prim.system.nx
    x, t, s, xsw = ca.SX.sym("x", nx), ca.SX.sym("t"), ca.SX.sym("s"), ca.SX.sym("xsw", nx)
    th, d = ca.SX.sym("th", plant_fn.size1_in(2)), ca.SX.sym("d", Bd.shape[1])

    def f(xx, tt, ss):
        u = prim.control(xx, tt, ss, xsw)[1]
        return plant_fn(xx, u + ca.mtimes(ca.DM(Bd), d) if prim.system.nu else u, th)

    xn, _ = rk4(f, x, (t, s), dt)
    z = ca.vertcat(x, t, s, xsw)
    return cse(ca.Function(f"dstep_{prim.digest()[:16]}", [z, th, d],
                           [ca.vertcat(xn, t + dt, s + dt, xsw), prim.h(xn, t + dt, s + dt, xsw),
                            prim.roa_margin(xn, t + dt)]))


class _Stepper:
    """One primitive's mapped step over the runs: init (x0, clock, theta, d) -> z and step (z, theta,
    d) -> (z next, h, RoA margin), on columns (runs); z = [x; clock; s; x_sw; ...]. Each call maps
    the step over exactly the columns given (the runs in this primitive), not over every run."""

    def __init__(self, step: ca.Function, first: ca.Function | None, rigid: bool):
        self.rigid, self.nz = rigid, step.size1_in(0)
        self.fns = {"step": step, "first": first}
        self._bound: dict[tuple[str, int], _Bound] = {}

    def _fn(self, kind: str, width: int) -> _Bound:
        if (kind, width) not in self._bound:
            self._bound[kind, width] = _Bound(self.fns[kind].map(width))
        return self._bound[kind, width]

    def init(self, X0, T0, TH, D) -> np.ndarray:
        z = np.vstack([X0, T0[None, :], np.zeros((1, X0.shape[1])), X0])
        if not self.rigid:
            return z
        out, hold = self._fn("first", X0.shape[1])(X0, T0[None, :], np.zeros((1, X0.shape[1])), TH, D)
        return np.vstack([z, TH, hold])

    def __call__(self, Z, TH, D):
        step = self._fn("step", Z.shape[1])
        if self.rigid:  # theta rides in z; the step's outputs are (z, [h; margin])
            z, out = step(Z[:self.nz], D)
            return z, out[:-1], out[-1]
        z, h, m = step(Z[:self.nz], TH, D)
        return z, h, m.ravel()


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

    def __init__(self, prims, steppers: dict[str, _Stepper], names: list[str], nd: int, bound, unc, settings, seq,
                 runs: int, seed: int, cols: list[int] | None = None):
        """`cols` (optional): run only these of the `runs` draws (each run's outcome depends on its
        own draws alone, so a block of runs gives the same outcomes as in the whole)."""
        self.prims, self.fns, self.settings, self.seq = prims, steppers, settings, seq
        sys = next(iter(prims.values())).system
        rng = np.random.default_rng(seed)
        lo = np.array([unc.parameters[p].range[0] for p in names])
        hi = np.array([unc.parameters[p].range[1] for p in names])
        self.theta = (lo + rng.random((runs, len(names))) * (hi - lo)).T  # nth x n
        self.err = np.zeros((sys.nx, runs))
        for s, b in unc.initial_state.items():
            self.err[sys.state_names.index(s)] = rng.uniform(-b, b, runs)
        self.steps = int(round(seq.duration / settings.dt))
        self.window, self.hold = push_window(unc)
        if self.window is None:
            shape = (int(np.ceil(seq.duration / HOLD)) + 1, nd, runs)
        else:
            shape = (PUSHES, unc.disturbance.segments, nd, runs)
        bnd = np.asarray(bound, float).reshape((1,) * (len(shape) - 2) + (nd, 1))
        self.dist = rng.uniform(-1, 1, shape) * bnd
        if cols is not None:
            self.theta, self.err, self.dist = self.theta[:, cols], self.err[:, cols], self.dist[..., cols]
        self.n = self.theta.shape[1] if cols is not None else runs
        self.nz = max(f.nz for f in steppers.values())

    def disturbance(self, t: float, since: np.ndarray, pushes: np.ndarray) -> np.ndarray:
        """The disturbance (nd x runs) over the step from t, for runs switched in at `since` for the
        pushes[r]-th time (counting the start as 0)."""
        if self.window is None:
            return self.dist[min(int(t / HOLD), len(self.dist) - 1)]
        j = np.floor((t - since) / self.hold + 1e-9).astype(int)
        on = np.flatnonzero((j >= 0) & (j < self.dist.shape[1]))
        d = np.zeros(self.dist.shape[2:])
        d[:, on] = self.dist[pushes[on] % PUSHES, j[on], :, on].T
        return d

    def _apply(self, fn, cols: np.ndarray, args: list[np.ndarray]):
        """fn on the columns `cols` of args, and the columns whose call failed (a control law that
        found no solution): each is re-run alone (compile/numeric.by_column)."""
        return by_column(fn, [a[:, cols] for a in args])

    def run(self, graph, table, mode: str) -> dict:
        """Safe fraction, per-run outcome and the switches made per edge of one mode ('naive' or
        'graph' with the given graph)."""
        dt = self.settings.dt
        runs = _Runs(self, mode, graph, table)
        for k in range(self.steps):
            t = (k + 1) * dt
            runs.step(t, self.disturbance(k * dt, runs.since, runs.pushes))
            new_goal = runs.commands(t - dt)
            runs.switch(t, new_goal)
            runs.arrive()
        safe = runs.safe
        return _statistics(self.n, int(safe.sum()), int((safe & runs.arrived.all(axis=0)).sum()), list(runs.goals),
                           [int((safe & a).sum()) for a in runs.arrived], [f for f in runs.first if f is not None],
                           runs.cur, runs.taken)


def _statistics(n: int, safe: int, reached: int, goals: list, goals_reached: list, first: list, final: list,
                taken: dict) -> dict:
    """A mode's statistics over n runs: safe and reached counts, per goal the safe runs that arrived in
    it, the first five violations in run order, each run's final primitive, the switches per edge."""
    return {"safe_fraction": safe / n, "safe_runs": safe, "runs": n, "reached_goal": reached, "goals": goals,
            "goals_reached": goals_reached, "first_violation": first[:5], "final": final,
            "switches": [{"from": a, "to": b, "count": c} for (a, b), c in sorted(taken.items())]}


class _Runs:
    """The n runs of one mode between steps: each run's primitive, augmented state, safety, whether
    it entered its E, its first violation and its goal; the switches taken per edge."""

    def __init__(self, ds: DisturbedSequences, mode: str, graph, table):
        self.ds, self.mode, self.graph, self.table = ds, mode, graph, table
        prims, seq, n = ds.prims, ds.seq, ds.n
        self.nx = next(iter(prims.values())).system.nx
        self.cur = [seq.start] * n
        self.cur_a = np.array(self.cur, dtype=object)
        self.Z = np.zeros((ds.nz, n))
        self.safe, self.conv = np.ones(n, bool), np.zeros(n, bool)
        self.margin = np.full(n, -np.inf)  # each run's RoA margin after its last step
        self.since, self.pushes = np.zeros(n), np.zeros(n, int)  # each run's last switch-in: when, how many before
        self.first = [None] * n
        self.goal, self.cmd = [seq.start] * n, 0
        self.goals = [c.goal for c in seq.commands]
        self.arrived = np.zeros((len(self.goals), n), bool)  # run r was in goal i while it was commanded
        self.taken: dict[tuple[str, str], int] = {}  # switches per edge over all runs
        self.plan = ExecutorPlan.of(graph, table, seq, prims) if mode != "naive" and graph is not None else None
        self.trans = {name: p.cls is PrimitiveClass.TRANSIENT for name, p in prims.items()}
        c0 = prims[seq.start].start_clock()
        x0 = prims[seq.start].x_star(c0)[:, None] + ds.err
        self.enter(list(range(n)), seq.start, np.full(n, c0), x0, 0.0)

    def fail(self, r: int, t: float, name: str, why=None) -> None:
        """Run r is unsafe from t on; why: the violated h ({h, value}) or the error."""
        if self.safe[r]:
            self.first[r] = {"t": t, "primitive": name,
                             **(why if isinstance(why, dict) else {"error": why} if why else {})}
        self.safe[r] = False

    def enter(self, rs: list[int], name: str, clocks: np.ndarray, X: np.ndarray, t: float) -> None:
        """Switch primitive `name` in for the runs rs at the given clocks from the states X."""
        ds = self.ds
        d = ds.disturbance(t, self.since, self.pushes)
        cols = np.array(rs)
        fn = ds.fns[name]
        full = np.zeros((self.nx, ds.n)), np.zeros(ds.n)
        full[0][:, cols], full[1][cols] = X, clocks
        outs, failed = ds._apply(lambda a, b, c, e: [fn.init(a, b[0], c, e)], cols,
                                 [full[0], full[1][None, :], ds.theta, d])
        for q in failed:
            self.fail(int(cols[q]), t, name, "the control law found no input at the switch")
        if outs is not None:
            self.Z[:fn.nz, cols] = outs[0]

    def step(self, t: float, d: np.ndarray) -> None:
        """One step of every safe run under the disturbance d; marks violations and entries into E."""
        ds, nx, tol = self.ds, self.nx, self.ds.settings.h_tolerance
        M = np.full(ds.n, -np.inf)
        for name in set(self.cur_a[self.safe]):
            cols = np.flatnonzero((self.cur_a == name) & self.safe)
            fn = ds.fns[name]
            outs, failed = ds._apply(fn, cols, [self.Z[:fn.nz], ds.theta, d])
            for q in failed:
                self.fail(int(cols[q]), t, name, "the control law found no input")
            if outs is None:
                continue
            zf, hc, m = outs
            ok = np.ones(len(cols), bool)
            ok[failed] = False
            self.Z[:fn.nz, cols[ok]], M[cols[ok]] = zf[:, ok], m.ravel()[ok]
            bad = ~np.isfinite(zf[:nx]).all(axis=0) | (hc < -tol).any(axis=0) | ~np.isfinite(hc).all(axis=0)
            for q in np.flatnonzero(bad & ok):
                hq = np.where(np.isfinite(hc[:, q]), hc[:, q], -np.inf)
                j = int(np.argmin(hq)) if len(hq) else None
                self.fail(int(cols[q]), t, name, None if j is None or hq[j] >= -tol else
                          {"h": ds.prims[name].h_names[j], "value": float(hq[j])})
        self.conv |= M > 0
        self.margin = M

    def commands(self, t: float) -> str | None:
        """The goal of the commands due by t (every run's new goal), or None."""
        seq, new_goal = self.ds.seq, None
        while self.cmd < len(seq.commands) and seq.commands[self.cmd].t <= t + 1e-12:
            new_goal = seq.commands[self.cmd].goal
            self.cmd += 1
        if new_goal is not None:
            self.goal = [new_goal] * self.ds.n
        return new_goal

    def arrive(self) -> None:
        """Marks the safe runs that are in the goal commanded now (a goal counts as reached only
        when the run got there while it was the goal, not by never leaving it)."""
        if self.cmd:
            i = self.cmd - 1
            self.arrived[i] |= self.safe & (self.cur_a == self.goals[i])

    def switch(self, t: float, new_goal: str | None) -> None:
        """Move every safe run that switches at t to its next primitive and switch those in."""
        clocks = self.Z[self.nx]
        moves: dict[str, list[tuple[int, float]]] = {}
        for r in np.flatnonzero(self.safe):
            to = self._destination(int(r), clocks[r], t, new_goal)
            if to is not None:
                cur = self.cur[r]
                self.taken[(cur, to[0])] = self.taken.get((cur, to[0]), 0) + 1
                self.cur[r], self.conv[r] = to[0], False
                self.cur_a[r] = to[0]
                self.since[r], self.pushes[r] = t, self.pushes[r] + 1
                moves.setdefault(to[0], []).append((int(r), float(to[1])))
        for name, items in moves.items():
            rs = [r for r, _ in items if self.safe[r]]
            if rs:
                self.enter(rs, name, np.array([c for r, c in items if self.safe[r]]), self.Z[:self.nx, rs], t)

    def _destination(self, r: int, clk: float, t: float, new_goal: str | None):
        """(primitive, clock) run r switches to at t, or None: a naive switch to a new goal, a
        transient's hand-over at the end of its domain, or a verified switch towards the goal."""
        prims, mode, graph, cur = self.ds.prims, self.mode, self.graph, self.cur[r]
        p, trans = prims[cur], self.trans[cur]
        if not (new_goal is not None and mode == "naive" or trans and clk >= p.domain[1] - 1e-9
                or mode != "naive" and self.conv[r] and self.goal[r] != cur and not trans):
            return None
        if mode == "naive" and new_goal is not None and new_goal != cur:
            return (new_goal, prims[new_goal].start_clock())
        if trans and clk >= p.domain[1] - 1e-9:
            tr = graph.edge(cur, p.next) if graph is not None else None
            tb = tr.switch_clock(p.domain[1]) if tr is not None else None
            if mode != "naive" and tb is None:
                self.first[r] = {"t": t, "primitive": cur, "unverified_hand_over": p.next}
                self.safe[r] = False
            return (p.next, tb if tb is not None and mode != "naive" else prims[p.next].start_clock())
        if mode != "naive" and self.goal[r] != cur and self.conv[r] and not trans:
            nxt = (self.table.get(cur) or {}).get(self.goal[r])
            if nxt and nxt != cur:
                c = 0.0 if p.cls is PrimitiveClass.FIXED else grid_clock(clk, p.period)
                tb = self.plan.switch_clock(cur, nxt, c, self.ds.settings.dt / 2)
                if tb is not None and self.plan.admits(cur, nxt, c, self.ds.settings.dt / 2, float(self.margin[r]),
                                                       p.radius_at(clk)):
                    return (nxt, tb)
        return None


def _compiled(built: dict, rigid: bool, settings) -> dict[str, _Stepper]:
    """Steppers of the (step, first) pairs of every primitive, all compiled side by side."""
    fns = [f for pair in built.values() for f in pair if f is not None]
    fns = iter(compile_many(fns, STEP_FLAGS) if settings.jit else fns)
    return {name: _Stepper(next(fns), next(fns) if first is not None else None, rigid)
            for name, (_step_fn, first) in built.items()}


def steppers(spec, prims, settings) -> tuple[dict[str, _Stepper], list[str], int, np.ndarray]:
    """Each primitive's step on the perturbed plant (mapped over the runs it is given), the uncertain
    parameters' names, the disturbance's size and bound."""
    from ..spec.uncertainty_refs import latency_steps
    from .rigid import compiled_step, library_for, robust_plant
    from .rollout import plant

    unc, sys = spec.project.uncertainty, next(iter(prims.values())).system
    names, dist = list(unc.parameters), unc.disturbance
    if sys.is_rigid_body:
        force = dist.force if dist is not None else None
        frame = force.frame if force is not None else sys.base_frames()[0]
        built, shared = {}, {}
        for name, p in prims.items():
            lib = library_for(p, settings)
            parts, path = compiled_step(p, robust_plant(p, frame, lib), names, frame, force is not None, settings,
                                        lib, latency=latency_steps(spec, settings.dt))
            step, first = parts[:2]
            (built if path is None else shared)[name] = (step, first)
        out = {**_compiled(built, True, settings),
               **{name: _Stepper(step, first, True) for name, (step, first) in shared.items()}}
        out = {name: out[name] for name in prims}
        return out, names, 3 if force is not None else 0, np.asarray(force.bound if force else [], float)
    dist_idx = [sys.input_names.index(u) for u in dist.inputs] if dist is not None else []
    bound = np.broadcast_to(np.asarray(dist.bound, float), (len(dist_idx),)) if dist is not None else np.zeros(0)
    Bd = np.zeros((sys.nu, len(dist_idx)))
    for k, i in enumerate(dist_idx):
        Bd[i, k] = 1.0
    P = plant(spec, names)
    out = _compiled({name: (_step(p, P, Bd, settings.dt), None) for name, p in prims.items()}, False, settings)
    return out, names, len(dist_idx), bound


@dataclass
class ModeJob:
    """Some modes of the uncertain sequence, picklable: the spec (without its locators), the
    settings, the runs and seed of the draws, and (mode, graph, lookup table) per mode (graph None:
    naive). The closed loops travel apart, once per worker."""

    spec: object
    settings: object
    runs: int
    seed: int
    modes: list
    cols: list | None = None  # the runs of this job (None: all)


def run_modes(prims: dict, job: ModeJob) -> dict:
    """mode -> statistics of the job's modes, on the same seeded draws (the function an executor maps)."""
    spec, settings = job.spec, job.settings
    fns, names, nd, bound = steppers(spec, prims, settings)
    ds = DisturbedSequences(prims, fns, names, nd, bound, spec.project.uncertainty, settings,
                            spec.project.sequence, job.runs, job.seed, job.cols)
    return {m: ds.run(g, table, "naive" if g is None else "graph") for m, g, table in job.modes}


def sequence_under_uncertainty(spec, prims, settings, graphs: dict, runs: int, seed: int, executor=None,
                               progress=None) -> dict:
    """The project's goal sequence in `runs` seeded draws of its uncertainty, run naive and through
    each graph of `graphs` (mode -> (graph, lookup table)) on the same draws; per mode the safe
    fraction, the safe runs, the safe runs that end in the last goal and the first violations.
    With an executor of several workers the modes are spread over them (each builds the steppers;
    the draws depend on the seed only); a mode whose job raised records the error as its evidence."""
    stage = uncertain_stage(spec, prims, settings, graphs, runs, seed, getattr(executor, "workers", 1))
    return run(stage, executor or InProcess(), progress)


def uncertain_stage(spec, prims, settings, graphs: dict, runs: int, seed: int, workers: int = 1,
                    naive: bool = True):
    """sequence_under_uncertainty as a stage (mpgspec.oracle.joint): the modes (naive unless `naive` is
    False, then one per graph) spread over up to `workers` items of one map (in this process for one);
    with fewer modes than workers, each mode's runs in consecutive blocks, one item each, and the blocks'
    statistics merged (the same as one job's: each run depends on its own draws only)."""
    modes = [("naive", None, {})] * naive + [(m, g, table) for m, (g, table) in graphs.items()]
    workers = max(1, min(workers, max(len(modes), runs)))
    portable = _portable(spec) if workers > 1 else spec
    if len(modes) >= workers:
        jobs = [ModeJob(portable, settings, runs, seed, modes[k::workers]) for k in range(workers)]
    else:
        blocks = [b.tolist() for b in np.array_split(np.arange(runs), workers) if len(b)]
        jobs = [ModeJob(portable, settings, runs, seed, modes, b) for b in blocks]
    if len(jobs) == 1:
        done = [run_modes(prims, jobs[0])]
    else:
        done = yield Map(run_modes, jobs, "sequence under uncertainty", prims,
                         cost=[float(len(job.modes) * (len(job.cols) if job.cols is not None else runs)) for job in jobs])
    parts: dict[str, list] = {}
    for job, res in zip(jobs, done):
        for m, _, _ in job.modes:
            parts.setdefault(m, []).append(_failed_mode(runs, res.error) if isinstance(res, Failed) else res[m])
    out = {m: (got[0] if len(got) == 1 else _merged(got, runs)) for m, got in parts.items()}
    window, hold = push_window(spec.project.uncertainty)
    return {"runs": runs, "seed": seed, "disturbance_hold_s": hold, "disturbance_after_switch_in_s": window,
            "modes": {m: out[m] for m, _, _ in modes}}


def push_window(unc) -> tuple[float | None, float]:
    """(seconds a push is on after each switch-in, None when the disturbance is on throughout; seconds
    each drawn value holds)."""
    dist = unc.disturbance
    force = dist.force if dist is not None else None
    if force is None or force.duration is None:
        return None, HOLD
    return float(force.duration), float(force.duration) / dist.segments


def _merged(blocks: list[dict], runs: int) -> dict:
    """One mode's statistics from those of consecutive blocks of its runs, as DisturbedSequences.run
    gives them for all runs at once; a block that failed fails the mode (its error the evidence)."""
    failed = next((b for b in blocks if "goals" not in b), None)  # _failed_mode's record
    if failed is not None:
        return failed
    taken: dict[tuple[str, str], int] = {}
    for b in blocks:
        for e in b["switches"]:
            taken[(e["from"], e["to"])] = taken.get((e["from"], e["to"]), 0) + e["count"]
    return _statistics(runs, sum(b["safe_runs"] for b in blocks), sum(b["reached_goal"] for b in blocks),
                       blocks[0]["goals"], [sum(v) for v in zip(*(b["goals_reached"] for b in blocks))],
                       [f for b in blocks for f in b["first_violation"]], [c for b in blocks for c in b["final"]], taken)


def _failed_mode(runs: int, error: str) -> dict:
    """The statistics of a mode whose runs raised: none counted safe, the error as the evidence."""
    return {"safe_fraction": 0.0, "safe_runs": 0, "runs": runs, "reached_goal": 0,
            "first_violation": [{"error": error}], "final": [], "switches": []}


def _nowhere(loc, offset=None):
    """The locator of a spec sent to a worker: positions are not needed there."""
    return None


def _portable(spec):
    """The spec without its locators (closures over the YAML positions), so that it pickles."""
    return dataclasses.replace(spec, system_locate=_nowhere, locate=_nowhere,
                               primitives=[dataclasses.replace(p, locate=_nowhere) for p in spec.primitives])
