"""What replaying Stand's ID-QP as the oracle runs it costs: the cross-check's sampled law (solved at
its rate from the previous solve's warm start, compiled in the loop library, held) against the
continuous law (a cold solve at every control update, in CasADi's virtual machine).

    python bench/bench_held_law.py [--repeats 3] [--no-write]

In one process, on specs/a1 with Lie and Stand (the run Stand, Lie at 1 s, Stand at 4 s; 6.5 s of
MuJoCo at 1 kHz): both replays of the same run, interleaved rounds. Prints the median ratio of the
replay times, the ID-QP solves that did not converge in each (the continuous law's cold solves are
counted by solving its QPs again in the virtual machine), and the
largest difference of the replayed states; writes the table to bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPGSPEC_CACHE", tempfile.mkdtemp(prefix="mpgspec-bench-"))

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)

from mpgspec.api import compile_project, settings_for  # noqa: E402
from mpgspec.execute.crosscheck import CrossCheckSettings  # noqa: E402
from mpgspec.execute.crosscheck import replay as rp  # noqa: E402
from mpgspec.execute.crosscheck.mjcf import build_robot  # noqa: E402
from mpgspec.execute.sequence import simulate_sequence  # noqa: E402
from mpgspec.oracle import looplib  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from mpgspec.spec.models import GoalCommand, Sequence  # noqa: E402

HEADING = "## Cross-check: Stand's ID-QP replayed as sampled"


def heading(table2: bool, mode: str) -> str:
    return HEADING + (f" (Table II, {mode} run)" if table2 else "")


def _lie_stand(folder: Path) -> Path:
    dst = folder / "a1"
    shutil.copytree(ROOT / "specs" / "a1", dst, ignore=shutil.ignore_patterns("gaits*", "walks.yaml"))
    common.pd_lie(dst)  # the run the tests replay: Lie under the paper's joint PD, Stand's ID-QP the held law
    doc = yaml.safe_load((dst / "project.yaml").read_text())
    doc["primitives"] = ["primitives/lie.yaml", "primitives/stand.yaml"]
    for k in ("assertions", "sequence", "crosscheck", "uncertainty"):
        doc.pop(k, None)
    (dst / "project.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst / "project.yaml"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--table2", type=Path, default=None, metavar="REPORT",
                    help="replay instead a run of Table II from this specs/a1 report.json (22 s)")
    ap.add_argument("--mode", choices=("graph", "naive"), default="graph", help="which run of Table II")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    if args.table2 is None:
        spec = load_project(_lie_stand(Path(tempfile.mkdtemp())))
        prims = compile_project(spec)
        settings = settings_for(spec)
        seq = Sequence(start="Stand", duration=6.5, commands=[GoalCommand(t=1, goal="Lie"), GoalCommand(t=4, goal="Stand")])
        switches, duration = simulate_sequence(prims, None, None, seq, settings, "naive").switches, seq.duration
        what = "Stand, Lie at 1 s, Stand at 4 s: 6.5 s of MuJoCo, control at 1 kHz"
    else:
        spec = load_project(ROOT / "specs" / "a1" / "project.yaml")
        prims = compile_project(spec)
        settings = settings_for(spec)
        rep = json.loads(args.table2.read_text())
        switches, duration = rep["sequence"]["runs"][args.mode]["switches"], float(rep["sequence"]["duration"])
        what = f"specs/a1, Table II's {args.mode} run from the report: {duration:g} s of MuJoCo, control at 1 kHz"
    xs = CrossCheckSettings()
    robot = build_robot(prims["Lie"].system, xs)
    stand = prims["Stand"]
    looplib.held_law(stand)  # compile (or load) the library outside the timed rounds
    held = stand.cache["looplib_held"]
    qp = stand.sampled.solve.find_function("idqp")
    data = stand.sampled.solve.find_function("idqp_data")
    nu, nw = stand.system.nu, qp.sparsity_in("h").shape[0]
    lbx, ubx = np.full(nw, -np.inf), np.full(nw, np.inf)
    lbx[:nu], ubx[:nu] = stand.system.u_lo, stand.system.u_hi
    lbx[nu + 2::3] = 0.0
    out, cold_fail = {}, {"n": 0, "calls": 0}

    def continuous():
        stand.cache.pop("looplib_held", None)
        orig = looplib.held_law
        looplib.held_law = lambda p: None if p is stand else orig(p)
        try:
            out["continuous"] = rp.replay(robot, prims, switches, duration, xs, settings.h_tolerance)
        finally:
            looplib.held_law = orig
            stand.cache["looplib_held"] = held

    def sampled():
        out["sampled"] = rp.replay(robot, prims, switches, duration, xs, settings.h_tolerance)

    times = common.rounds({"sampled": sampled, "continuous": continuous}, args.repeats)
    r = common.med_ratio(times["continuous"], times["sampled"])
    a, b = out["sampled"], out["continuous"]
    rate = xs.control_rate
    for k, (x, t) in enumerate(zip(b.x, b.t)):  # the continuous law's QPs again, with the solver's status
        sw = [q for q in b.switches if q["t"] <= t + 0.5 / rate][-1]
        if sw["to"] != "Stand" or not np.isfinite(x).all():
            continue
        s_ = t - sw["t"]
        H, g, A, lba, uba, _w, ok = data(x, sw["clock"] + s_, s_, b.x[int(round(sw["t"] * rate))])
        if float(ok) < 0.5:
            qp(h=H, g=g, a=A, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
            cold_fail["n"] += not qp.stats()["success"]
        cold_fail["calls"] += 1
    dx = np.nanmax(np.abs(a.x - b.x))
    rows = [("run replayed", what),
            ("**continuous (cold, VM) / sampled (warm, compiled) replay time**",
             f"**{r:.2f}x** ({np.median(times['continuous']):.1f} s vs {np.median(times['sampled']):.1f} s)"),
            ("sampled: solves that did not converge", f"{sum(a.law_failures.values())}"),
            ("continuous: Stand's cold solves that stop unconverged (its QPs solved again in the VM)",
             f"{cold_fail['n']} of {cold_fail['calls']}"),
            ("verdicts in MuJoCo, sampled; continuous", f"{'safe' if a.safe else 'unsafe'}; {'safe' if b.safe else 'unsafe'}"),
            ("largest state difference between the two replays", f"{dx:.3g}")]
    mach = common.machine(casadi=ca.__version__, revision=common.revision(ROOT))
    common.publish(heading(args.table2 is not None, args.mode), mach, "bench_held_law.py" + (f" --table2 {args.table2} --mode {args.mode}" if args.table2 else ""), args.repeats, time.perf_counter() - t_all,
                   common.markdown_table(rows), not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
