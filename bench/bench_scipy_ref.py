"""What the scipy reference backend's own LSODA driver saves against solve_ivp, the same numbers.

    python bench/bench_scipy_ref.py [--project pendulum|cart] [--points 300] [--repeats 5] [--no-write]

In one process, a seeded sample of Algorithm 1's oracle calls on an example project (each source's
setpoint on its t_A grid, every target on its t_B grid) runs through the "scipy" backend twice per
round: each piece between clock switches and guard crossings stepped by verifiers.lsoda_piece (scipy's
LSODA, its event search and solution object, without solve_ivp's per-step array bookkeeping), and the
same pieces through solve_ivp itself (lsoda_piece's fallback, forced here). Prints the median
per-round ratio and whether every evidence (verdict, margins, times, bounds) is the same on both.
The right-hand side and the judge's samples are on NumPy buffers on both sides.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPGSPEC_CACHE", tempfile.mkdtemp(prefix="mpgspec-bench-"))

import common  # noqa: E402  (bench/common.py)
from bench_oracle import example, own_grid_points, stratified  # noqa: E402

import verifiers.lsoda_piece as piece  # noqa: E402
from mpgspec.oracle import SafetyOracle  # noqa: E402

HEADING = "## Reference backend: its LSODA driver against solve_ivp"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", choices=("pendulum", "cart"), default="pendulum")
    ap.add_argument("--points", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    prims, settings = example(args.project)
    st = settings.replace(method="scipy")
    pts, _order, _ = stratified(own_grid_points(prims), args.points)
    oracles = {b: SafetyOracle(prims[b], st) for b in pts}
    own = piece.handle_events

    def run(lean: bool) -> list:
        piece.handle_events = own if lean else None  # None: every piece through solve_ivp
        try:
            return [vars(e) for b, (x0s, t0s) in pts.items() for e in oracles[b].evaluate(x0s, t0s)]
        finally:
            piece.handle_events = own

    same = repr(run(True)) == repr(run(False))
    times = common.rounds({"lean": lambda: run(True), "solve_ivp": lambda: run(False)}, args.repeats)
    med = {k: float(np.median(v)) for k, v in times.items()}
    n = sum(len(v[1]) for v in pts.values())
    rows = [(f"oracle calls per round ({args.project}, a seeded sample of Algorithm 1's)", f"{n}"),
            ("**solve_ivp / lsoda_piece**", f"**{common.med_ratio(times['solve_ivp'], times['lean']):.2f}x** "
             f"({med['solve_ivp'] * 1e3:.0f} ms vs {med['lean'] * 1e3:.0f} ms per round, "
             f"{med['lean'] / n * 1e3:.1f} ms per call)"),
            ("every evidence the same (verdicts, margins, times, bounds)", "yes" if same else "**no**")]
    common.publish_rows(HEADING + ("" if args.project == "pendulum" else f" ({args.project})"), "bench_scipy_ref.py",
                        args.repeats, t_all, rows, not args.no_write)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
