"""The gait tube's period map with one loop evaluation per state against the fold of hybrid_body.

    python bench/bench_period_map.py [--project a1|anymal] [--starts 48] [--periods 3] [--repeats 5] [--no-write]

In one process, for every walk of the project, `starts` seeded starts near the orbit (as the tube's
bisection draws them, at phases on the dt grid) run `periods` periods through two compiled period maps
that call the same loop library: HybridFlow.period_end (each step evaluates the loop once at its start
for k1, the jump's input and h of that state; 4 evaluations per step and one at the end) and the fold
of hybrid_body as HybridFlow compiled it before (k1 and the jump's input in two calls, h at the step's
end in a third: 6 per step). Prints the median per-round ratio and whether the states and least h are
the same bits.
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

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)

from mpgspec.api import compile_project  # noqa: E402
from mpgspec.certify import hybrid_orbit as ho  # noqa: E402
from mpgspec.compile.contacts import Schedule  # noqa: E402
from mpgspec.oracle import looplib  # noqa: E402
from mpgspec.oracle.flow import LEFT, rk4_jump  # noqa: E402
from mpgspec.oracle.jit import compile_many  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

HEADING = "## Gait tubes: the period map's loop evaluations"


def six_per_step(flow: ho.HybridFlow) -> ca.Function:
    """The period map as the fold of hybrid_body (the baseline), compiled as HybridFlow compiles its own."""
    prim, nx, h = flow.prim, flow.prim.system.nx, flow.dt
    xs0 = np.array(prim.setpoint(0.0), float).ravel()
    f, k, jump, h_of, _start = ho._parts(prim, xs0)
    left = LEFT if isinstance(prim.contacts, Schedule) else 0.0
    z = ca.MX.sym("z", nx + 2)
    x, t, m = z[:nx], z[nx], z[nx + 1]
    xn = rk4_jump(f, k, jump, x, t, h, left)
    body = ca.Function("hybrid_body", [z], [ca.vertcat(xn, t + h, ho._least(m, h_of(xn, t + h)))])
    zz = ca.MX.sym("z", nx + 2)
    fn = ca.Function("hybrid_period_end_six", [zz], [body.fold(flow.steps)(zz)])
    return compile_many([fn], looplib.caller_flags(prim, ("-O1",)), libs=looplib.libs_of(prim))[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", choices=("a1", "anymal"), default="a1")
    ap.add_argument("--starts", type=int, default=48)
    ap.add_argument("--periods", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    prims = compile_project(load_project(ROOT / "specs" / args.project / "project.yaml"))
    walks = [n for n, p in prims.items() if p.period is not None and ho.hold_size(p) == 0]
    rng = np.random.default_rng(0)
    runs, same = {}, True
    for n in walks:
        flow = ho.HybridFlow(prims[n], 0.001, states=False)
        old = six_per_step(flow)
        xs = np.array(prims[n].setpoint(0.0), float).ravel()
        X0 = xs[:, None] + 0.005 * rng.standard_normal((xs.size, args.starts))
        t0 = rng.integers(0, flow.steps, args.starts) * flow.dt
        Z0 = np.vstack([X0, t0[None, :], np.full((1, args.starts), np.inf)])
        new_map, old_map = flow.period_end.map(args.starts), old.map(args.starts)

        def roll(fn, Z=Z0):
            for _ in range(args.periods):
                Z = np.array(fn(Z), float)
            return Z

        same &= np.array_equal(roll(new_map), roll(old_map), equal_nan=True)
        runs[n] = (new_map, old_map, roll)
    times = common.rounds({"four": lambda: [r(a) for a, _b, r in runs.values()],
                           "six": lambda: [r(b) for _a, b, r in runs.values()]}, args.repeats)
    med = {k: float(np.median(v)) for k, v in times.items()}
    rows = [(f"walks ({args.project}); starts x periods each", f"{len(walks)}; {args.starts} x {args.periods}"),
            ("**6 loop evaluations per step / 4**", f"**{common.med_ratio(times['six'], times['four']):.2f}x** "
             f"({med['six'] * 1e3:.0f} ms vs {med['four'] * 1e3:.0f} ms per round)"),
            ("states and least h the same bits", "yes" if same else "**no**")]
    common.publish_rows(HEADING + ("" if args.project == "a1" else f" ({args.project})"), "bench_period_map.py",
                        args.repeats, t_all, rows, not args.no_write)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
