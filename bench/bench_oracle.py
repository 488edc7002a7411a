"""Benchmark of the safety oracle (Definition 4) on the pendulum example.

    python bench/bench_oracle.py            # ~2-3 minutes (the scipy reference takes most of it)
    python bench/bench_oracle.py --quick    # ~40 s, fewer points and repeats

Measures, in one process and on the same start points (setpoints x_A*(t_A) of every primitive A on
its grid, paired with every target B and its t_B grid, as Algorithm 1 does):

  (a) the default rk4 oracle (SafetyOracle.evaluate per target B, batched, early termination,
      error-aware three-valued verdicts, inconclusive rollouts refined at dt/2 as the project's
      accuracy preset says), and the same with refinements=0 (the 'low' preset);
  (b) two scipy solve_ivp LSODA oracles, one rollout per call from Python, on a stratified subset
      when the time budget runs out, scaled per call: the LSODA baseline (terminal events on each
      h and on E, rtol 1e-8, atol 1e-10, written here as the scipy backend used to be) and the
      current 'scipy' backend (rtol 1e-10, atol 1e-12, max_step dt/2, dense output judged every
      dt/4 by the same error-aware judge as rk4), with the verdicts of both against rk4's;
  (c) the compiled integration loop alone: the same compiled chunks (integrator.build_chunk) over
      the full horizon, batched and padded the same way, with no early termination and no
      evidence processing (the floor); a replay of exactly the chunk calls the oracle made (its
      compiled work without its Python bookkeeping); and, built here, a plain RK4 chunk as the
      code had it before the error-aware verdicts (one loop evaluation at the step start for
      xdot, h, u_raw, u, three f_cl evaluations for k2..k4; outputs h, RoA margin, u_raw) run the
      same way, so that new chunk / plain chunk is what the error-aware check costs in compiled work;

then whole-graph builds (mpgspec.api.build) per accuracy preset. Prints a markdown table and
writes it to bench/RESULTS.md. See bench/README.md for what every number means.
"""
from __future__ import annotations

import atexit as _atexit
import os as _os
import shutil as _shutil
import tempfile as _tempfile

_TMP_DIRS: list[str] = []  # compile caches this run created; removed at exit
_atexit.register(lambda: [_shutil.rmtree(d, ignore_errors=True) for d in _TMP_DIRS])
if "MPGSPEC_CACHE" not in _os.environ:  # cold cache: JIT is measured
    _TMP_DIRS.append(_tempfile.mkdtemp(prefix="mpgspec-bench-"))
    _os.environ["MPGSPEC_CACHE"] = _TMP_DIRS[-1]
import argparse
import contextlib
import dataclasses
import datetime as _dt
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca
import common  # noqa: E402  (bench/common.py)
from common import med_ratio, rounds  # noqa: E402
from plain_rk4 import build_plain_chunk  # noqa: E402  (bench/plain_rk4.py)
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from mpgspec.api import build, compile_project, settings_for  # noqa: E402
from mpgspec.graph.build import grids  # noqa: E402
from mpgspec.oracle.evidence import OracleEvidence, Reason  # noqa: E402
from mpgspec.oracle.integrator import Chunk, build_chunk, initial_state  # noqa: E402
from mpgspec.oracle.judged import JudgedChunk  # noqa: E402
from mpgspec.oracle.oracle import SafetyOracle  # noqa: E402
from mpgspec.pipeline.reuse import compiled  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

try:
    from verifiers.rk4 import SIZES
except ImportError:  # pragma: no cover - keep the benchmark alive if the constant moves
    SIZES = (1, 4, 16, 64, 256)

PROJECT = ROOT / "specs" / "pendulum" / "project.yaml"


# ----------------------------------------------------------------------------------------------
# helpers

def log(msg: str) -> None:
    print(msg, flush=True)


def timed(fn, repeats: int) -> tuple[float, float, list[float]]:
    """(median, min, all) wall time of fn() over `repeats` runs."""
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), min(ts), ts


def machine() -> dict:
    return common.machine(casadi=ca.__version__, numpy=np.__version__, scipy=scipy.__version__)


def all_points(prims, gA, gB) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict[str, list[str]]]:
    """Per target B: every (x_A*(t_A), t_B) of Algorithm 1, in build_graph's order; and the source
    "A @ t_A" of each."""
    out, src = {}, {}
    for b in prims:
        x0s, t0s, sb = [], [], []
        for a in prims:
            if a == b:
                continue
            for ta in gA[a]:
                xa = prims[a].x_star(float(ta))
                for tb in gB[b]:
                    x0s.append(xa)
                    t0s.append(float(tb))
                    sb.append(f"{a} @ t_A={float(ta):.4g}")
        out[b], src[b] = (np.array(x0s), np.array(t0s)), sb
    return out, src


def own_grid_points(prims) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """all_points on every primitive's own t_A and t_B grids (at least one clock each)."""
    gA = {n: p.clock_grid(max(p.grid_A, 1), "A") for n, p in prims.items()}
    gB = {n: p.clock_grid(max(p.grid_B, 1), "B") for n, p in prims.items()}
    return all_points(prims, gA, gB)[0]


def example(name: str):
    """(primitives, settings) of specs/<name>: the A1 with E sized by its verifiers, as verify sizes it
    (pipeline.reuse.compiled); another project compiled only."""
    spec = load_project(ROOT / "specs" / name / "project.yaml")
    if name == "a1":
        cp = compiled(spec)
        return cp.prims, cp.settings
    return compile_project(spec), settings_for(spec)


