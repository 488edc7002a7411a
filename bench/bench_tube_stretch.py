"""A gait tube's starts before contact changes: run through the change and 20 ms beyond against a whole period.

    python bench/bench_tube_stretch.py [--project a1|anymal] [--starts 512] [--radii 0.01 0.006] [--repeats 3] [--no-write]

In one process, for every walk of the project and radius, `starts` seeded starts on E's sphere at phases in the
last 20 ms before a scheduled contact change, put on the contact manifold of the feet held there and inside C
(as the floquet verifier draws them), run through two compiled maps of the walk's own discrete flow:
HybridFlow.run_stretch (40 steps: through the change and 20 ms beyond, what the verifier runs) and
HybridFlow.period_end (one whole period, the baseline). Prints the median ratio of their times and how many
starts leave C in each: the short run is sound for the sizing only if it finds every start the period finds.
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

from mpgspec.api import compile_project, settings_for  # noqa: E402
from mpgspec.certify import hybrid_orbit as ho  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from verifiers import floquet_hybrid as fh  # noqa: E402

HEADING = "## Gait tubes: starts before a contact change, run 40 ms or a period"
WINDOW = 0.02


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", choices=("a1", "anymal"), default="a1")
    ap.add_argument("--starts", type=int, default=512)
    ap.add_argument("--radii", type=float, nargs="+", default=[0.01, 0.006])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    spec = load_project(ROOT / "specs" / args.project / "project.yaml")
    prims, tol = compile_project(spec), settings_for(spec).h_tolerance
    walks = [n for n, p in prims.items() if p.period is not None and ho.hold_size(p) == 0]
    rows, runs, missed = [], {}, 0
    for n in walks:
        p = prims[n]
        flow, W = ho.HybridFlow(p, 0.001, stretch=2 * fh.window_steps(WINDOW, 0.001)), np.asarray(p.W)
        Xs = ho.orbit(flow, W)[0]
        rng = np.random.default_rng(0)
        for r in args.radii:
            k = fh.before_changes(p, flow.dt, flow.steps, args.starts, WINDOW, rng)
            X0 = fh.placed(p, flow.dt, Xs, fh.inverse_root(W), r, fh.unit_sphere(k.size, W.shape[0], rng), k, W)
            inside = flow.least_h(X0, k * flow.dt) >= -tol
            X0, t0 = X0[:, inside], k[inside] * flow.dt
            short = lambda X0=X0, t0=t0: flow.run_stretch(X0, t0)  # noqa: E731
            whole = lambda X0=X0, t0=t0: flow.run_until(X0, t0, 1)[:2]  # noqa: E731
            bad = [~(hmin >= 0) | ~np.isfinite(XT).all(axis=0) for XT, hmin in (short(), whole())]
            missed += int((bad[1] & ~bad[0]).sum())
            rows.append((f"{n}, r = {r:g}: starts in C; leave C within 40 ms / within the period",
                         f"{int(inside.sum())}; {int(bad[0].sum())} / {int(bad[1].sum())}"))
            runs[(n, r)] = (short, whole)
    times = common.rounds({"short": lambda: [s() for s, _w in runs.values()],
                           "whole": lambda: [w() for _s, w in runs.values()]}, args.repeats)
    med = {k: float(np.median(v)) for k, v in times.items()}
    rows += [("**a whole period / 40 ms**", f"**{common.med_ratio(times['whole'], times['short']):.2f}x** "
              f"({med['whole']:.2f} s vs {med['short']:.2f} s per round, every walk and radius)"),
             ("starts that leave C within the period but not within 40 ms", str(missed))]
    common.publish_rows(HEADING + ("" if args.project == "a1" else f" ({args.project})"), "bench_tube_stretch.py",
                        args.repeats, t_all, rows, not args.no_write)
    return 0 if missed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
