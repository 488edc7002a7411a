"""Benchmark of the polynomial SOS certificates on the time-reversed Van der Pol oscillator.

    python bench/bench_sos.py               # about 1 minute on 2 cores
    python bench/bench_sos.py --no-write    # print only
    options: --degrees 4 6, --repeats R (rounds of the quadratic certificate, default 3)

x1' = -x2, x2' = x1 + (x1^2 - 1) x2; its true region of attraction is bounded by the unstable
limit cycle, and the largest ball inside it has radius 1.5317. In one process it runs the `sos`
verifier with the quadratic V of the Lyapunov equation (degree 2) and with polynomial V of each
degree given (V-rho alternation, verifiers/polyv.py, default options), and prints for each: the
certified ball radius, its fraction of 1.5317, the alternation's iterations, the wall time and its
ratio to the quadratic certificate's time (median of R rounds), and the number of SOS solves of the
level bisections (rho, ball) with their time in cvxpy and the solver; the rest is building the
programs, the positivity checks of V and the V steps. Replaces (or appends)
the section "SOS certificates" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import casadi as ca
import cvxpy as cp
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, revision, write_section  # noqa: E402

from mpgspec.certify.problem import RoAProblem  # noqa: E402
from verifiers import sos  # noqa: E402

HEADING = "## SOS certificates"
TRUE_BALL = 1.5317


def solve_seconds(ev: dict) -> tuple[int, float]:
    """Level-bisection SOS solves and their solver time: over the alternation's iterations, or the
    parts of a quadratic certificate."""
    rows = ev.get("iterations")
    if rows:
        return sum(r.get("sos_solves", 0) for r in rows), sum(r.get("sos_solve_s", 0.0) for r in rows)
    parts = ev.get("parts", [])
    return sum(p.get("solves", 0) for p in parts), sum(p.get("solve_time_s", 0.0) for p in parts)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--degrees", type=int, nargs="+", default=[4, 6])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args()
    x = ca.SX.sym("x", 2)
    vdp = RoAProblem(ca.Function("f", [x], [ca.vertcat(-x[1], x[0] + (x[0] ** 2 - 1) * x[1])]), np.zeros(2))
    T0 = time.perf_counter()
    quad_t = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        quad = sos.verifier.estimate(vdp, {})
        quad_t.append(time.perf_counter() - t)
    tq = statistics.median(quad_t)
    rows = [("2 (Lyapunov equation, Q = I)", quad, tq, "-")]
    for d in args.degrees:
        t = time.perf_counter()
        res = sos.verifier.estimate(vdp, {"degree": d})
        rows.append((str(d), res, time.perf_counter() - t, str(len(res.evidence.get("iterations", [])) - 1)))
        print(f"degree {d}: r = {res.radius:.4f} ({res.level}) in {rows[-1][2]:.1f} s", file=sys.stderr)
    table = ["| degree of V | certified ball r | r / 1.5317 | iterations | wall time | level-set solves (solver time) "
             "| time / quadratic |", "|---|---|---|---|---|---|---|"]
    for name, res, sec, it in rows:
        n, st = solve_seconds(res.evidence)
        table.append(f"| {name} | {res.radius:.4f} ({res.level}) | {res.radius / TRUE_BALL:.1%} | {it} | "
                     f"{sec:.2f} s | {n} ({st:.2f} s) | {sec / tq:.0f}x |")
    mach = machine(casadi=ca.__version__, cvxpy=cp.__version__, numpy=np.__version__)
    when = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    head = (f"Time-reversed Van der Pol, {when}, {revision(ROOT)}; {mach['nproc']} CPU ({mach['cpu']}), Python "
            f"{mach['python']}, cvxpy {mach['cvxpy']} with Clarabel; `python bench/bench_sos.py` "
            f"({time.perf_counter() - T0:.0f} s wall). Largest ball inside the true region of attraction: 1.5317. "
            f"Every radius is certified (each certificate checked in float64; the ball by an S-procedure "
            f"certificate of V <= rho on it); the quadratic time is the median of {args.repeats} runs.")
    section = f"{HEADING}\n\n{head}\n\n" + "\n".join(table) + "\n"
    print(section)
    if not args.no_write:
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, section)
    ok = all(res.level == "certified" and res.radius <= TRUE_BALL for _, res, _, _ in rows)
    return 0 if ok and rows[-1][1].radius >= 0.9 * TRUE_BALL else 1


if __name__ == "__main__":
    sys.exit(main())
