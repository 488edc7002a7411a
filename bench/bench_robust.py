"""Benchmark of the A1's robust checks: a robust rollout's step against the nominal oracle's step,
the batching of scenarios, and the goal sequence's runs under sampled uncertainty.

    python bench/bench_robust.py            # about 4 minutes on 2 cores with a warm compile cache
    python bench/bench_robust.py --quick    # 3 rounds
    options: --repeats R, --no-write

Everything runs in one process on specs/a1 with the project's settings (dt 1 ms). Measured, in
interleaved rounds (a row is the median over rounds, a ratio the median of per-round ratios):

  oracle   SafetyOracle(B)(x_A*(t_A), t_B) of one nominal cell (step doubling, error bookkeeping);
  robust   RigidRobustRollout(B).run of the same cell at the nominal scenario (plant with k = 1,
           mu = 0.6, no push; h at both ends of each step), per step;
  batch    the cell's 27 scenarios of specs/a1 (4 corners, centre, 4 samples, each with the push at
           0, +bound, -bound) in one call, per rollout-step;
for Stand -> Walk(in_place) (a trot under a contact schedule) and Jump -> Land (contact events).
And the sequence Stand, Jump at 0.05 s, Land, 1.5 s, run naive under seeded draws of the project's
uncertainty with 1 and with 8 runs advancing together (one mapped step per active primitive), per run.

Prints a table and replaces (or appends) the section "A1 robust checks" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)
from common import markdown_table, med_ratio, rounds, stamp, write_section  # noqa: E402

from mpgspec.api import compile_stage, settings_for  # noqa: E402
from mpgspec.oracle.oracle import SafetyOracle  # noqa: E402
from mpgspec.robust.scenarios import scenarios  # noqa: E402
from mpgspec.robust.rigid import RigidRobustRollout  # noqa: E402
from mpgspec.robust.sequence import DisturbedSequences, steppers  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from mpgspec.spec.project import Sequence  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## A1 robust checks"
CELLS = {"Stand -> Walk(in_place)": ("Stand", "Walk(in_place)", 0.0, 0.0), "Jump -> Land": ("Jump", "Land", 0.25, 0.0)}


def log(msg: str) -> None:
    print(msg, flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 rounds")
    ap.add_argument("--repeats", type=int, default=None, help="measurement rounds (default 5, quick 3)")
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    R = args.repeats or (3 if args.quick else 5)
    T0 = time.perf_counter()
    mach = common.machine(casadi=ca.__version__, numpy=np.__version__, revision=common.revision(ROOT))
    spec = load_project(SPEC)
    st = settings_for(spec)
    prims = compile_stage(spec, st).prims  # with E sized by the project's verifiers (the walks' Floquet tubes)
    unc = spec.project.uncertainty
    sys_ = next(iter(prims.values())).system
    TH, ERR, SG, _ = scenarios(unc, sys_, np.random.default_rng(unc.seed), {"mass_scale": 1.0, "friction": 0.6})
    bound = np.asarray(unc.disturbance.force.bound, float)
    K = unc.disturbance.segments
    D = (SG[:, None, None] * bound[None, :, None]) * np.ones((1, 3, K))
    fns, facts = {}, {}
    for label, (a, b, t_A, t_B) in CELLS.items():
        B, x0 = prims[b], prims[a].x_star(t_A)
        t = time.perf_counter()
        rr = RigidRobustRollout(B, list(unc.parameters), "trunk", True, K, st, st.horizon, unc.disturbance.force.duration)
        build = time.perf_counter() - t
        oracle = SafetyOracle(B, st)
        ev = oracle(x0, t_B)
        one = (x0[None], np.array([t_B]), np.array([[1.0, 0.6]]), np.zeros((1, 3, K)))
        Y, last = rr.run(*one, None, st.h_tolerance)
        S = len(TH)
        many = (np.repeat(x0[None], S, 0) + ERR, np.full(S, t_B), TH, D)
        _, last_m = rr.run(*many, None, st.h_tolerance)
        facts[label] = {"oracle_steps": ev.steps, "verdict": ev.verdict, "robust_steps": int(last[0]),
                        "batch_steps": int(last_m.sum()), "S": S, "build": build}
        log(f"{label}: oracle {ev.status} in {ev.steps} steps; robust nominal {int(last[0])} steps; "
            f"{S} scenarios {int(last_m.sum())} rollout-steps; robust build {build:.1f} s")
        fns[f"oracle {label}"] = lambda o=oracle, x0=x0, tb=t_B: o(x0, tb)
        fns[f"robust {label}"] = lambda r=rr, a=one: r.run(*a, None, st.h_tolerance)
        fns[f"batch {label}"] = lambda r=rr, a=many: r.run(*a, None, st.h_tolerance)
    seq = Sequence(start="Stand", duration=1.5, commands=[{"t": 0.05, "goal": "Jump"}])
    small = dataclasses.replace(spec, project=spec.project.model_copy(update={"sequence": seq}))
    ds = {}
    for n in (1, 8):
        t = time.perf_counter()
        f, names, nd, bnd = steppers(small, prims, st)
        ds[n] = DisturbedSequences(prims, f, names, nd, bnd, unc, st, seq, n, unc.seed)
        log(f"sequence steppers for {n} runs: {time.perf_counter() - t:.1f} s")
        fns[f"sequence {n}"] = lambda d=ds[n]: d.run(None, {}, "naive")
    times = rounds(fns, R)
    med = statistics.median
    rows = []
    for label, f in facts.items():
        per_o = [v / f["oracle_steps"] for v in times[f"oracle {label}"]]
        per_r = [v / max(1, f["robust_steps"]) for v in times[f"robust {label}"]]
        per_b = [v / max(1, f["batch_steps"]) for v in times[f"batch {label}"]]
        rows += [(f"{label}: oracle call ({f['oracle_steps']} steps, verdict {f['verdict']})",
                  f"{med(times[f'oracle {label}']) * 1e3:,.1f} ms, {med(per_o) * 1e6:,.1f} us/step"),
                 (f"{label}: robust rollout, nominal scenario ({f['robust_steps']} steps)",
                  f"{med(times[f'robust {label}']) * 1e3:,.1f} ms, {med(per_r) * 1e6:,.1f} us/step"),
                 (f"{label}: {f['S']} scenarios in one call ({f['batch_steps']} rollout-steps)",
                  f"{med(times[f'batch {label}']) * 1e3:,.1f} ms, {med(per_b) * 1e6:,.1f} us/rollout-step"),
                 (f"**{label}: robust step / oracle step**", f"**{med_ratio(per_r, per_o):.2f}x**"),
                 (f"{label}: batched rollout-step / single robust step", f"{med_ratio(per_b, per_r):.2f}x")]
    per1 = times["sequence 1"]
    per8 = [v / 8 for v in times["sequence 8"]]
    rows += [("sequence Stand, Jump, Land (1.5 s), naive: 1 run", f"{med(per1) * 1e3:,.1f} ms"),
             ("same, 8 runs together", f"{med(times['sequence 8']) * 1e3:,.1f} ms, {med(per8) * 1e3:,.1f} ms per run"),
             ("**per run, 8 together / 1 alone**", f"**{med_ratio(per8, per1):.2f}x**")]
    table = markdown_table(rows)
    head = (stamp(mach, "bench_robust.py", args.quick, R, time.perf_counter() - T0) + f" specs/a1, dt={st.dt:g}, "
            "the project's compile cache (warm unless stated by the build times in the log).")
    section = f"{HEADING}\n\n{head}\n\n{table}\n\nSee the docstring of bench/bench_robust.py for the meaning of each row.\n"
    log("\n" + section)
    if not args.no_write:
        out = ROOT / "bench" / "RESULTS.md"
        write_section(out, HEADING, section)
        log(f"wrote the '{HEADING[3:]}' section of {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
