"""What certifying costs and how much of the pendulum it certifies: the validated oracle against rk4.

    python bench/bench_validated.py [--jobs 2] [--no-write]

In one process, on the pendulum example: Algorithm 1's whole grid (every source's setpoint on its
t_A grid, every target on its t_B grid: 4,930 oracle calls) through the rk4 oracle (jit, compiled
and warmed up first, then timed) and through the validated oracle (arb balls, timed), both on
`--jobs` worker processes; then the certified windows of every edge (t_A intervals proved for every
t_A, mpgspec.graph.certified). Prints the share of rk4's safe cells that are certified, the cells
the two disagree on (a decided verdict against the other decided one: must be 0), the share of
rk4's Class 1 edges certified for every t_A of the source's domain, and the time per cell of each
oracle with their ratio; writes the table to bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPGSPEC_CACHE", tempfile.mkdtemp(prefix="mpgspec-bench-"))

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)
import flint  # noqa: E402

from mpgspec.graph.build import build_graph  # noqa: E402
from mpgspec.graph.certified import certify_windows  # noqa: E402
from mpgspec.graph.transition import TransitionClass  # noqa: E402
from mpgspec.oracle.executors import make_executor  # noqa: E402
from mpgspec.pipeline.settings import settings_for  # noqa: E402
from mpgspec.pipeline.stages import compile_project  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from mpgspec.spec.models import PrimitiveClass  # noqa: E402

HEADING = "## Validated oracle: certified cells and windows on the pendulum"


def _graph(prims, settings, grid, executor):
    t = time.perf_counter()
    g = build_graph(prims, settings, grid.t_A, grid.t_B, None, executor)
    return g, time.perf_counter() - t


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    spec = load_project(ROOT / "specs" / "pendulum" / "project.yaml")
    prims = compile_project(spec)
    grid = spec.project.oracle.grid
    rk4 = settings_for(spec)
    val = rk4.replace(method="validated")
    ex = make_executor(args.jobs)
    _graph(prims, rk4, grid, ex)  # gcc and the workers' start outside the timing
    g_rk4, t_rk4 = _graph(prims, rk4, grid, ex)
    g_val, t_val = _graph(prims, val, grid, ex)
    t = time.perf_counter()
    certify_windows(g_val, prims, val, ex)
    t_win = time.perf_counter() - t
    cells = same = disagree = 0
    safe_rk4 = safe_cert = 0
    for key, tr in g_rk4.transitions.items():
        for row_r, row_v in zip(tr.evidence, g_val.transitions[key].evidence):
            for e, v in zip(row_r, row_v):
                cells += 1
                same += e.status == v.status
                decided = {e.status, v.status} <= {"safe", "unsafe"}
                disagree += decided and e.status != v.status
                if e.status == "safe":
                    safe_rk4 += 1
                    safe_cert += v.status == "safe" and v.method == "certified"
    counts = {k: sum(v.status == k for tr in g_val.transitions.values() for row in tr.evidence for v in row)
              for k in ("safe", "unsafe", "inconclusive")}
    class1 = [k for k, tr in g_rk4.transitions.items() if tr.cls == TransitionClass.CLASS_1]
    full = [k for k in class1 if _whole_domain(prims[k[0]], g_val.transitions[k])]
    moving = [k for k in class1 if prims[k[0]].cls is not PrimitiveClass.FIXED]
    full_moving = [k for k in full if k in moving]
    n = cells
    rows = [("oracle calls (Algorithm 1's grid)", f"{cells}"),
            ("validated verdicts safe / unsafe / inconclusive", f"{counts['safe']} / {counts['unsafe']} / "
                                                                f"{counts['inconclusive']} (all decided ones certified)"),
            ("decided verdicts that differ from rk4's (must be 0)", f"**{disagree}**"),
            ("**rk4-safe cells certified** (target >= 80 %)", f"**{safe_cert} of {safe_rk4} "
                                                              f"({100 * safe_cert / max(safe_rk4, 1):.1f} %)**"),
            ("**rk4 Class 1 edges certified for every t_A of the domain** (target >= 50 %)",
             f"**{len(full)} of {len(class1)} ({100 * len(full) / max(len(class1), 1):.0f} %)**; from a moving "
             f"source (periodic, transient): {len(full_moving)} of {len(moving)}"),
            ("time per oracle call, rk4 (jit, warm) / validated", f"{t_rk4 / n * 1e3:.2f} ms / {t_val / n * 1e3:.1f} ms"),
            ("**validated / rk4 time per call**", f"**{t_val / t_rk4:.0f}x**"),
            ("certified windows of all edges", f"{t_win:.0f} s ({sum(tr.certified.get('boxes', 0) for tr in g_val.transitions.values())} start sets)"),
            ("workers", f"{args.jobs}")]
    mach = common.machine(casadi=ca.__version__, flint=flint.__version__, revision=common.revision(ROOT))
    common.publish(HEADING, mach, "bench_validated.py", 1, time.perf_counter() - t_all, common.markdown_table(rows),
                   not args.no_write)
    return 0


def _whole_domain(a, tr) -> bool:
    """Whether the certified windows cover the source's whole t_A domain."""
    wins = tr.certified.get("windows", [])
    if a.cls is PrimitiveClass.FIXED:
        return bool(wins)
    lo, hi = (0.0, float(a.period)) if a.cls is PrimitiveClass.PERIODIC else a.t_range
    return any(w[0] <= lo + 1e-9 and w[1] >= hi - 1e-9 for w in wins)


if __name__ == "__main__":
    sys.exit(main())
