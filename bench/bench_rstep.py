"""Benchmark of the robust step libraries calling the primitive's loop library: A1 targets' robust
rollouts with the sampled law's solve (and, without a gradient, a large RoA margin) compiled again into
each step library (inline) against calls into the loop library (called), in one process.

    python bench/bench_rstep.py                                  # Stand, about 2 minutes
    python bench/bench_rstep.py --targets Stand "Walk(slow)" --no-gradient --no-write

A walk's gradient step calls nothing (its RoA margin's unit has no reverse derivative): both sides are
the same library. Measured before choosing the parts (Walk(slow), push gradient): the trot law with
its reverse derivative as a loop-library unit of its own takes 2.9 CPU-s of gcc at -O1 and leaves a
step library of 0.62 MB (1.4 s, full -O1 below 1 MB) against 3.3 s for the 1.10 MB step with it
inlined (LARGE_CODE_FLAGS); at -O0 the unit takes 0.6 s but rollouts run 1.17x and gradients 1.32x
the time. Moving the margin's table out likewise brings the step under 1 MB: 5.5 s against 3.6 s.

The robot library and the loop libraries (built by the oracle before the robust stage) are compiled
first in a private cache and not counted. Then each side builds the target's RigidRobustRollout
(first sample, 100-step chunk, push gradient where taken) in a copy of that cache: C bytes of the step
library (rstep_*), gcc CPU seconds of everything the side compiled (the children's rusage), then runs the same scenarios (rollouts to their horizon and one
gradient call), interleaved rounds, median run time. The outputs of both sides must be equal.

Prints a table and replaces (or appends) the section "A1 robust step libraries" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import common  # noqa: E402  (bench/common.py)
from common import markdown_table, rounds  # noqa: E402

from mpgspec.api import settings_for  # noqa: E402
from mpgspec.oracle import looplib  # noqa: E402
from mpgspec.pipeline.stages import compile_project  # noqa: E402
from mpgspec.robust import rigid  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## A1 robust step libraries"
NAMES = ["mass_scale", "friction"]


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def build(prim, settings, base: str, inline: bool, gradient: bool) -> tuple[rigid.RigidRobustRollout, dict]:
    """The target's robust rollout built in a copy of the base cache; its compile figures."""
    cache, log = tempfile.mkdtemp(prefix="mpgspec-rstep-"), tempfile.mktemp(suffix=".jsonl")
    shutil.copytree(base, cache, dirs_exist_ok=True)
    os.environ["MPGSPEC_CACHE"], os.environ["MPGSPEC_JIT_LOG"] = cache, log
    real = rigid.loop_parts
    if inline:
        rigid.loop_parts = lambda p, lib, reverse: ({}, ())
    try:
        c0 = _cpu()
        rr = rigid.RigidRobustRollout(prim, NAMES, "trunk", True, 4, settings, 1.0, 0.2, gradient=gradient)
        cpu = _cpu() - c0
    finally:
        rigid.loop_parts = real
    recs = [json.loads(line) for line in open(log)] if os.path.exists(log) else []

    def size(prefix):
        return sum(r["c_bytes"] for r in recs if r["name"].startswith(prefix))
    return rr, {"rstep": size("rstep_"), "all": size(""), "gcc_cpu_s": cpu}


def scenarios(prim, rr, n: int, rng) -> tuple:
    x0 = np.asarray(prim.x_star(0.0), float).ravel()
    TH = np.column_stack([rng.uniform(0.9, 1.1, n), rng.uniform(0.4, 0.8, n)])
    D = rng.uniform(-7.5, 7.5, (n, 3, rr.K)) * np.array([1, 1, 0])[None, :, None]
    return np.tile(x0, (n, 1)), np.zeros(n), TH, D


def measure(prim, settings, base: str, n: int, repeats: int, gradient: bool) -> tuple[list[tuple[str, str]], bool]:
    """Rows of the table for one target; whether both sides' outputs are equal."""
    sides = {k: build(prim, settings, base, k == "inline", gradient) for k in ("inline", "called")}
    args = scenarios(prim, sides["inline"][0], n, np.random.default_rng(0))
    steps = min(200, sides["inline"][0].N)
    limit, run = np.full(n, steps), dict(tol=1e9, until_entry=False)  # every rollout runs its steps
    same = all(np.array_equal(a, b, equal_nan=True) for a, b in
               zip(*(rr.run(*args, limit, **run) for rr, _ in sides.values())))
    timed = {f"run {k}": (lambda rr=rr: rr.run(*args, limit, **run)) for k, (rr, _) in sides.items()}
    grad_args = (*args, [0] * n, [steps] * n)
    if sides["inline"][0].grad is not None:
        timed.update({f"grad {k}": (lambda rr=rr: rr.gradients(*grad_args)) for k, (rr, _) in sides.items()})
        same = same and np.array_equal(*(rr.gradients(*grad_args) for rr, _ in sides.values()))
    t = {k: statistics.median(v) for k, v in rounds(timed, repeats).items()}
    i, c = sides["inline"][1], sides["called"][1]
    rows = [("step library C bytes", f"{i['rstep'] / 1e6:.2f} MB", f"{c['rstep'] / 1e6:.2f} MB"),
            ("gcc CPU-s (step library, robust chunks)", f"{i['gcc_cpu_s']:.1f} s", f"{c['gcc_cpu_s']:.1f} s"),
            (f"{n} rollouts x {steps} steps", f"{t['run inline'] * 1e3:.0f} ms",
             f"{t['run called'] * 1e3:.0f} ms ({t['run called'] / t['run inline']:.2f}x the time)")]
    if "grad inline" in t:
        rows.append((f"push gradient, {n} rollouts", f"{t['grad inline'] * 1e3:.0f} ms",
                     f"{t['grad called'] * 1e3:.0f} ms ({t['grad called'] / t['grad inline']:.2f}x the time)"))
    rows.append(("outputs equal (bit for bit)", "", str(same)))
    return [(f"{prim.name}: {m}", f"inline {x}; called {y}" if x else y) for m, x, y in rows], same


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", nargs="+", default=["Stand"])
    ap.add_argument("--no-gradient", action="store_true", help="rollouts without a push gradient")
    ap.add_argument("--rollouts", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t_start = time.perf_counter()
    spec = load_project(SPEC)
    prims, settings = compile_project(spec), settings_for(spec)
    base = tempfile.mkdtemp(prefix="mpgspec-rstep-base-")
    os.environ["MPGSPEC_CACHE"] = base
    targets = [prims[name] for name in a.targets]
    looplib.build_all(targets)  # as the oracle stage does, not counted
    for p in targets:
        rigid.library_for(p, settings)
    rows, ok = [], True
    for p in targets:
        print(f"measuring {p.name} ...", flush=True)
        got, same = measure(p, settings, base, a.rollouts, a.repeats, not a.no_gradient)
        rows += got
        ok = ok and same
    mach = common.machine(casadi=ca.__version__, revision=common.revision(ROOT))
    cmd = "bench_rstep.py --targets " + " ".join(f"'{t}'" for t in a.targets) + " --no-gradient" * a.no_gradient
    common.publish(HEADING, mach, cmd, a.repeats, time.perf_counter() - t_start, markdown_table(rows), not a.no_write)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
