"""Soundness of the validated oracle backend on about 1,050 generated cases with exact answers.

    python bench/bench_validated_soundness.py [--workers 2] [--scale 1.0] [--seed S] [--no-write]

The families and their exact answers are those of tests/validated/validated_campaign.py: the rk4
campaigns' generators (keep-out windows narrower than a step, thin keep-out slabs, grazing peaks
between samples, fast undershoots; laws switching on the clock or the state inside a step, pulses,
input saturation) plus grazing ties and a saturation kink followed by a tight margin. Every case
runs through `ValidatedRunner` with its default options, one start point per call, in `workers`
spawned processes (the slow families first). Prints per family: cases, truly safe, grazing truths,
certified safe, certified unsafe, inconclusive, false safe, false unsafe, errors and seconds (the
sum of the per-case wall times), then every false verdict in full and the inconclusive cases'
reasons, and writes the table to bench/RESULTS.md. `--scale` multiplies every family's count (at
least one case each). Exit code 1 when a verdict is false or a case raised.
"""
from __future__ import annotations

import argparse
import collections
import concurrent.futures
import multiprocessing
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "validated"))
os.environ.setdefault("MPGSPEC_CACHE", tempfile.mkdtemp(prefix="mpgspec-bench-"))

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)
import validated_campaign as vc  # noqa: E402  (tests/validated/validated_campaign.py)

HEADING = "## Validated oracle: soundness on generated cases"
SEED = 20261204
COUNTS = {"window": 150, "slab": 150, "graze": 150, "fast": 150, "graze_tie": 60, "satosc": 150, "clock": 100,
          "pulse": 100, "state": 16, "sat": 24}
COST = {"state": 60.0, "sat": 12.0}  # rough seconds per case, to hand the slow jobs out first (else 0.2)
REASONS = (("grew past", "enclosure blow-up"), ("may have entered E before", "h in doubt, E possibly entered"),
           ("entered E after it", "h in doubt, then E entered"), ("horizon passed", "E touched, never inside"),
           ("more than", "step budget"), ("no a-priori", "no a-priori enclosure"))


def _job(items: list) -> list:
    """Judge one job's cases in a worker process."""
    return vc.judge(items)


def reason(message: str) -> str:
    for key, name in REASONS:
        if key in message:
            return name
    return "other"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    load0 = " ".join(Path("/proc/loadavg").read_text().split()[:3]) if Path("/proc/loadavg").exists() else "?"
    counts = {f: max(1, round(n * args.scale)) for f, n in COUNTS.items()}
    items = vc.generate(counts, args.seed)
    t_ref = time.perf_counter() - t_all
    jobs = []
    for fam in vc.FAMILIES:
        mine = [it for it in items if it.family == fam]
        size = 1 if COST.get(fam, 0.2) > 5 else 10
        jobs += [mine[i:i + size] for i in range(0, len(mine), size)]
    jobs.sort(key=lambda j: -COST.get(j[0].family, 0.2) * len(j))
    done: list = []
    if args.workers <= 1:
        for j in jobs:
            done += _job(j)
    else:
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(args.workers, mp_context=ctx) as pool:
            futures = [pool.submit(_job, j) for j in jobs]
            for k, fut in enumerate(concurrent.futures.as_completed(futures), 1):
                done += fut.result()
                print(f"\r{k}/{len(jobs)} jobs, {time.perf_counter() - t_all:.0f} s", end="", file=sys.stderr)
            print(file=sys.stderr)
    done.sort(key=lambda it: vc.FAMILIES.index(it.family))
    wall = time.perf_counter() - t_all
    wrong = vc.false_verdicts(done)
    errors = [it for it in done if it.status not in ("safe", "unsafe", "inconclusive")]
    notes = [f"{len(done)} cases (seed {args.seed}); exact references {t_ref:.1f} s; grazing = exact least margin "
             f"within {vc.GRAZING:g} of 0; seconds = the sum of the per-case wall times in {args.workers} worker(s)."]
    for fam in vc.FAMILIES:
        why = collections.Counter(reason(it.message) for it in done if it.family == fam and it.status == "inconclusive")
        if why:
            notes.append(f"{fam} inconclusive: " + ", ".join(f"{n} {r}" for r, n in why.most_common()))
    notes.append(f"false verdicts: {len(wrong)}; errors: {len(errors)}")
    notes += [f"FALSE: {it.describe()}" for it in wrong]
    notes += [f"ERROR: {it.describe()}" for it in errors[:5]]
    import flint

    mach = common.machine(casadi=ca.__version__, revision=common.revision(ROOT))
    load1 = " ".join(Path("/proc/loadavg").read_text().split()[:3]) if Path("/proc/loadavg").exists() else "?"
    head = (f"{time.strftime('%Y-%m-%d %H:%M')}, {mach['revision']}; {mach['nproc']} CPU ({mach['cpu']}), Python "
            f"{mach['python']}, CasADi {mach['casadi']}, python-flint {flint.__version__}; load average {load0} "
            f"({load1} at the end); `python bench/bench_validated_soundness.py"
            f"{'' if args.scale == 1.0 else f' --scale {args.scale:g}'}` ({wall:.0f} s wall).")
    section = head + "\n\n" + vc.table(done) + "\n\n" + "\n".join(f"- {n}" for n in notes)
    print(section)
    if not args.no_write:
        common.write_section(ROOT / "bench" / "RESULTS.md", HEADING, HEADING + "\n\n" + section + "\n")
    return 1 if wrong or errors else 0


if __name__ == "__main__":
    sys.exit(main())
