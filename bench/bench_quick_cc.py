"""What building unoptimised code with tcc costs at run time and saves at compile time.

    python bench/bench_quick_cc.py [--project pendulum|a1] [--repeats 7] [--no-write]

In one process, on an example project, every oracle call of Algorithm 1 (each source's setpoint on
its t_A grid, every target on its t_B grid) is made once per round through two copies of the
primitives: one whose chunks were built as `mpgspec verify` builds them with tcc installed
(oracle.jit.QUICK_CC: -O0 code to tcc; a small guarded loop's judged chunk keeps the project's
flags), one as without it (everything to gcc; such a chunk at judged.GUARDED_FLAGS). Prints the
compilers' CPU seconds for each copy's chunks (rusage of the child processes), the median per-round
ratio of oracle time tcc / gcc, and whether every verdict and margin is the same float. A robot's
loop libraries are compiled at their own flags by gcc either way (built once, before both copies).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import resource
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

from mpgspec.oracle import SafetyOracle, jit  # noqa: E402
from mpgspec.oracle.looplib import attach  # noqa: E402

HEADING = "## Quick compiler: tcc for unoptimised code"


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _set_quick(value: str | None) -> None:
    """MPGSPEC_QUICK_CC set to value, or unset for None (the default, tcc)."""
    if value is None:
        os.environ.pop("MPGSPEC_QUICK_CC", None)
    else:
        os.environ["MPGSPEC_QUICK_CC"] = value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", choices=("pendulum", "a1"), default="pendulum")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    if jit.quick_compiler() is None:
        print("no tcc on this machine (apt-get install tcc): nothing to compare", file=sys.stderr)
        return 2
    t_all = time.perf_counter()
    prims, settings = example(args.project)
    for p in prims.values():
        attach(p)  # the loop libraries (gcc, their own flags), shared by both copies
    os.environ["MPGSPEC_CACHE"] = tempfile.mkdtemp(prefix="mpgspec-bench-")  # no chunk built while sizing E is reused
    pts = own_grid_points(prims)
    n_calls = sum(len(v[1]) for v in pts.values())
    quick = os.environ.get("MPGSPEC_QUICK_CC")
    oracles, build_cpu, evidence = {}, {}, {}
    for kind, env in (("tcc", quick), ("gcc", "")):
        _set_quick(env)
        # nothing compiled before but the loop libraries (looplib* entries), so each copy builds its own chunks
        own = {n: dataclasses.replace(p, cache={k: v for k, v in p.cache.items() if str(k).startswith("looplib")})
               for n, p in prims.items()}
        c0 = _children_cpu()
        oracles[kind] = {b: SafetyOracle(own[b], settings) for b in pts}
        evidence[kind] = [e for b, (x0s, t0s) in pts.items() for e in oracles[kind][b].evaluate(x0s, t0s)]
        build_cpu[kind] = _children_cpu() - c0
    _set_quick(quick)

    def run(kind):
        for b, (x0s, t0s) in pts.items():
            oracles[kind][b].evaluate(x0s, t0s)

    times = common.rounds({k: (lambda k=k: run(k)) for k in oracles}, args.repeats)
    same = all(a.status == b.status and a.margin == b.margin for a, b in zip(evidence["tcc"], evidence["gcc"]))
    med = {k: float(np.median(v)) for k, v in times.items()}
    rows = [("oracle calls per round (Algorithm 1's grids)", f"{n_calls}"),
            ("compiler CPU seconds for the chunks, tcc; gcc", f"{build_cpu['tcc']:.1f} s; {build_cpu['gcc']:.1f} s "
             f"({build_cpu['gcc'] / max(build_cpu['tcc'], 1e-9):.0f}x)"),
            ("**oracle time, tcc's chunks / gcc's**", f"**{common.med_ratio(times['tcc'], times['gcc']):.2f}x** "
             f"({med['tcc'] * 1e3:.0f} ms vs {med['gcc'] * 1e3:.0f} ms per round)"),
            ("every verdict and margin the same float", "yes" if same else "**no**")]
    common.publish_rows(HEADING + ("" if args.project == "pendulum" else " (A1)"), "bench_quick_cc.py", args.repeats,
                        t_all, rows, not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
