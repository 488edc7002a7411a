"""How far MuJoCo's walk sits from the orbit E is built around, nominal and under each cross-check variant.

    python bench/bench_transfer_gap.py                    # specs/a1, Walk(fast), every variant
    options: --project DIR, --walk NAME, --seconds T (default 3), --settle S (default 1), --no-write

The graph executor switches out of a walk only from states inside E (||x - x*(t)||_W <= r). This
runs the walk alone in MuJoCo, from x*(t_B) at its first double support, for T seconds under the
project's cross-check settings and under each of its `crosscheck.variants`, and measures the W-distance
of MuJoCo's state from x*(clock) at every control update after the first S seconds (the walk's
multipliers are below 0.05: a second is about 30 periods). Per run: least, median and largest
distance, the median over E's radius, the median over the nominal run's (the ratio this bench
exists for: how much a model or sensing error moves the orbit in E's metric), and which states
carry most of the squared distance. Replaces the section "A1 walks in MuJoCo: distance from the
orbit" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import publish_rows  # noqa: E402

from mpgspec.api import compile_project, load_project  # noqa: E402
from mpgspec.execute.crosscheck.mjcf import build_robot  # noqa: E402
from mpgspec.execute.crosscheck.replay import replay  # noqa: E402
from mpgspec.execute.crosscheck.settings import settings_of, variants_of  # noqa: E402

HEADING = "## A1 walks in MuJoCo: distance from the orbit"


def distances(p, rep, settle: float) -> tuple[np.ndarray, np.ndarray]:
    """(W-distance per control update after `settle` s, each state's mean share of the squared distance)."""
    W = np.asarray(p.W, float)
    keep = [k for k in range(len(rep.t)) if rep.t[k] >= settle and np.isfinite(rep.x[k]).all()]
    dx = np.array([rep.x[k] - p.x_star(float(rep.clock[k])) for k in keep]) if keep else np.zeros((0, W.shape[0]))
    sq = dx * (dx @ W.T)
    d2 = sq.sum(axis=1)
    share = sq.mean(axis=0) / max(d2.mean(), 1e-300) if len(d2) else np.zeros(W.shape[0])
    return np.sqrt(np.maximum(d2, 0.0)), share


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1"))
    ap.add_argument("--walk", default="Walk(fast)")
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--settle", type=float, default=1.0)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    t_start = time.perf_counter()
    spec = load_project(Path(args.project) / "project.yaml")
    prims = compile_project(spec)
    p = prims[args.walk]
    base = settings_of(spec)
    runs = [("the project's cross-check settings", base)] + [(n, st) for n, st, _c in variants_of(spec, base)]
    t_B = float(p.t_range[0]) + 0.19 if p.period and p.period > 0.19 else float(p.t_range[0])
    names = p.system.state_names
    rows, nominal = [], None
    for label, st in runs:
        robot = build_robot(p.system, st)
        rep = replay(robot, prims, [{"t": 0.0, "to": args.walk, "clock": t_B}], args.seconds, st, 0.0)
        rep.clock = t_B + rep.t  # the walk's clock at each control update
        d, share = distances(p, rep, args.settle)
        if not len(d):
            rows.append((label, "no finite state after the settling time"))
            continue
        med = float(np.median(d))
        nominal = nominal if nominal is not None else med
        top = np.argsort(-share)[:3]
        what = ", ".join(f"{names[i]} {share[i]:.0%}" for i in top)
        rows.append((label, f"least {d.min():.4f}, median {med:.4f}, largest {d.max():.4f}; median / r "
                            f"{med / float(p.radius):.2f}, / nominal's **{med / nominal:.2f}x**; most of it: {what}"))
        print(label, rows[-1][1], flush=True)
    rows.insert(0, ("run (the walk alone in MuJoCo)", f"{args.walk} from x*({t_B:.2f}) for {args.seconds:g} s, "
                    f"distance ||x - x*(t)||_W after {args.settle:g} s; E's radius r = {float(p.radius):g}"))
    publish_rows(HEADING, "bench_transfer_gap.py", 1, t_start, rows, not args.no_write)


if __name__ == "__main__":
    main()
