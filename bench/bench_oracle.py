"""Benchmark of the safety oracle (Definition 4) on the pendulum example.

    python bench/bench_oracle.py            # ~1-2 minutes
    python bench/bench_oracle.py --quick    # ~30 s, fewer points and repeats

Measures, in one process and on the same start points (setpoints x_A*(t_A) of every primitive A on
its grid, paired with every target B and its t_B grid, as Algorithm 1 does):

  (a) the default rk4 oracle (SafetyOracle.evaluate per target B, batched, early termination,
      step-halving check of the project's accuracy preset), and the same with check='none';
  (b) scipy's solve_ivp LSODA with terminal events (the 'scipy' backend), on a stratified subset
      when the time budget runs out, scaled per call;
  (c) the compiled integration loop alone: the same compiled RK4 chunks (integrator.build_chunk)
      over the full horizon, batched and padded the same way, with no early termination and no
      evidence processing (the floor); and a replay of exactly the chunk calls the oracle made
      (its compiled work without its Python bookkeeping);

then whole-graph builds (mpgspec.api.build) per accuracy preset. Prints a markdown table and
writes it to bench/RESULTS.md. See bench/README.md for what every number means.
"""
from __future__ import annotations

import os as _os
import tempfile as _tempfile

_os.environ.setdefault("MPGSPEC_CACHE", _tempfile.mkdtemp(prefix="mpgspec-bench-"))  # cold cache: JIT is measured
import argparse
import dataclasses
import datetime as _dt
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca
import common  # noqa: E402  (bench/common.py)
from common import med_ratio, rounds  # noqa: E402
import scipy  # noqa: E402

from mpgspec.api import build, compile_project, settings_for  # noqa: E402
from mpgspec.graph.build import grids  # noqa: E402
from mpgspec.oracle.integrator import Chunk, build_chunk, initial_state  # noqa: E402
from mpgspec.oracle.oracle import SafetyOracle  # noqa: E402
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


def all_points(prims, gA, gB) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per target B: every (x_A*(t_A), t_B) of Algorithm 1, in build_graph's order."""
    out = {}
    for b in prims:
        x0s, t0s = [], []
        for a in prims:
            if a == b:
                continue
            for ta in gA[a]:
                xa = prims[a].x_star(float(ta))
                for tb in gB[b]:
                    x0s.append(xa)
                    t0s.append(float(tb))
        out[b] = (np.array(x0s), np.array(t0s))
    return out


def stratified(points: dict, n: int, seed: int = 0) -> tuple[dict, list[tuple[str, int]]]:
    """About n points, proportional per target B (at least a few of each), and a global order in
    which every prefix is again roughly proportional (used for the LSODA subset)."""
    rng = np.random.default_rng(seed)
    total = sum(len(t) for _, t in points.values())
    chosen, order = {}, []
    for b, (x0s, t0s) in points.items():
        nb = len(t0s)
        k = min(nb, max(min(nb, 6), int(round(n * nb / total))))
        idx = np.sort(rng.choice(nb, k, replace=False))
        chosen[b] = (x0s[idx], t0s[idx])
        perm = rng.permutation(k)
        order.extend(((r + 0.5) / k, b, int(i)) for r, i in enumerate(perm))
    order.sort(key=lambda o: o[0])
    return chosen, [(b, i) for _, b, i in order]


class ChunkRecorder:
    """Records every Chunk.run call (chunk, input) while active; times spent inside the calls."""

    def __init__(self):
        self.calls: list[tuple[Chunk, np.ndarray]] = []
        self.t_in = 0.0
        self._orig = None

    def __enter__(self):
        self._orig = orig = Chunk.run
        rec = self

        def run(chunk, Z):
            t = time.perf_counter()
            r = orig(chunk, Z)
            rec.t_in += time.perf_counter() - t
            rec.calls.append((chunk, np.array(Z, copy=True)))
            return r

        Chunk.run = run
        return self

    def __exit__(self, *exc):
        Chunk.run = self._orig

    @property
    def step_columns(self) -> int:
        return sum(z.shape[1] * c.K for c, z in self.calls)



class RawChunk:
    """A chunk's compiled function called through CasADi's FunctionBuffer: input and outputs bound
    once per batch size to numpy arrays, so a call is the compiled loop and nothing else (no
    numpy -> DM -> numpy conversion as in Chunk.run). Outputs are computed but not read."""

    def __init__(self, ch: Chunk):
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


