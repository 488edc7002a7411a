"""Benchmark of a robust cell as one decision: its scenarios stop once one of them is unsafe.

    python bench/bench_robust_stop.py                      # Walk(in_place) and Stand, 3 rounds
    python bench/bench_robust_stop.py --targets 'Walk(fast)' --repeats 5
    options: --no-write

specs/a1's nominal graph is built first (its oracle calls from the result cache when they are
there); then each target's robust check (mpgspec.robust.cells.run_target: its in-edges' cells
under the 27 scenarios, the search, its own flow) runs in this process, in interleaved rounds:

  stop   as verify runs it: a cell's (and an own flow's) rollouts stop once one of them is unsafe;
  full   the baseline: every rollout runs until it is decided alone (entered E_B, left C_B, or
         reached the horizon), as before the stop.

Rows: the median time of each and the median per-round ratio stop / full, the rollouts each ran to
a decision, and whether every cell's and own flow's verdict is the same (it must be).
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

from mpgspec import api  # noqa: E402
from mpgspec.pipeline.stages import build  # noqa: E402
from mpgspec.robust.cells import run_target  # noqa: E402
from mpgspec.robust.graph import target_jobs  # noqa: E402
from mpgspec.robust.rollout import RobustRollout  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## Robust cells stop once decided"
STOP = RobustRollout.run_groups


def _full(self, *a, groups=None, **k):
    """run_groups with no groups: every rollout runs until it is decided alone."""
    return STOP(self, *a, **k)


def check(prims, job, stop: bool):
    RobustRollout.run_groups = STOP if stop else _full
    try:
        return run_target(prims, job)
    finally:
        RobustRollout.run_groups = STOP


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
    spec = load_project(SPEC)
    cp, vg = build(spec, api.settings_for(spec), executor=api.executor(1, None, cache=True))
    _, jobs = target_jobs(spec, cp.prims, cp.settings, vg.graph)
    jobs = {j.target: j for j in jobs if j.target in args.targets}
    fns, facts = {}, {}
    for name, job in jobs.items():
        a, b = check(cp.prims, job, True), check(cp.prims, job, False)  # builds the rollout once, and checks
        stopped = sum(sum(e["cells"]["stopped"]) for e in a[0]) + a[1]["stopped"]
        facts[name] = {"rollouts": a[2], "stopped": stopped, "same": verdicts(a) == verdicts(b)}
        print(f"{name}: {a[2]} rollouts, {stopped} stopped; verdicts equal: {facts[name]['same']}", flush=True)
        fns[f"stop {name}"] = lambda j=job: check(cp.prims, j, True)
        fns[f"full {name}"] = lambda j=job: check(cp.prims, j, False)
    times = rounds(fns, args.repeats)
    med = statistics.median
    rows = []
    for name, f in facts.items():
        s, full = times[f"stop {name}"], times[f"full {name}"]
        rows += [(f"{name}: target check, every rollout to its own decision (full)", f"{med(full):.1f} s"),
                 (f"{name}: target check, a cell's rollouts stop once one is unsafe", f"{med(s):.1f} s"),
                 (f"**{name}: stop / full**", f"**{med_ratio(s, full):.2f}x**"),
                 (f"{name}: rollouts stopped undecided / started", f"{f['stopped']} / {f['rollouts']}"),
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