def stratified(points: dict, n: int, seed: int = 0) -> tuple[dict, list[tuple[str, int]], dict]:
    """About n points, proportional per target B (at least a few of each), a global order in
    which every prefix is again roughly proportional (used for the scipy subsets), and the indices
    chosen per target."""
    rng = np.random.default_rng(seed)
    total = sum(len(t) for _, t in points.values())
    chosen, order, picks = {}, [], {}
    for b, (x0s, t0s) in points.items():
        nb = len(t0s)
        k = min(nb, max(min(nb, 6), int(round(n * nb / total))))
        idx = np.sort(rng.choice(nb, k, replace=False))
        chosen[b], picks[b] = (x0s[idx], t0s[idx]), idx
        perm = rng.permutation(k)
        order.extend(((r + 0.5) / k, b, int(i)) for r, i in enumerate(perm))
    order.sort(key=lambda o: o[0])
    return chosen, [(b, i) for _, b, i in order], picks


class ChunkRecorder:
    """Records every Chunk.run and JudgedChunk.run call (chunk, input) while active; times spent
    inside the calls."""

    def __init__(self):
        self.calls: list[tuple[Chunk, np.ndarray]] = []
        self.t_in = 0.0
        self._orig = None

    def __enter__(self):
        self._orig = {cls: cls.run for cls in (Chunk, JudgedChunk)}
        rec = self

        def recording(orig):
            def run(chunk, Z):
                t = time.perf_counter()
                r = orig(chunk, Z)
                rec.t_in += time.perf_counter() - t
                rec.calls.append((chunk, np.array(Z, copy=True)))
                return r
            return run

        for cls, orig in self._orig.items():
            cls.run = recording(orig)
        return self

    def __exit__(self, *exc):
        for cls, orig in self._orig.items():
            cls.run = orig

    @property
    def step_columns(self) -> int:
        return sum(z.shape[1] * c.K for c, z in self.calls)



class RawChunk:
    """A chunk's compiled function called through CasADi's FunctionBuffer: input and outputs bound
    once per batch size to numpy arrays, so a call is the compiled loop and nothing else (no
    numpy -> DM -> numpy conversion as in Chunk.run). Outputs are computed but not read."""

    def __init__(self, ch: Chunk | JudgedChunk):
        self.ch, self.K, self.prim, self.dt = ch, ch.K, ch.prim, ch.dt
        self.nz = ch.fn.size1_in(0)

    def run(self, Z: np.ndarray) -> tuple[np.ndarray, None]:
        n = Z.shape[1]
        ev, zin, zf, _out = self.ch.bound(n)
        zin.reshape(self.nz, n, order="F")[:] = Z
        ev()
        return zf.reshape(self.nz, n, order="F"), None


def floor_loop(ch, x0s: np.ndarray, t0s: np.ndarray, horizons: np.ndarray, cap: int) -> int:
    """The compiled loop alone: every point over its full horizon, cap columns side by side, slots
    refilled from the queue as rollouts reach their horizon, padded to the same SIZES; no early
    termination, no evidence. `ch` is a Chunk or a RawChunk. Returns the step-columns computed."""
    prim, K, dt = ch.prim, ch.K, ch.dt
    nsteps = np.ceil(horizons / dt - 1e-9).astype(int)
    chunks_left = (nsteps // K + 1).astype(int)  # the oracle's HORIZON stop: steps + K > nsteps
    n = len(t0s)
    Z = np.zeros((len(initial_state(prim, x0s[0], t0s[0])), 0)) if n else None
    left = np.zeros(0, int)
    nxt, work = 0, 0
    while nxt < n or left.size:
        if nxt < n and left.size < cap:
            take = min(cap - left.size, n - nxt)
            Zn = np.stack([initial_state(prim, x0s[i], t0s[i]) for i in range(nxt, nxt + take)], axis=1)
            Z = np.concatenate([Z, Zn], axis=1)
            left = np.concatenate([left, chunks_left[nxt:nxt + take]])
            nxt += take
        m = left.size
        size = next(s for s in SIZES if s >= m)
        Zp = Z if size == m else np.concatenate([Z, np.repeat(Z[:, :1], size - m, axis=1)], axis=1)
        Zf, _out = ch.run(Zp)
        work += size * K
        left = left - 1
        keep = left > 0
        Z, left = Zf[:, :m][:, keep], left[keep]
    return work


def replay(calls, raw: dict) -> None:
    """Re-issue recorded chunk calls; through RawChunk wrappers when `raw` is given."""
    for c, z in calls:
        (raw.setdefault(id(c), RawChunk(c)) if raw is not None else c).run(z)


@contextlib.contextmanager
def cold_cache():
    """A fresh, empty MPGSPEC_CACHE while active, so compile_cached really runs the C compiler."""
    old = os.environ.get("MPGSPEC_CACHE")
    _TMP_DIRS.append(tempfile.mkdtemp(prefix="mpgspec-bench-cold-"))
    os.environ["MPGSPEC_CACHE"] = _TMP_DIRS[-1]
    try:
        yield _TMP_DIRS[-1]
    finally:
        if old is None:
            os.environ.pop("MPGSPEC_CACHE", None)
        else:
            os.environ["MPGSPEC_CACHE"] = old


class LsodaBaseline:
    """The LSODA baseline: solve_ivp LSODA with terminal events on each h (crossing -tol downwards)
    and on E (the RoA margin crossing 0 upwards), rtol 1e-8, atol 1e-10, one Python-driven rollout
    per call; a start outside C is unsafe and one inside E safe without integrating. Two-valued, as
    the 'scipy' backend was before the error-aware verdicts; written here so the baseline stays fixed."""

    RTOL, ATOL = 1e-8, 1e-10

    def __init__(self, prim, settings, horizons):
        self.prim, self.s, self.horizons = prim, settings, horizons  # horizons: SafetyOracle.horizons

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray) -> list[OracleEvidence]:
        T = self.horizons(np.atleast_1d(t0s))
        return [self.one(np.asarray(x0, float), float(t0), float(h)) for x0, t0, h in zip(x0s, t0s, T)]

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
        enter = lambda s, x: margin(s, x)  # noqa: E731
        enter.terminal, enter.direction = True, 1
        events.append(enter)
        h0 = hv(0.0, x0)
        if nh and (h0 < -tol).any():
            return OracleEvidence(0, Reason.LEFT_C, 0.0, violated=p.h_names[int(np.argmin(h0))])
        if margin(0.0, x0) > 0:
            return OracleEvidence(1, Reason.ENTERED_E, 0.0, t_enter=0.0)
        try:
            sol = solve_ivp(rhs, (0.0, T), x0, method="LSODA", events=events, rtol=self.RTOL, atol=self.ATOL)
        except Exception as err:
            return OracleEvidence(0, Reason.ERROR, 0.0, message=str(err)[:500])
        if sol.status == -1 or not np.isfinite(sol.y).all():
            return OracleEvidence(0, Reason.INTEGRATION_FAILED, float(sol.t[-1]), message=str(sol.message))
        hits = [(float(te[0]), i) for i, te in enumerate(sol.t_events) if len(te)]
        if not hits:
            return OracleEvidence(0, Reason.HORIZON, T, steps=len(sol.t))
        ts, i = min(hits)
        if i == nh:
            return OracleEvidence(1, Reason.ENTERED_E, ts, t_enter=ts, steps=len(sol.t))
        return OracleEvidence(0, Reason.LEFT_C, ts, violated=p.h_names[i], steps=len(sol.t))