# ----------------------------------------------------------------------------------------------
# measurements

def setup_oracles(prims, settings, pts):
    """SafetyOracle per target B: construction (JIT of the chunk) and a first call on the batch
    (which compiles the fine check's chunk and builds the mapped functions), both timed."""
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="150 points, fewer repeats, smaller LSODA budget")
    ap.add_argument("-n", "--points", type=int, default=None, help="start points (default 600, quick 150)")
    ap.add_argument("--repeats", type=int, default=None, help="measurement rounds (default 7, quick 3)")
    ap.add_argument("--scipy-budget", type=float, default=None,
                    help="seconds of LSODA calls before stopping at a subset (default 25, quick 8)")
    ap.add_argument("--build-repeats", type=int, default=None, help="graph builds per preset (default 3, quick 1)")
    ap.add_argument("--no-write", action="store_true", help="do not write bench/RESULTS.md")
    args = ap.parse_args(argv)
    N = args.points or (150 if args.quick else 600)
    R = args.repeats or (3 if args.quick else 7)
    budget = args.scipy_budget if args.scipy_budget is not None else (8.0 if args.quick else 25.0)
    BR = args.build_repeats or (1 if args.quick else 3)
    T0 = time.perf_counter()
    mach = machine()
    try:
        load = " load average %.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        load = ""
    log(f"machine: {mach['nproc']} cpu ({mach['cpu']}), python {mach['python']}, casadi {mach['casadi']}, "
        f"numpy {mach['numpy']}, scipy {mach['scipy']};{load}")

    spec = load_project(PROJECT)
    settings = settings_for(spec)
    log(f"project {spec.name}: accuracy {spec.project.oracle.accuracy}, {settings}")
    prims = compile_project(spec)
    gA, gB = grids(prims, spec.project.oracle.grid.t_A, spec.project.oracle.grid.t_B)
    full = all_points(prims, gA, gB)
    n_full = sum(len(t) for _, t in full.values())
    pts, order = stratified(full, N)
    n = sum(len(t) for _, t in pts.values())
    log(f"start points: {n} of the {n_full} of Algorithm 1 "
        f"({', '.join(f'{b}: {len(t)}' for b, (_, t) in pts.items())})")

    # set-up: oracles (JIT), the bare chunks, recordings of the oracle's chunk calls ---------------
    log("\nset-up (JIT compiles, first calls)")
    oracles, run_rk, c_rk, f_rk = setup_oracles(prims, settings, pts)
    s_low = settings.replace(refinements=0)
    _, run_low, c_low, f_low = setup_oracles(prims, s_low, pts)
    log(f"  rk4 oracles, check={settings.check!r}: construct {c_rk:.2f} s, first calls {f_rk:.2f} s; "
        f"check='none': construct {c_low:.2f} s, first calls {f_low:.2f} s")
    horizons = {b: oracles[b].horizons(t0s) for b, (_, t0s) in pts.items()}
    ev_rk, ev_low = run_rk(), run_low()
    with ChunkRecorder() as rec:
        run_rk()
    with ChunkRecorder() as rec_low:
        run_low()
    cap = min(settings.batch, SIZES[-1])
    chunks, t_jit = {}, []
    for b in pts:
        t = time.perf_counter()
        chunks[b] = build_chunk(prims[b], settings.dt, settings.chunk, settings.jit, settings.jit_flags)
        t_jit.append(time.perf_counter() - t)
    t = time.perf_counter()
    build_chunk(next(iter(prims.values())), settings.dt / max(settings.refine, 1),
                settings.chunk * max(settings.refine, 1), settings.jit, settings.jit_flags)
    t_jit_fine = time.perf_counter() - t
    log(f"  JIT compile of one chunk (K={settings.chunk}): median {statistics.median(t_jit):.3f} s over "
        f"{len(t_jit)} primitives; fine-check chunk (K={settings.chunk * settings.refine}): {t_jit_fine:.3f} s")
    raw = {b: RawChunk(c) for b, c in chunks.items()}
    rawc: dict = {}
    work = {}

    def floor_all(which):
        for b, (x0s, t0s) in pts.items():
            work[b] = floor_loop(which[b], x0s, t0s, horizons[b], cap)

    floor_all(chunks)  # warm-up: mapped functions and buffers
    floor_all(raw)
    replay(rec.calls, rawc)
    replay(rec_low.calls, rawc)
    fl_work = sum(work.values())

    steps_used = sum(e.steps for evs in ev_low.values() for e in evs)
    checked = sum(e.checked for evs in ev_rk.values() for e in evs)
    refined = sum(e.refined for evs in ev_rk.values() for e in evs)
    mean_h = np.mean([math.ceil(h / settings.dt - 1e-9) for hs in horizons.values() for h in hs])
    log(f"  decided at step 0: {sum(e.steps == 0 for evs in ev_low.values() for e in evs)} of {n}; mean steps "
        f"to a verdict {steps_used / n:.0f} of a mean horizon of {mean_h:.0f}; re-run at dt/{settings.refine} "
        f"by the check: {checked}, verdicts changed by it: {refined}")
    log(f"  compiled chunk calls: oracle {len(rec.calls)} (check='none': {len(rec_low.calls)}); step-columns "
        f"computed: oracle {rec.step_columns:,} (check='none': {rec_low.step_columns:,}, of which needed for the "
        f"verdicts {steps_used + n:,}), full-horizon loop {fl_work:,}")

    # timed rounds -------------------------------------------------------------------------------
    log(f"\n(a)+(c) {R} interleaved rounds")
    T = rounds({
        "rk4": run_rk,
        "rk4_none": run_low,
        "floor": lambda: floor_all(chunks),
        "floor_raw": lambda: floor_all(raw),
        "own": lambda: replay(rec.calls, None),
        "own_none": lambda: replay(rec_low.calls, None),
        "own_raw": lambda: replay(rec.calls, rawc),
        "own_raw_none": lambda: replay(rec_low.calls, rawc),
    }, R)
    md = {k: statistics.median(v) for k, v in T.items()}
    mn = {k: min(v) for k, v in T.items()}
    what = {
        "rk4": f"(a) rk4 oracle, check={settings.check!r}",
        "rk4_none": "(a) rk4 oracle, check='none'",
        "floor": "(c) loop alone, full horizon, Chunk.run",
        "floor_raw": "(c) loop alone, full horizon, zero-copy",
        "own": "    oracle's chunk calls replayed, Chunk.run",
        "own_none": "    same, check='none'",
        "own_raw": "    oracle's chunk calls replayed, zero-copy",
        "own_raw_none": "    same, check='none'",
    }
    for k, label in what.items():
        rate = f"-> {n / md[k]:,.0f} calls/s" if not k.startswith("own") else ""
        log(f"  {label:45s} median {md[k] * 1e3:7.1f} ms  min {mn[k] * 1e3:7.1f} ms  {rate}")
    log(f"  ns per step-column, full-horizon loop: {md['floor'] / fl_work * 1e9:.0f} through Chunk.run, "
        f"{md['floor_raw'] / fl_work * 1e9:.0f} zero-copy (Chunk.run's numpy/DM conversion: "
        f"{1 - md['floor_raw'] / md['floor']:.0%} of its time)")
    r_floor = med_ratio(T["rk4"], T["floor"])
    r_floor_none = med_ratio(T["rk4_none"], T["floor"])
    r_floor_raw = med_ratio(T["rk4"], T["floor_raw"])
    r_own = med_ratio(T["rk4"], T["own_raw"])
    r_own_none = med_ratio(T["rk4_none"], T["own_raw_none"])
    r_own_run = med_ratio(T["rk4"], T["own"])
    log(f"  oracle / floor: {r_floor:.2f} (check='none' {r_floor_none:.2f}; vs the zero-copy floor {r_floor_raw:.2f}); "
        f"oracle / its own compiled work: {r_own:.1f}x zero-copy, {r_own_run:.2f}x through Chunk.run "
        f"(check='none': {r_own_none:.1f}x zero-copy)")

    # (b) scipy LSODA ----------------------------------------------------------------------------
    log(f"\n(b) scipy solve_ivp LSODA with terminal events (budget {budget:.0f} s)")
    s_sp = settings.replace(method="scipy")
    sp_oracles = {b: SafetyOracle(prims[b], s_sp) for b in pts}
    sp_ev, sp_t = {}, 0.0
    for b, i in order:
        if sp_t > budget:
            break
        x0s, t0s = pts[b]
        t = time.perf_counter()
        e = sp_oracles[b].evaluate(x0s[i:i + 1], t0s[i:i + 1])[0]
        sp_t += time.perf_counter() - t
        sp_ev[(b, i)] = e
    m = len(sp_ev)
    sp_per_call = sp_t / m
    sub = {}
    for (b, i) in sp_ev:
        sub.setdefault(b, []).append(i)
    sub_pts = {b: (pts[b][0][ix], pts[b][1][ix]) for b, ix in sub.items()}
    sub_med, _, _ = timed(lambda: [oracles[b].evaluate(x, t) for b, (x, t) in sub_pts.items()], R)
    rk_per_call = md["rk4"] / n
    ratio_sp = sp_per_call / rk_per_call
    ratio_sp_same = sp_per_call / (sub_med / m)
    log(f"  {m} calls ({'all points' if m == n else 'stratified subset'}) in {sp_t:.2f} s -> "
        f"{1 / sp_per_call:,.0f} calls/s ({sp_per_call * 1e3:.2f} ms per call); rk4 oracle {rk_per_call * 1e3:.3f} ms "
        f"per call -> {ratio_sp:.0f}x" + ("" if m == n else f" (rk4 on the same {m} points: {ratio_sp_same:.0f}x)"))
    dis, rk_safe_sp_unsafe, rk_unsafe_sp_safe, examples = 0, 0, 0, []
    for (b, i), e in sp_ev.items():
        r = ev_rk[b][i]
        if r.verdict != e.verdict:
            dis += 1
            if r.verdict == 1:
                rk_safe_sp_unsafe += 1
            else:
                rk_unsafe_sp_safe += 1
            if len(examples) < 8:
                examples.append(f"    B={b} x0={np.round(pts[b][0][i], 3).tolist()} t_B={pts[b][1][i]:.3f}: "
                                f"rk4 {r.verdict} ({r.reason.value} @ {r.t_stop:.3f}) vs "
                                f"LSODA {e.verdict} ({e.reason.value} @ {e.t_stop:.3f})")
    reasons_same = sum(ev_rk[b][i].reason == e.reason for (b, i), e in sp_ev.items())
    log(f"  verdicts on the {m} common points: {dis} disagreements (rk4 safe / LSODA unsafe: {rk_safe_sp_unsafe}; "
        f"rk4 unsafe / LSODA safe: {rk_unsafe_sp_safe}); safe by LSODA: {sum(e.verdict for e in sp_ev.values())}; "
        f"same stop reason: {reasons_same}")
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

    for level in ("low", "medium", "high"):
        sp_l = dataclasses.replace(spec, project=spec.project.model_copy(
            update={"oracle": spec.project.oracle.model_copy(update={"accuracy": level})}))
        st = settings_for(sp_l)
        runs = []
        _vr.build_chunk = _timed_bc
        try:
            for _ in range(BR):
                jit_acc[0] = 0.0
                t = time.perf_counter()
                _p, g, _o, info, _roa = build(sp_l, st)
                runs.append((time.perf_counter() - t, info["graph_s"], jit_acc[0], info, g))
        finally:
            _vr.build_chunk = _orig_bc
        total, gs, jit, info, g = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
        edges = g.G.number_of_edges()
        builds[level] = {"total": total, "graph_s": gs, "jit": jit, "calls": info["oracle_calls"],
                         "cps": info["oracle_calls"] / gs, "cps_nojit": info["oracle_calls"] / max(gs - jit, 1e-9),
                         "edges": edges}
        log(f"  {level:6s}: total {total:.2f} s (median of {BR}), graph {gs:.2f} s of which JIT {jit:.2f} s; "
            f"{info['oracle_calls']} oracle calls -> {builds[level]['cps']:,.0f} calls/s "
            f"({builds[level]['cps_nojit']:,.0f} without JIT), {edges} edges")

    # summary ------------------------------------------------------------------------------------
    d = builds.get(spec.project.oracle.accuracy, builds["medium"])
    lo = builds["low"]["total"]
    rows = [
        ("start points (stratified from Algorithm 1's grids)", f"{n} of {n_full}"),
        (f"rk4 oracle, default (`check={settings.check}`, dt={settings.dt:g}, T={settings.horizon:g})",
         f"{n / md['rk4']:,.0f} calls/s ({md['rk4'] * 1e3:.0f} ms)"),
        ("rk4 oracle, `check=none`", f"{n / md['rk4_none']:,.0f} calls/s ({md['rk4_none'] * 1e3:.0f} ms)"),
        ("scipy solve_ivp LSODA + terminal events" + ("" if m == n else f" ({m}-point subset)"),
         f"{1 / sp_per_call:,.0f} calls/s ({sp_per_call * 1e3:.2f} ms/call)"),
        ("compiled RK4 loop alone, full horizon, via Chunk.run (floor)",
         f"{n / md['floor']:,.0f} rollouts/s ({md['floor'] * 1e3:.0f} ms)"),
        ("same loop, zero-copy FunctionBuffer calls (pure compiled cost)",
         f"{n / md['floor_raw']:,.0f} rollouts/s ({md['floor_raw'] * 1e3:.0f} ms, "
         f"{md['floor_raw'] / fl_work * 1e9:.0f} ns/step)"),
        ("oracle's own chunk calls replayed zero-copy (its compiled work)",
         f"{md['own_raw'] * 1e3:.1f} ms (`check=none`: {md['own_raw_none'] * 1e3:.1f} ms)"),
        ("**speed-up rk4 oracle vs LSODA** (target >= 30x)",
         f"**{ratio_sp:.0f}x**" + ("" if m == n else f" (same {m} points: {ratio_sp_same:.0f}x)")),
        ("**rk4 oracle time / compiled-loop floor** (target <= 2)",
         f"**{r_floor:.2f}** (`check=none`: {r_floor_none:.2f}; vs zero-copy floor: {r_floor_raw:.2f})"),
        ("rk4 oracle time / its own compiled work (pure overhead)",
         f"{r_own:.1f}x (`check=none`: {r_own_none:.1f}x)"),
        (f"verdicts rk4 vs LSODA ({m} points)",
         f"{dis} disagree; rk4-safe/LSODA-unsafe {rk_safe_sp_unsafe}, rk4-unsafe/LSODA-safe {rk_unsafe_sp_safe}"),
        ("JIT compile per chunk (excluded from calls/s above)",
         f"{statistics.median(t_jit):.2f} s (K={settings.chunk}); fine-check chunk {t_jit_fine:.2f} s"),
        (f"graph build, {spec.project.oracle.accuracy} ({d['calls']} oracle calls, {d['edges']} edges)",
         f"{d['total']:.2f} s ({d['graph_s']:.2f} s graph, of which JIT {d['jit']:.2f} s); "
         f"{d['cps']:,.0f} calls/s ({d['cps_nojit']:,.0f} without JIT)"),
        ("accuracy presets low / medium / high: build time vs low",
         " / ".join(f"{builds[k]['total'] / lo:.2f}" for k in ("low", "medium", "high"))
         + " (" + " / ".join(f"{builds[k]['total']:.2f} s" for k in ("low", "medium", "high")) + ")"),
    ]
    w = max(len(a) for a, _ in rows)
    table = [f"| {'measure':{w}s} | value |", f"|{'-' * (w + 2)}|-------|"]
    table += [f"| {a:{w}s} | {b} |" for a, b in rows]
    table = "\n".join(table)
    when = _dt.datetime.now().strftime("%Y-%m-%d %H:%M")
    head = (f"Pendulum example (compile cache warm after the first measurement), {when}; {mach['nproc']} CPU ({mach['cpu']}), Python {mach['python']}, "
            f"CasADi {mach['casadi']}, NumPy {mach['numpy']}, SciPy {mach['scipy']};{load}; "
            f"`python bench/bench_oracle.py{' --quick' if args.quick else ''}` "
            f"(medians of {R} interleaved rounds, builds median of {BR}; {time.perf_counter() - T0:.0f} s wall).")
    log("\n" + head + "\n\n" + table)
    if not args.no_write:
        out = ROOT / "bench" / "RESULTS.md"
        rest = ""  # keep the sections other benchmarks wrote (e.g. "## A1 (rigid body)")
        if out.exists() and "\n## " in out.read_text():
            rest = "\n## " + out.read_text().split("\n## ", 1)[1]
        out.write_text("# Oracle benchmark results\n\n" + head + "\n\n" + table + "\n\n"
                       "See bench/README.md for the meaning of each row.\n" + rest)
        log(f"\nwrote {out.relative_to(ROOT)}")
    ok = ratio_sp >= 30 and r_floor <= 2 and rk_safe_sp_unsafe == 0
    log(f"targets: LSODA speed-up >= 30x {'met' if ratio_sp >= 30 else 'MISSED'}; "
        f"within 2x of the loop alone {'met' if r_floor <= 2 else 'MISSED'}; "
        f"no rk4-safe/LSODA-unsafe {'met' if rk_safe_sp_unsafe == 0 else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
