"""Benchmark of a robust cell as one decision: its scenarios run in waves and stop once one is unsafe.

    python bench/bench_robust_stop.py                      # Walk(in_place) and Stand, 3 rounds
    python bench/bench_robust_stop.py --targets 'Walk(fast)' --repeats 5
    options: --no-write

specs/a1's nominal graph is built first (its oracle calls from the result cache when they are
there); then each target's robust check (mpgspec.robust.cells.run_target: its in-edges' cells
under the 27 scenarios, the search, its own flow) runs in this process, in interleaved rounds:

  waves  as verify runs it: a cell's scenarios run in two waves (the box's corners without
         disturbance, then the rest only if every one of those was safe), and a cell's (and an own
         flow's) rollouts stop once one of them is unsafe;
  stop   one wave: every scenario of a cell at once, stopping once one is unsafe;
  full   the baseline: one wave, every rollout runs until it is decided alone (entered E_B, left
         C_B, or reached the horizon).

Rows: the median time of each and the median per-round ratios, the rollouts started and stopped
undecided, and whether every cell's and own flow's verdict is the same (it must be).
Prints a table and replaces (or appends) the section "Robust cells stop once decided" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402
import common  # noqa: E402  (bench/common.py)
from common import markdown_table, med_ratio, rounds, stamp, write_section  # noqa: E402

from mpgspec.robust.cells import run_target  # noqa: E402
from mpgspec.robust.rollout import RobustRollout  # noqa: E402
from mpgspec.robust.scenarios import Scenarios  # noqa: E402

HEADING = "## Robust cells stop once decided"
STOP = RobustRollout.run_groups
WAVES = Scenarios.waves


def _full(self, *a, groups=None, **k):
    """run_groups with no groups: every rollout runs until it is decided alone."""
    return STOP(self, *a, **k)


def _one_wave(self):
    return [np.arange(self.S)]


def check(prims, job, mode: str):
    """run_target as `mode` runs it: 'waves' (verify's), 'stop' (one wave) or 'full'."""
    RobustRollout.run_groups = _full if mode == "full" else STOP
    Scenarios.waves = WAVES if mode == "waves" else _one_wave
    try:
        return run_target(prims, job)
    finally:
        RobustRollout.run_groups, Scenarios.waves = STOP, WAVES


def stopped(res) -> int:
    return sum(sum(e["cells"]["stopped"]) for e in res[0]) + res[1]["stopped"]


def verdicts(res) -> tuple:
    edges, node, _, _ = res
    return tuple((e["from"], tuple(e["cells"]["robust_safe"])) for e in edges) + (node["robust_safe"],)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets", nargs="+", default=["Walk(in_place)", "Stand"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    T0 = time.perf_counter()
    mach = common.machine(casadi=ca.__version__, numpy=np.__version__, revision=common.revision(ROOT))
    cp, jobs = common.a1_target_jobs(args.targets)
    fns, facts = {}, {}
    modes = ("waves", "stop", "full")
    for name, job in jobs.items():
        res = {m: check(cp.prims, job, m) for m in modes}  # builds the rollout once, and checks
        facts[name] = {m: (res[m][2], stopped(res[m])) for m in modes}
        facts[name]["same"] = len({verdicts(r) for r in res.values()}) == 1
        print(f"{name}: " + "; ".join(f"{m} {facts[name][m][0]} rollouts, {facts[name][m][1]} stopped" for m in modes)
              + f"; verdicts equal: {facts[name]['same']}", flush=True)
        for m in modes:
            fns[f"{m} {name}"] = lambda j=job, m=m: check(cp.prims, j, m)
    times = rounds(fns, args.repeats)
    med = statistics.median
    rows = []
    for name, f in facts.items():
        w, s, full = (times[f"{m} {name}"] for m in modes)
        rows += [(f"{name}: target check, every rollout to its own decision (full)", f"{med(full):.1f} s"),
                 (f"{name}: one wave, a cell's rollouts stop once one is unsafe (stop)", f"{med(s):.1f} s"),
                 (f"{name}: corners first, the rest only for a cell still safe (waves)", f"{med(w):.1f} s"),
                 (f"**{name}: waves / stop**", f"**{med_ratio(w, s):.2f}x**"),
                 (f"**{name}: waves / full**", f"**{med_ratio(w, full):.2f}x**"),
                 (f"{name}: rollouts started / stopped undecided or never started (waves)", f"{f['waves'][0]} / {f['waves'][1]}"),
                 (f"{name}: rollouts started / stopped undecided or never started (stop)", f"{f['stop'][0]} / {f['stop'][1]}"),
                 (f"{name}: every cell's and own flow's verdict equal", str(f["same"]))]
    table = markdown_table(rows)
    head = stamp(mach, "bench_robust_stop.py", False, args.repeats, time.perf_counter() - T0) + " specs/a1, one process."
    section = f"{HEADING}\n\n{head}\n\n{table}\n\nSee the docstring of bench/bench_robust_stop.py for the meaning of each row.\n"
    print("\n" + section)
    if not args.no_write:
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, section)
    return 0 if all(f["same"] for f in facts.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
