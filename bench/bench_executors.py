"""Executors, the result cache and the oracle's compute floor, measured as ratios in one process.

1. The graph stage (mpgspec.api.graph_stage: Algorithm 1 and the report's traces, no result
   cache) of the compiled pendulum and A1 projects with one process, a local pool of 2 processes
   and a Dask LocalCluster of 2 workers (pool and cluster start-up included, since a user pays
   them), interleaved rounds, medians; speed-up vs one process.
2. Incremental rebuild: a copy of the pendulum verified with a cold result store, then one
   primitive edited (Balance's radius) and verified again: calls re-run and time, as fractions of
   the full build.
3. Compute floor of the rk4 oracle on the pendulum's Swing(2.6) target (Algorithm 1's start
   points): the steps each rollout needs to its decision, times the compiled cost of one step
   (full 256-wide chunks, zero-copy), against the oracle's own time (accuracy low: no refinement),
   with the judge inside the compiled chunk (the default) and, in the same rounds, in Python on
   every step's outputs (RK4Runner(judged=False), as the oracle ran before); both give the same
   evidence, which is asserted.

Prints a markdown table; `--write` puts it into bench/RESULTS.md under "## Executors and cache".
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent))

from common import machine, rounds  # noqa: E402

from mpgspec import api  # noqa: E402
from mpgspec.graph.build import _start_points, grids  # noqa: E402
from mpgspec.oracle import SafetyOracle  # noqa: E402
from mpgspec.oracle.cache import CachedExecutor, ResultStore  # noqa: E402
from mpgspec.oracle.executors import DaskExecutor, InProcess, ProcessPool  # noqa: E402
from mpgspec.oracle.integrator import build_chunk, initial_state  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from verifiers.rk4 import RK4Runner  # noqa: E402


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def builds(project: Path, repeats: int, accuracy: str | None = None) -> dict:
    """The graph stage (Algorithm 1 and the report's traces) of a compiled project, per executor."""
    from mpgspec.settings import OracleSettings

    spec = load_project(project)
    settings = api.settings_for(spec)
    if accuracy:
        o = spec.project.oracle
        settings = OracleSettings.with_accuracy(accuracy, horizon=o.horizon, dt=o.dt, method=o.method)
    cp = api.compile_stage(spec, settings)
    api.graph_stage(cp, executor=InProcess())  # warm the compile cache
    fns = {"1 process": lambda: api.graph_stage(cp, executor=InProcess()),
           "pool of 2": lambda: api.graph_stage(cp, executor=ProcessPool(2)),
           "Dask, 2 workers": lambda: api.graph_stage(cp, executor=DaskExecutor(workers=2))}
    t = rounds(fns, repeats)
    base = t["1 process"]
    calls = api.graph_stage(cp).timing["oracle_calls"]
    return {k: (statistics.median(v), statistics.median(b / x for b, x in zip(base, v))) for k, v in t.items()} | \
        {"calls": calls}


def incremental(repeats: int) -> dict:
    out = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            proj = Path(tmp) / "pendulum"
            shutil.copytree(ROOT / "specs" / "pendulum", proj)
            store = ResultStore(Path(tmp) / "results.sqlite")
            full = CachedExecutor(InProcess(), store)
            t0 = time.perf_counter()
            api.verify([proj], out_dir=None, executor=full)
            t_full = time.perf_counter() - t0
            bal = proj / "primitives" / "balance.yaml"
            bal.write_text(bal.read_text().replace("radius: 0.2", "radius: 0.19"))
            edit = CachedExecutor(InProcess(), store)
            t0 = time.perf_counter()
            api.verify([proj], out_dir=None, executor=edit)
            t_edit = time.perf_counter() - t0
            again = CachedExecutor(InProcess(), store)
            t0 = time.perf_counter()
            api.verify([proj], out_dir=None, executor=again)
            t_none = time.perf_counter() - t0
            store.close()
            out.append((full.stats["cache_misses"], edit.stats["cache_misses"], again.stats["cache_misses"],
                        t_full, t_edit, t_none))
    a = np.array(out)
    med = np.median(a, axis=0)
    return {"calls_full": int(med[0]), "calls_edit": int(med[1]), "calls_again": int(med[2]),
            "t_full": med[3], "t_edit": med[4], "t_none": med[5],
            "frac_calls": med[1] / med[0], "frac_time": float(np.median(a[:, 4] / a[:, 3]))}


def floor(repeats: int) -> dict:
    spec = load_project(ROOT / "specs" / "pendulum" / "project.yaml")
    settings = api.settings_for(spec).replace(refinements=0)
    cp = api.compile_stage(spec, settings)
    prims = cp.prims
    g = spec.project.oracle.grid
    gA, gB = grids(prims, g.t_A, g.t_B)
    x0s, t0s, _ = _start_points(prims, gA, gB, "Swing(2.6)")
    prim = prims["Swing(2.6)"]
    oracle = SafetyOracle(prim, settings)
    python = SafetyOracle(prim, settings)
    python.runner = RK4Runner(prim, settings, judged=False)  # the judge in Python, on every step's outputs
    ev = oracle.evaluate(x0s, t0s)
    assert [e.to_dict() for e in ev] == [e.to_dict() for e in python.evaluate(x0s, t0s)]
    needed = int(sum(e.steps + 1 for e in ev))  # samples judged: steps taken plus the deciding one
    at_zero = sum(e.steps == 0 for e in ev)
    ch = build_chunk(prim, settings.dt, settings.chunk, settings.jit, settings.jit_flags)
    Z = np.stack([initial_state(prim, x0s[i % len(x0s)], t0s[i % len(x0s)]) for i in range(256)], axis=1)
    ev_fn, zin, _zf, _out = ch.bound(256)
    zin.reshape(Z.shape[0], 256, order="F")[:] = Z
    fns = {"oracle": lambda: oracle.evaluate(x0s, t0s), "python": lambda: python.evaluate(x0s, t0s), "chunk": ev_fn}
    out = {"points": len(t0s), "at_zero": int(at_zero), "steps_needed": needed}
    for clock, t in (("", rounds(fns, repeats)), ("cpu_", cpu_rounds(fns, repeats))):
        per_step = statistics.median(t["chunk"]) / (256 * ch.K)
        t_oracle, t_python = statistics.median(t["oracle"]), statistics.median(t["python"])
        out |= {clock + "ns_per_step": per_step * 1e9, clock + "floor_s": needed * per_step,
                clock + "oracle_s": t_oracle, clock + "ratio": t_oracle / (needed * per_step),
                clock + "python_s": t_python, clock + "ratio_python": t_python / (needed * per_step),
                clock + "speedup": statistics.median(p / o for p, o in zip(t["python"], t["oracle"]))}
    return out


def cpu_rounds(fns: dict, repeats: int) -> dict[str, list[float]]:
    """As common.rounds, in this process's CPU time: on a machine other jobs share, the time spent
    waiting for a core is left out (the calls run on one thread)."""
    out = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t = time.process_time()
            fn()
            out[k].append(time.process_time() - t)
    return out


def floor_rows(fl: dict) -> list[str]:
    return [f"| **oracle time / compute floor** (target <= 2), judge in the compiled chunk | **{fl['ratio']:.2f}** "
            f"({fl['oracle_s'] * 1e3:.1f} ms); in CPU time {fl['cpu_ratio']:.2f} ({fl['cpu_oracle_s'] * 1e3:.1f} ms "
            f"/ {fl['cpu_floor_s'] * 1e3:.1f} ms) |",
            f"| the same oracle with the judge in Python on every step's outputs (as before) | {fl['ratio_python']:.2f} "
            f"({fl['python_s'] * 1e3:.1f} ms); in CPU time {fl['cpu_ratio_python']:.2f}; the judge in the chunk "
            f"**{fl['speedup']:.2f}x** faster ({fl['cpu_speedup']:.2f}x in CPU time), same evidence |"]


def write_floor(fl: dict) -> None:
    """Replace the floor's rows of the section written by a full run (--only floor --write)."""
    res = ROOT / "bench" / "RESULTS.md"
    lines = res.read_text().splitlines()
    keep = [ln for ln in lines if not ln.startswith(("| **oracle time / compute floor**", "| the same oracle with the judge",
                                                      "| steps needed to the verdicts", "| rk4 oracle on Swing(2.6)"))]
    at = max(i for i, ln in enumerate(keep) if ln.startswith("| incremental:")) + 1
    rows = [f"| rk4 oracle on Swing(2.6): start points, decided at their first sample | {fl['points']}, {fl['at_zero']} |",
            f"| steps needed to the verdicts x compiled cost per step (floor) | {fl['steps_needed']:,} x "
            f"{fl['ns_per_step']:.0f} ns = {fl['floor_s'] * 1e3:.1f} ms |", *floor_rows(fl)]
    note = (f"Floor rows: {time.strftime('%Y-%m-%d %H:%M')}, `python bench/bench_executors.py --only floor` "
            f"(load average {' '.join(f'{v:.2f}' for v in __import__('os').getloadavg())}).")
    keep[at:at] = rows
    keep.insert(at + len(rows), "")
    keep.insert(at + len(rows) + 1, note)
    res.write_text("\n".join(keep) + "\n")


def table(b_p, b_v, b_a, inc, fl, info) -> str:
    rows = [
        "| measure | value |", "|---|---|",
        *[f"| pendulum graph stage ({b_p['calls']} calls), {k} | {v[0]:.2f} s, **{v[1]:.2f}x** vs 1 process |"
          for k, v in b_p.items() if k != "calls"],
        *[f"| pendulum graph stage at `accuracy: very_high` (dt/4), {k} | {v[0]:.2f} s, **{v[1]:.2f}x** vs 1 process |"
          for k, v in b_v.items() if k != "calls"],
        *[f"| A1 graph stage ({b_a['calls']} calls), {k} | {v[0]:.2f} s, {v[1]:.2f}x vs 1 process |"
          for k, v in b_a.items() if k != "calls"],
        f"| incremental: Balance edited, calls re-run | {inc['calls_edit']} of {inc['calls_full']} "
        f"(**{100 * inc['frac_calls']:.1f} %**; target <= 25 %) |",
        f"| incremental: verify time after the edit / full verify | {100 * inc['frac_time']:.0f} % "
        f"({inc['t_edit']:.2f} s / {inc['t_full']:.2f} s; nothing changed: {inc['calls_again']} calls, "
        f"{inc['t_none']:.2f} s) |",
        f"| rk4 oracle on Swing(2.6): start points, decided at their first sample | {fl['points']}, {fl['at_zero']} |",
        f"| steps needed to the verdicts x compiled cost per step (floor) | {fl['steps_needed']:,} x "
        f"{fl['ns_per_step']:.0f} ns = {fl['floor_s'] * 1e3:.1f} ms |",
        *floor_rows(fl),
    ]
    head = (f"{time.strftime('%Y-%m-%d %H:%M')}; {info['nproc']} CPU ({info['cpu']}), Python {info['python']}; "
            f"load average {' '.join(f'{v:.2f}' for v in __import__('os').getloadavg())}; "
            "`python bench/bench_executors.py` (medians of interleaved rounds).")
    return head + "\n\n" + "\n".join(rows) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="update bench/RESULTS.md")
    ap.add_argument("--only", choices=("floor",), help="only the compute floor (with --write: its rows only)")
    a = ap.parse_args(argv)
    if a.only == "floor":
        fl = floor(max(5, a.repeats))
        print("\n".join(floor_rows(fl)))
        if a.write:
            write_floor(fl)
        return 0
    log("pendulum builds")
    b_p = builds(ROOT / "specs" / "pendulum" / "project.yaml", a.repeats)
    log("pendulum builds, very_high")
    b_v = builds(ROOT / "specs" / "pendulum" / "project.yaml", a.repeats, "very_high")
    log("A1 builds")
    b_a = builds(ROOT / "specs" / "a1" / "project.yaml", max(1, a.repeats - 1))
    log("incremental rebuild")
    inc = incremental(a.repeats)
    log("compute floor")
    fl = floor(5)
    import casadi

    text = table(b_p, b_v, b_a, inc, fl, machine(casadi=casadi.__version__))
    print(text)
    if a.write:
        res = ROOT / "bench" / "RESULTS.md"
        cur = res.read_text() if res.exists() else "# Benchmark results\n"
        head = "## Executors and cache"
        if head in cur:
            a0 = cur.index(head)
            b0 = cur.find("\n## ", a0 + len(head))
            cur = cur[:a0] + cur[b0 + 1:] if b0 >= 0 else cur[:a0]
        res.write_text(cur.rstrip() + f"\n\n{head}\n\n" + text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
