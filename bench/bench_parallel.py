"""The robust stage on one core and on two, measured as ratios in one process.

    python bench/bench_parallel.py              # about 15 minutes on 2 cores with a warm compile cache
    python bench/bench_parallel.py --quick      # 1 round, no uncertain sequence
    options: --repeats R, --targets A,B, --no-sequence, --no-write

1. The A1's robust checks of two targets (mpgspec.robust.graph.check_targets: every cell of every
   in-edge under the project's scenarios, the adversarial search and the target's own flow), the
   two targets in this process (-j 1) and in a pool of 2 processes (-j 2, pool start-up and the
   closed loops' transfer included, since a user pays them). By default Walk(slow) and
   Walk(medium): five in-edges each, so the two jobs are of a size (two unequal targets cannot use
   two cores: the larger one is the critical path).
2. The A1's goal sequence under sampled uncertainty (the project's runs and seed), naive and
   through the nominal graph twice (as the graph and robust-graph modes: the cost of a mode, not
   its statistics), -j 1 against the three modes spread over 2 processes.
3. The pendulum's whole robust stage (all six targets and its uncertain sequence), -j 1 against -j 2.

The compile cache (MPGSPEC_CACHE, else ~/.cache/mpgspec) is warmed by a first run of each
measurement, which also gives the reference result every timed run must equal. Rounds are
interleaved; a row is the median over rounds, a ratio the median of per-round ratios. The machine
is shared with other jobs: quote the ratios, not the seconds. Prints a table and replaces (or
appends) the section "Robust stage on two cores" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)
from common import markdown_table, med_ratio, rounds, stamp, write_section  # noqa: E402

from mpgspec import api  # noqa: E402
from mpgspec.graph.build import build_graph  # noqa: E402
from mpgspec.oracle.cache import CachedExecutor  # noqa: E402
from mpgspec.oracle.executors import InProcess, ProcessPool  # noqa: E402
from mpgspec.plan.planner import lookup_table  # noqa: E402
from mpgspec.robust.graph import check_targets, robust_stage, target_jobs  # noqa: E402
from mpgspec.robust.sequence import sequence_under_uncertainty  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

HEADING = "## Robust stage on two cores"


def log(msg: str) -> None:
    print(msg, flush=True)


def same(a, b) -> str:
    """The results as JSON without timings, for the identity check."""
    return json.dumps(a, sort_keys=True, default=float) == json.dumps(b, sort_keys=True, default=float)


def a1_graph():
    """The A1 compiled (E sized) and its nominal graph, oracle results and sizing from the cache."""
    spec = load_project(ROOT / "specs" / "a1" / "project.yaml")
    st = api.settings_for(spec)
    ex = CachedExecutor(ProcessPool(2))
    t = time.perf_counter()
    cp = api.compile_stage(spec, st, memo=ex.memo)
    grid = spec.project.oracle.grid
    g = build_graph(cp.prims, st, grid.t_A, grid.t_B, None, ex)
    log(f"A1 compiled and its graph built in {time.perf_counter() - t:.0f} s")
    return cp, g


def timed_pair(name: str, fn, R: int, rows: list, check) -> None:
    """Warm-up (the reference), then R interleaved rounds of fn(InProcess()) and fn(ProcessPool(2))."""
    t = time.perf_counter()
    ref = fn(InProcess())
    log(f"{name}: warm-up {time.perf_counter() - t:.1f} s")
    out = {}
    res = rounds({"j1": lambda: out.__setitem__("j1", fn(InProcess())),
                  "j2": lambda: out.__setitem__("j2", fn(ProcessPool(2)))}, R)
    for k in out:
        assert check(out[k], ref), f"{name}: {k} differs from the reference"
    j1, j2 = statistics.median(res["j1"]), statistics.median(res["j2"])
    log(f"{name}: -j 1 {j1:.1f} s, -j 2 {j2:.1f} s, speed-up {med_ratio(res['j1'], res['j2']):.2f}x "
        f"(rounds: {[round(x, 1) for x in res['j1']]} / {[round(x, 1) for x in res['j2']]})")
    rows += [(f"{name}, -j 1 (this process)", f"{j1:.1f} s"),
             (f"{name}, -j 2 (pool of 2)", f"{j2:.1f} s, **{med_ratio(res['j1'], res['j2']):.2f}x** vs -j 1")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="1 round, no uncertain sequence")
    ap.add_argument("--repeats", type=int, default=None, help="measurement rounds (default 2, quick 1)")
    ap.add_argument("--targets", default="Walk(slow),Walk(medium)", help="two A1 targets, comma-separated")
    ap.add_argument("--no-sequence", action="store_true", help="skip the A1's uncertain sequence")
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    R = args.repeats or (1 if args.quick else 2)
    T0 = time.perf_counter()
    mach = common.machine(casadi=ca.__version__, numpy=np.__version__, revision=common.revision(ROOT))
    rows: list[tuple[str, str]] = []
    cp, g = a1_graph()
    unc = cp.spec.project.uncertainty
    _, jobs = target_jobs(cp.spec, cp.prims, cp.settings, g)
    two = [j for j in jobs if j.target in args.targets.split(",")]
    names = " and ".join(f"{j.target} ({len(j.items)} in-edges)" for j in two)
    log(f"A1 targets: {names}")
    timed_pair(f"A1 robust checks of {names}", lambda ex: check_targets(two, cp.prims, unc, ex)[:3], R, rows,
               same)
    if not (args.quick or args.no_sequence):
        graphs = {"graph": (g, lookup_table(g)), "robust_graph": (g, lookup_table(g))}
        timed_pair(f"A1 uncertain sequence ({unc.runs} runs, 3 modes)",
                   lambda ex: sequence_under_uncertainty(cp.spec, cp.prims, cp.settings, graphs, unc.runs, unc.seed,
                                                         ex), 1, rows, same)
    spec = load_project(ROOT / "specs" / "pendulum" / "project.yaml")
    pcp, pvg = api.build(spec, api.settings_for(spec), executor=InProcess())
    timed_pair("pendulum robust stage (6 targets, uncertain sequence)",
               lambda ex: {k: v for k, v in robust_stage(pcp, pvg, executor=ex).to_dict().items() if k != "timing"},
               R, rows, same)
    table = markdown_table(rows)
    print(table)
    if not args.no_write:
        section = (f"{HEADING}\n\n{stamp(mach, 'bench_parallel.py', args.quick, R, time.perf_counter() - T0)} "
                   "The machine is shared with other jobs (2 cores, 3-4 processes): quote the ratios. The compile "
                   "cache is warm; every timed result equals the warm-up's.\n\n" + table + "\n")
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