# ----------------------------------------------------------------------------------------------
# measurements

def setup_oracles(prims, settings, pts):
    """SafetyOracle per target B: construction (JIT of the chunk) and a first call on the batch
    (which compiles the dt/2 refinement chunk when a rollout is inconclusive, and builds the
    mapped functions), both timed."""
    oracles, t_construct, t_first = {}, 0.0, 0.0
    for b, (x0s, t0s) in pts.items():
        t = time.perf_counter()
        oracles[b] = SafetyOracle(prims[b], settings)
        t_construct += time.perf_counter() - t
        t = time.perf_counter()
        oracles[b].evaluate(x0s, t0s)
        t_first += time.perf_counter() - t

    def run_all():
        return {b: oracles[b].evaluate(x0s, t0s) for b, (x0s, t0s) in pts.items()}

    return oracles, run_all, t_construct, t_first


STATUSES = ("safe", "unsafe", "inconclusive")


def status_counts(evs) -> dict[str, int]:
    out = {k: 0 for k in STATUSES}
    for e in evs:
        out[e.status] = out.get(e.status, 0) + 1
    return out


def _g(v) -> str:
    return "None" if v is None else f"{v:.3g}"


def fmt_counts(c: dict[str, int]) -> str:
    return " / ".join(f"{c.get(k, 0)}" for k in STATUSES)


