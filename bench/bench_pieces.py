"""What stepping piece by piece costs: the oracle on loops with guards, against the same loops without.

    python bench/bench_pieces.py [--project pendulum|a1] [--repeats 7] [--no-write]

In one process, on an example project, every oracle call of Algorithm 1 (each source's setpoint
on its t_A grid, every target on its t_B grid) is made twice per round with jit: through the
guarded step (oracle/pieces.py) and through the same primitives with their guards removed, i.e.
the smooth step every loop took before guards. Prints the median per-round ratio guarded /
unguarded (target <= 1.3x) and the verdict counts of both, and writes the table to
bench/RESULTS.md.

- pendulum (small loops, inlined): every primitive's loop has guards (its input saturation,
  SwingUp's switch at t = 1.5, the swings' clock wrap); both error estimates. A guarded chunk is
  compiled at judged.GUARDED_FLAGS (-O1) by gcc, or at the project's flags (-O0) by tcc when it is
  installed (bench_quick_cc.py), an unguarded one at the project's flags: the table also gives the
  ratio with the unguarded chunks at -O1, the cost of the guards alone.
- a1 (large loops, called from their loop libraries; E sized as `mpgspec verify` sizes it): the
  walks' 24 torque limits and their gait's clock guards, the transients' likewise; the sampled
  ID-QP of Stand and Lie has none. The project's own error estimate (step doubling).
"""
from __future__ import annotations

import argparse
import dataclasses
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
from bench_oracle import example, own_grid_points  # noqa: E402

from mpgspec.compile.guards import Guards  # noqa: E402
from mpgspec.oracle import SafetyOracle  # noqa: E402
from mpgspec.oracle.judged import GUARDED_FLAGS  # noqa: E402

HEADING = "## Guards: stepping piece by piece"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", choices=("pendulum", "a1"), default="pendulum")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    prims, base = example(args.project)
    errors = (base.error,) if args.project == "a1" else ("local", "doubling")  # the A1: the project's own
    pts = own_grid_points(prims)
    plain = {n: dataclasses.replace(p, guards=Guards(), cache={}) for n, p in prims.items()}
    n_calls = sum(len(v[1]) for v in pts.values())
    rows = [("oracle calls per round (Algorithm 1's grids)", f"{n_calls}"),
            ("primitives with guards", ", ".join(f"{n} ({len(p.guards)})" for n, p in prims.items()))]
    for error in errors:
        s = base.replace(error=error)
        kinds = [("guarded", prims, s), ("plain", plain, s)]
        if args.project == "pendulum":  # its guarded chunks are compiled at GUARDED_FLAGS: the unguarded ones so too
            plain_o1 = {n: dataclasses.replace(p, guards=Guards(), cache={}) for n, p in prims.items()}
            kinds.append(("plain_O1", plain_o1, s.replace(jit_flags=GUARDED_FLAGS)))
        oracles = {kind: {b: SafetyOracle(src[b], st) for b in pts} for kind, src, st in kinds}
        verdicts, per = {}, {kind: {b: [] for b in pts} for kind in oracles}

        def run(kind, oracles=oracles, verdicts=verdicts, per=per):
            out = []
            for b, (x0s, t0s) in pts.items():
                t0 = time.perf_counter()
                out += [e.status for e in oracles[kind][b].evaluate(x0s, t0s)]
                per[kind][b].append(time.perf_counter() - t0)
            verdicts[kind] = out

        for kind in oracles:  # compile and warm up outside the timed rounds
            run(kind)
        times = common.rounds({k: (lambda k=k: run(k)) for k in oracles}, args.repeats)
        r = common.med_ratio(times["guarded"], times["plain"])
        med = {k: float(np.median(v)) for k, v in times.items()}
        count = {k: {st: v.count(st) for st in ("safe", "unsafe", "inconclusive")} for k, v in verdicts.items()}
        differ = sum(a != b for a, b in zip(verdicts["guarded"], verdicts["plain"]))
        rows += [(f"**{error}: guarded / unguarded oracle time** (target <= 1.3x)",
                  f"**{r:.2f}x** ({med['guarded'] * 1e3:.0f} ms vs {med['plain'] * 1e3:.0f} ms per round)"),
                 (f"{error}: verdicts safe / unsafe / inconclusive, guarded; unguarded",
                  f"{count['guarded']['safe']} / {count['guarded']['unsafe']} / {count['guarded']['inconclusive']}; "
                  f"{count['plain']['safe']} / {count['plain']['unsafe']} / {count['plain']['inconclusive']}; "
                  f"{differ} differ"),
                 *([(f"{error}: guarded / unguarded, both at gcc {' '.join(GUARDED_FLAGS)}",
                     f"{common.med_ratio(times['guarded'], times['plain_O1']):.2f}x "
                     f"({med['plain_O1'] * 1e3:.0f} ms per round unguarded; verdicts differ from -O0's: "
                     f"{sum(a != b for a, b in zip(verdicts['plain_O1'], verdicts['plain']))})")]
                   if "plain_O1" in times else []),
                 (f"{error}: guarded / unguarded by target (median of its rounds)",
                  ", ".join(f"{b} {np.median(per['guarded'][b][1:]) / np.median(per['plain'][b][1:]):.2f}x"
                            for b in pts))]
    common.publish_rows(HEADING + ("" if args.project == "pendulum" else " (A1)"), "bench_pieces.py", args.repeats, t_all,
                        rows, not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