def run_reference(make, pts: dict, order: list, budget: float) -> tuple[dict, float]:
    """One call per point, in the stratified `order`, until `budget` seconds of calls are spent:
    {(B, i): evidence}, total time of the calls."""
    refs = {b: make(b) for b in pts}
    ev, spent = {}, 0.0
    for b, i in order:
        if spent > budget:
            break
        x0s, t0s = pts[b]
        t = time.perf_counter()
        ev[(b, i)] = refs[b].evaluate(x0s[i:i + 1], t0s[i:i + 1])[0]
        spent += time.perf_counter() - t
    return ev, spent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="150 points, fewer repeats, smaller scipy budgets")
    ap.add_argument("-n", "--points", type=int, default=None, help="start points (default 600, quick 150)")
    ap.add_argument("--repeats", type=int, default=None, help="measurement rounds (default 7, quick 3)")
    ap.add_argument("--scipy-budget", type=float, default=None,
                    help="seconds of calls of the scipy backend before stopping at a subset (default 150, quick 15)")
    ap.add_argument("--lsoda-budget", type=float, default=None,
                    help="seconds of LSODA-baseline calls before stopping at a subset (default 25, quick 8)")
    ap.add_argument("--build-repeats", type=int, default=None, help="graph builds per preset (default 3, quick 1)")
    ap.add_argument("--no-write", action="store_true", help="do not write bench/RESULTS.md")
    args = ap.parse_args(argv)
    N = args.points or (150 if args.quick else 600)
    R = args.repeats or (3 if args.quick else 7)
    budget_sp = args.scipy_budget if args.scipy_budget is not None else (15.0 if args.quick else 150.0)
    budget_ls = args.lsoda_budget if args.lsoda_budget is not None else (8.0 if args.quick else 25.0)
    BR = args.build_repeats or (1 if args.quick else 3)
    T0 = time.perf_counter()
    mach = machine()
    mach["revision"] = common.revision(ROOT)  # at the start: what is measured
    try:
        load = " load average %.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        load = ""
    log(f"machine: {mach['nproc']} cpu ({mach['cpu']}), python {mach['python']}, casadi {mach['casadi']}, "
        f"numpy {mach['numpy']}, scipy {mach['scipy']};{load}")

    spec = load_project(PROJECT)
    settings = settings_for(spec)
    level = spec.project.oracle.accuracy
    log(f"project {spec.name}: accuracy {level}, {settings}")
    prims = compile_project(spec)
    gA, gB = grids(prims, spec.project.oracle.grid.t_A, spec.project.oracle.grid.t_B)
    full, src_full = all_points(prims, gA, gB)
    n_full = sum(len(t) for _, t in full.values())
    pts, order, picks = stratified(full, N)
    src = {b: [src_full[b][int(i)] for i in picks[b]] for b in pts}
    n = sum(len(t) for _, t in pts.values())
    log(f"start points: {n} of the {n_full} of Algorithm 1 "
        f"({', '.join(f'{b}: {len(t)}' for b, (_, t) in pts.items())})")

    # set-up: oracles (JIT), the bare chunks, recordings of the oracle's chunk calls ---------------
    log("\nset-up (JIT compiles, first calls)")
    oracles, run_rk, c_rk, f_rk = setup_oracles(prims, settings, pts)
    s_low = settings.replace(refinements=0)
    _, run_low, c_low, f_low = setup_oracles(prims, s_low, pts)
    log(f"  rk4 oracles, refinements={settings.refinements} ({level}): construct {c_rk:.2f} s, first calls "
        f"{f_rk:.2f} s; refinements=0 (low): construct {c_low:.2f} s, first calls {f_low:.2f} s")
    horizons = {b: oracles[b].horizons(t0s) for b, (_, t0s) in pts.items()}
    ev_rk, ev_low = run_rk(), run_low()
    with ChunkRecorder() as rec:
        run_rk()
    with ChunkRecorder() as rec_low:
        run_low()
    cap = min(settings.batch, SIZES[-1])
    chunks = {b: build_chunk(prims[b], settings.dt, settings.chunk, settings.jit, settings.jit_flags) for b in pts}
    plain = {b: build_plain_chunk(prims[b], settings.dt, settings.chunk, settings.jit, settings.jit_flags)
             for b in pts}
    # JIT: fresh copies of the primitives (no remembered chunks) and an empty compile cache
    t_jit, t_jit_ref, t_jit_plain = [], [], []
    with cold_cache():
        for b in pts:
            fresh = dataclasses.replace(prims[b], cache={})
            for acc, mk in ((t_jit, lambda: build_chunk(fresh, settings.dt, settings.chunk, settings.jit,
                                                        settings.jit_flags)),
                            (t_jit_ref, lambda: build_chunk(fresh, settings.dt / 2, settings.chunk, settings.jit,
                                                            settings.jit_flags)),
                            (t_jit_plain, lambda: build_plain_chunk(fresh, settings.dt, settings.chunk, settings.jit,
                                                                    settings.jit_flags))):
                t = time.perf_counter()
                mk()
                acc.append(time.perf_counter() - t)
    jit_c, jit_r, jit_p = (statistics.median(v) for v in (t_jit, t_jit_ref, t_jit_plain))
    log(f"  JIT compile, cold cache, median over {len(t_jit)} primitives: chunk (dt={settings.dt:g}, "
        f"K={settings.chunk}) {jit_c:.3f} s; refinement chunk (dt={settings.dt / 2:g}, K={settings.chunk}) "
        f"{jit_r:.3f} s; plain RK4 chunk (built here) {jit_p:.3f} s")
    # the plain chunk integrates the same steps where no step is shortened
    same = [b for b in pts if not prims[b].boundaries][:1]
    if same:
        b0 = same[0]
        Zs = np.stack([initial_state(prims[b0], x, t) for x, t in zip(*pts[b0])], axis=1)[:, :16]
        dz = np.abs(chunks[b0].run(Zs)[0] - plain[b0].run(Zs)[0])
        log(f"  plain vs new chunk, {b0}, one chunk of {settings.chunk} steps from {Zs.shape[1]} points: "
            f"max |z_new - z_plain| = {np.nanmax(dz):.1e}")
    raw = {b: RawChunk(c) for b, c in chunks.items()}
    raw_plain = {b: RawChunk(c) for b, c in plain.items()}
    rawc: dict = {}
    work = {}

    def floor_all(which):
        for b, (x0s, t0s) in pts.items():
            work[b] = floor_loop(which[b], x0s, t0s, horizons[b], cap)
        return sum(work.values())

    floor_all(chunks)  # warm-up: mapped functions and buffers
    floor_all(raw)
    pl_work = floor_all(raw_plain)
    replay(rec.calls, rawc)
    replay(rec_low.calls, rawc)
    fl_work = floor_all(raw)
    assert pl_work == fl_work

    steps_used = sum(e.steps for evs in ev_low.values() for e in evs)
    sc_low = status_counts(e for evs in ev_low.values() for e in evs)
    sc_rk = status_counts(e for evs in ev_rk.values() for e in evs)
    refined = sum(e.refined for evs in ev_rk.values() for e in evs)
    mean_h = np.mean([math.ceil(h / settings.dt - 1e-9) for hs in horizons.values() for h in hs])
    log(f"  decided at step 0: {sum(e.steps == 0 for evs in ev_low.values() for e in evs)} of {n}; mean steps "
        f"to a verdict {steps_used / n:.0f} of a mean horizon of {mean_h:.0f}")
    log(f"  safe / unsafe / inconclusive: low {fmt_counts(sc_low)}; {level} {fmt_counts(sc_rk)} "
        f"({refined} rollouts re-run at dt/2)")
    log(f"  compiled chunk calls: oracle {len(rec.calls)} (low: {len(rec_low.calls)}); step-columns "
        f"computed: oracle {rec.step_columns:,} (low: {rec_low.step_columns:,}, of which needed for the "
        f"verdicts {steps_used + n:,}), full-horizon loop {fl_work:,}")

    # timed rounds -------------------------------------------------------------------------------
    log(f"\n(a)+(c) {R} interleaved rounds")
    T = rounds({
        "rk4": run_rk,
        "rk4_low": run_low,
        "floor": lambda: floor_all(chunks),
        "floor_raw": lambda: floor_all(raw),
        "plain_raw": lambda: floor_all(raw_plain),
        "own": lambda: replay(rec.calls, None),
        "own_low": lambda: replay(rec_low.calls, None),
        "own_raw": lambda: replay(rec.calls, rawc),
        "own_raw_low": lambda: replay(rec_low.calls, rawc),
    }, R)
    md = {k: statistics.median(v) for k, v in T.items()}
    mn = {k: min(v) for k, v in T.items()}
    what = {
        "rk4": f"(a) rk4 oracle, refinements={settings.refinements} ({level})",
        "rk4_low": "(a) rk4 oracle, refinements=0 (low)",
        "floor": "(c) loop alone, full horizon, Chunk.run",
        "floor_raw": "(c) loop alone, full horizon, zero-copy",
        "plain_raw": "(c) plain RK4 chunk, full horizon, zero-copy",
        "own": "    oracle's chunk calls replayed, Chunk.run",
        "own_low": "    same, low",
        "own_raw": "    oracle's chunk calls replayed, zero-copy",
        "own_raw_low": "    same, low",
    }
    for k, label in what.items():
        rate = f"-> {n / md[k]:,.0f} calls/s" if not k.startswith("own") else ""
        log(f"  {label:45s} median {md[k] * 1e3:7.1f} ms  min {mn[k] * 1e3:7.1f} ms  {rate}")
    ns_new, ns_plain = md["floor_raw"] / fl_work * 1e9, md["plain_raw"] / fl_work * 1e9
    r_check = med_ratio(T["floor_raw"], T["plain_raw"])
    log(f"  ns per step-column, full-horizon loop: {md['floor'] / fl_work * 1e9:.0f} through Chunk.run, "
        f"{ns_new:.0f} zero-copy (Chunk.run's numpy/DM conversion: {1 - md['floor_raw'] / md['floor']:.0%} of its "
        f"time); plain RK4 chunk {ns_plain:.0f} zero-copy")
    log(f"  cost of the error-aware check in compiled work: new chunk / plain RK4 chunk = {r_check:.2f}")
    r_floor = med_ratio(T["rk4"], T["floor"])
    r_floor_low = med_ratio(T["rk4_low"], T["floor"])
    r_floor_raw = med_ratio(T["rk4"], T["floor_raw"])
    r_floor_plain = med_ratio(T["rk4"], T["plain_raw"])
    r_own = med_ratio(T["rk4"], T["own_raw"])
    r_own_low = med_ratio(T["rk4_low"], T["own_raw_low"])
    r_own_run = med_ratio(T["rk4"], T["own"])
    log(f"  oracle / floor: {r_floor:.2f} (low {r_floor_low:.2f}; vs the zero-copy floor {r_floor_raw:.2f}; vs the "
        f"plain-RK4 floor {r_floor_plain:.2f}); oracle / its own compiled work: {r_own:.1f}x zero-copy, "
        f"{r_own_run:.2f}x through Chunk.run (low: {r_own_low:.1f}x zero-copy)")

    # (b) scipy: the LSODA baseline and the scipy backend ------------------------------------------
    rk_per_call = md["rk4"] / n

    def per_call(evs: dict, spent: float, label: str):
        m = len(evs)
        sub: dict = {}
        for (b, i) in evs:
            sub.setdefault(b, []).append(i)
        sub_pts = {b: (pts[b][0][ix], pts[b][1][ix]) for b, ix in sub.items()}
        pc = spent / m
        ratio = pc / rk_per_call
        ratio_same = ratio
        if m < n:
            sub_med, _, _ = timed(lambda: [oracles[b].evaluate(x, t) for b, (x, t) in sub_pts.items()], R)
            ratio_same = pc / (sub_med / m)
        log(f"  {label}: {m} calls ({'all points' if m == n else 'stratified subset'}) in {spent:.2f} s -> "
            f"{1 / pc:,.1f} calls/s ({pc * 1e3:.2f} ms per call); rk4 oracle {rk_per_call * 1e3:.3f} ms per call "
            f"-> {ratio:.0f}x" + ("" if m == n else f" (rk4 on the same {m} points: {ratio_same:.0f}x)"))
        return m, pc, ratio, ratio_same

    log(f"\n(b) LSODA baseline: solve_ivp LSODA, terminal events on h and E, rtol {LsodaBaseline.RTOL:g}, "
        f"atol {LsodaBaseline.ATOL:g} (budget {budget_ls:.0f} s)")
    baselines = {b: LsodaBaseline(prims[b], settings, oracles[b].horizons) for b in pts}
    ls_ev, ls_t = run_reference(baselines.__getitem__, pts, order, budget_ls)
    m_ls, ls_pc, ratio_ls, ratio_ls_same = per_call(ls_ev, ls_t, "LSODA baseline")
    ratio_ls_pass = ratio_ls_same  # its first pass against rk4's own rounds (or rk4 on the same subset)
    RL = min(R, int(budget_ls // max(ls_t, 1e-9)))
    if RL >= 2:  # the ratio as everywhere else: interleaved rounds of both on the same points, median
        ls_sub: dict = {}
        for (b, i) in ls_ev:
            ls_sub.setdefault(b, []).append(i)
        ls_pts = {b: (pts[b][0][ix], pts[b][1][ix]) for b, ix in ls_sub.items()}
        TL = rounds({"lsoda": lambda: [baselines[b].evaluate(x, t) for b, (x, t) in ls_pts.items()],
                     "rk4": lambda: [oracles[b].evaluate(x, t) for b, (x, t) in ls_pts.items()]}, RL)
        ls_pc = statistics.median(TL["lsoda"]) / m_ls
        ratio_ls = ratio_ls_same = med_ratio(TL["lsoda"], TL["rk4"])
        log(f"  {RL} interleaved rounds of the baseline and rk4 on the same {m_ls} points: baseline "
            f"{ls_pc * 1e3:.2f} ms per call (median), rk4 {statistics.median(TL['rk4']) / m_ls * 1e3:.3f} ms per call; "
            f"median ratio {ratio_ls:.1f}x")
    ls_rounds = RL if RL >= 2 else 1
    ls_cmp = {"rk_safe_ls_unsafe": 0, "rk_unsafe_ls_safe": 0, "rk_inc_ls_safe": 0, "rk_inc_ls_unsafe": 0}
    for (b, i), e in ls_ev.items():
        r = ev_rk[b][i].status
        if r == "safe" and e.verdict == 0:
            ls_cmp["rk_safe_ls_unsafe"] += 1
        elif r == "unsafe" and e.verdict == 1:
            ls_cmp["rk_unsafe_ls_safe"] += 1
        elif r == "inconclusive":
            ls_cmp["rk_inc_ls_safe" if e.verdict == 1 else "rk_inc_ls_unsafe"] += 1
    log(f"  verdicts on the {m_ls} points: LSODA safe {sum(e.verdict for e in ls_ev.values())}, unsafe "
        f"{sum(1 - e.verdict for e in ls_ev.values())}; rk4 safe / LSODA unsafe {ls_cmp['rk_safe_ls_unsafe']}, "
        f"rk4 unsafe / LSODA safe {ls_cmp['rk_unsafe_ls_safe']}, rk4 inconclusive where LSODA says safe "
        f"{ls_cmp['rk_inc_ls_safe']} / unsafe {ls_cmp['rk_inc_ls_unsafe']}")

    log(f"\n(b) scipy backend: LSODA rtol 1e-10, atol 1e-12, max_step dt/2, dense output judged every dt/4 "
        f"(budget {budget_sp:.0f} s)")
    s_sp = settings.replace(method="scipy")
    sp_ev, sp_t = run_reference(lambda b: SafetyOracle(prims[b], s_sp), pts, order, budget_sp)
    m_sp, sp_pc, ratio_sp, ratio_sp_same = per_call(sp_ev, sp_t, "scipy backend")
    conf = {(a, c): 0 for a in STATUSES for c in STATUSES}
    danger, examples = [], []
    for (b, i), e in sp_ev.items():
        r = ev_rk[b][i]
        conf[(r.status, e.status)] = conf.get((r.status, e.status), 0) + 1
        if r.status != e.status:
            T_b = float(horizons[b][i])
            note = ""
            if e.reason is Reason.HORIZON and e.t_stop < T_b - settings.dt:
                note = (f"; scipy stopped at its E event at s={e.t_stop:.4f} < T={T_b:g} with RoA margin "
                        f"{_g(e.best_roa_margin)} not above its error bound, and reports horizon_reached")
            line = (f"    B={b} from {src[b][i]} x0={np.round(pts[b][0][i], 4).tolist()} t_B={pts[b][1][i]:.4f}: "
                    f"rk4 {r.status} ({r.reason.value} @ {r.t_stop:.3f}, h margin {_g(r.margin)}"
                    + (f", RoA entry margin {_g(r.entry_margin)} +- {_g(r.entry_error)}" if r.entry_margin is not None
                       else "")
                    + f") vs scipy {e.status} ({e.reason.value} @ {e.t_stop:.3f}, h margin {_g(e.margin)}){note}")
            if r.status == "safe" and e.status == "unsafe":
                danger.append(line)
            elif len(examples) < 8:
                examples.append(line)
    sc_rk_sub = status_counts(ev_rk[b][i] for (b, i) in sp_ev)
    sc_sp = status_counts(sp_ev.values())
    dis = sum(v for (a, c), v in conf.items() if a != c)
    rk_safe_sp_unsafe = conf[("safe", "unsafe")]
    log(f"  safe / unsafe / inconclusive on the {m_sp} common points: rk4 {fmt_counts(sc_rk_sub)}, scipy "
        f"{fmt_counts(sc_sp)}; {dis} disagreements")
    log("  rk4 \\ scipy     " + "".join(f"{c:>14s}" for c in STATUSES))
    for a in STATUSES:
        log(f"  {a:15s} " + "".join(f"{conf[(a, c)]:14d}" for c in STATUSES))
    log(f"  rk4 safe / scipy unsafe: {rk_safe_sp_unsafe}" + (" <-- DANGEROUS" if rk_safe_sp_unsafe else ""))
    for line in danger:
        log(line)
    if examples:
        log("  other disagreements (conservative or inconclusive):")
    for line in examples:
        log(line)

    # graph builds per preset --------------------------------------------------------------------
    log("\ngraph builds (mpgspec.api.build; includes JIT compiles)")
    builds = {}
    import verifiers.rk4 as _vr  # time spent in build_chunk (JIT) during the builds
    _orig_bc, jit_acc = _vr.build_chunk, [0.0]

    def _timed_bc(*a, **k):
        t = time.perf_counter()
        try:
            return _orig_bc(*a, **k)
        finally:
            jit_acc[0] += time.perf_counter() - t

    presets = ("low", "medium", "high", "very_high")
    for lv in presets:
        sp_l = dataclasses.replace(spec, project=spec.project.model_copy(
            update={"oracle": spec.project.oracle.model_copy(update={"accuracy": lv})}))
        st = settings_for(sp_l)
        runs = []
        _vr.build_chunk = _timed_bc
        try:
            for _ in range(BR):
                jit_acc[0] = 0.0
                t = time.perf_counter()
                _p, g, info, _o = common.run_build(build, sp_l, st, SafetyOracle)
                runs.append((time.perf_counter() - t, info["graph_s"], jit_acc[0], info, g))
        finally:
            _vr.build_chunk = _orig_bc
        total, gs, jit, info, g = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
        edges = g.G.number_of_edges()
        cells = [e for tr in g.transitions.values() for row in tr.evidence for e in row]
        builds[lv] = {"total": total, "graph_s": gs, "jit": jit, "calls": info["oracle_calls"],
                      "cps": info["oracle_calls"] / gs, "cps_nojit": info["oracle_calls"] / max(gs - jit, 1e-9),
                      "edges": edges, "inc": sum(e.status == "inconclusive" for e in cells)}
        log(f"  {lv:9s}: total {total:.2f} s (median of {BR}), graph {gs:.2f} s of which JIT {jit:.2f} s; "
            f"{info['oracle_calls']} oracle calls -> {builds[lv]['cps']:,.0f} calls/s "
            f"({builds[lv]['cps_nojit']:,.0f} without JIT), {edges} edges, {builds[lv]['inc']} inconclusive")

    # summary ------------------------------------------------------------------------------------
    d = builds.get(level, builds["medium"])
    lo = builds["low"]["total"]

    def sub(m):
        return "" if m == n else f" ({m}-point subset)"

    rows = [
        ("start points (stratified from Algorithm 1's grids)", f"{n} of {n_full}"),
        (f"rk4 oracle, default (`{level}`: refinements={settings.refinements}, dt={settings.dt:g}, "
         f"T={settings.horizon:g})", f"{n / md['rk4']:,.0f} calls/s ({md['rk4'] * 1e3:.0f} ms)"),
        ("rk4 oracle, `refinements=0` (low)", f"{n / md['rk4_low']:,.0f} calls/s ({md['rk4_low'] * 1e3:.0f} ms)"),
        ("LSODA baseline: solve_ivp LSODA + terminal events, rtol 1e-8" + sub(m_ls),
         f"{1 / ls_pc:,.0f} calls/s ({ls_pc * 1e3:.2f} ms/call)"),
        ("scipy backend: LSODA rtol 1e-10, judged every dt/4" + sub(m_sp),
         f"{1 / sp_pc:,.1f} calls/s ({sp_pc * 1e3:.1f} ms/call)"),
        ("compiled chunk alone, full horizon, via Chunk.run (floor)",
         f"{n / md['floor']:,.0f} rollouts/s ({md['floor'] * 1e3:.0f} ms)"),
        ("same loop, zero-copy FunctionBuffer calls (pure compiled cost)",
         f"{n / md['floor_raw']:,.0f} rollouts/s ({md['floor_raw'] * 1e3:.0f} ms, {ns_new:.0f} ns/step)"),
        ("plain RK4 chunk (as before the error-aware check), zero-copy",
         f"{n / md['plain_raw']:,.0f} rollouts/s ({md['plain_raw'] * 1e3:.0f} ms, {ns_plain:.0f} ns/step)"),
        ("**cost of the error-aware check in compiled work** (new / plain)",
         f"**{r_check:.2f}x** ({ns_new:.0f} vs {ns_plain:.0f} ns per step-column)"),
        ("oracle's own chunk calls replayed zero-copy (its compiled work)",
         f"{md['own_raw'] * 1e3:.1f} ms (low: {md['own_raw_low'] * 1e3:.1f} ms)"),
        ("**speed-up rk4 oracle vs LSODA baseline** (target >= 50x)",
         f"**{ratio_ls:.1f}x**" + (f" (median of {ls_rounds} interleaved rounds; the baseline's first pass against "
                                   f"rk4's own rounds: {ratio_ls_pass:.1f}x)" if ls_rounds > 1 else "")
         + ("" if m_ls == n or ls_rounds > 1 else f" (same {m_ls} points: {ratio_ls_same:.1f}x)")),
        ("**speed-up rk4 oracle vs scipy backend**",
         f"**{ratio_sp:,.0f}x**" + ("" if m_sp == n else f" (same {m_sp} points: {ratio_sp_same:,.0f}x)")),
        ("**rk4 oracle time / compiled-loop floor** (target <= 2)",
         f"**{r_floor:.2f}** (low: {r_floor_low:.2f}; vs zero-copy floor: {r_floor_raw:.2f}; "
         f"vs plain-RK4 floor: {r_floor_plain:.2f})"),
        ("rk4 oracle time / its own compiled work (pure overhead)", f"{r_own:.1f}x (low: {r_own_low:.1f}x)"),
        (f"verdicts safe / unsafe / inconclusive, rk4 vs scipy backend ({m_sp} points)",
         f"rk4 {fmt_counts(sc_rk_sub)}; scipy {fmt_counts(sc_sp)}; {dis} disagree"),
        ("**rk4-safe / scipy-unsafe** (must be 0)",
         f"**{rk_safe_sp_unsafe}**; rk4-unsafe/scipy-safe {conf[('unsafe', 'safe')]}, rk4-inconclusive/scipy-"
         f"safe {conf[('inconclusive', 'safe')]}, /scipy-unsafe {conf[('inconclusive', 'unsafe')]}, "
         f"rk4-safe/scipy-inconclusive {conf[('safe', 'inconclusive')]}, "
         f"rk4-unsafe/scipy-inconclusive {conf[('unsafe', 'inconclusive')]}"),
        (f"verdicts rk4 vs LSODA baseline ({m_ls} points)",
         f"rk4-safe/LSODA-unsafe {ls_cmp['rk_safe_ls_unsafe']}, rk4-unsafe/LSODA-safe "
         f"{ls_cmp['rk_unsafe_ls_safe']}, rk4-inconclusive {ls_cmp['rk_inc_ls_safe'] + ls_cmp['rk_inc_ls_unsafe']}"),
        (f"inconclusive rk4 verdicts ({n} points)",
         f"low: {sc_low['inconclusive']}; {level}: {sc_rk['inconclusive']} after {refined} re-run at dt/2"),
        ("JIT compile per chunk, cold cache (excluded from calls/s above)",
         f"{jit_c:.2f} s (dt={settings.dt:g}, K={settings.chunk}); refinement chunk (dt/2) {jit_r:.2f} s; "
         f"plain RK4 chunk {jit_p:.2f} s"),
        (f"graph build, {level} ({d['calls']} oracle calls, {d['edges']} edges, {d['inc']} inconclusive)",
         f"{d['total']:.2f} s ({d['graph_s']:.2f} s graph, of which JIT {d['jit']:.2f} s); "
         f"{d['cps']:,.0f} calls/s ({d['cps_nojit']:,.0f} without JIT)"),
        ("accuracy presets " + " / ".join(presets) + ": build time vs low",
         " / ".join(f"{builds[k]['total'] / lo:.2f}" for k in presets)
         + " (" + " / ".join(f"{builds[k]['total']:.2f} s" for k in presets) + "; inconclusive "
         + " / ".join(str(builds[k]['inc']) for k in presets) + ")"),
    ]
    table = common.markdown_table(rows)
    when = _dt.datetime.now().strftime("%Y-%m-%d %H:%M")
    try:
        load_end = " (%.2f %.2f %.2f at the end)" % os.getloadavg()
    except OSError:
        load_end = ""
    head = (f"Pendulum example, {when}, {mach['revision']}; {mach['nproc']} CPU ({mach['cpu']}), Python {mach['python']}, "
            f"CasADi {mach['casadi']}, NumPy {mach['numpy']}, SciPy {mach['scipy']};{load}{load_end}; "
            f"`python bench/bench_oracle.py{' --quick' if args.quick else ''}` "
            f"(medians of {R} interleaved rounds, builds median of {BR}; {time.perf_counter() - T0:.0f} s wall).")
    log("\n" + head + "\n\n" + table)
    if danger:
        log("\nrk4-safe / scipy-unsafe start points:\n" + "\n".join(danger))
    if not args.no_write:
        out = ROOT / "bench" / "RESULTS.md"
        rest = ""  # keep the sections other benchmarks wrote (e.g. "## A1 (rigid body)")
        if out.exists() and "\n## " in out.read_text():
            rest = "\n## " + out.read_text().split("\n## ", 1)[1]
        extra = ("\n**rk4-safe / scipy-unsafe start points:**\n\n" + "\n".join(danger) + "\n") if danger else ""
        out.write_text("# Oracle benchmark results\n\n" + head + "\n\n" + table + "\n" + extra + "\n"
                       "See bench/README.md for the meaning of each row.\n" + rest)
        log(f"\nwrote {out.relative_to(ROOT)}")
    ok_ls, ok_floor, ok_safe = ratio_ls >= 50, r_floor <= 2, rk_safe_sp_unsafe == 0
    log(f"targets: LSODA-baseline speed-up >= 50x {'met' if ok_ls else 'MISSED'}; "
        f"within 2x of the loop alone {'met' if ok_floor else 'MISSED'}; "
        f"no rk4-safe/scipy-unsafe {'met' if ok_safe else 'MISSED'}")
    return 0 if (ok_ls and ok_floor and ok_safe) else 1


if __name__ == "__main__":
    sys.exit(main())
