"""Benchmark of the robot library: one A1 target's robust rollout with the robot's dynamics inlined in
every robust function (each target and each sequence stepper compiling its own copy) against the
robot library and the target's shared step library, in one process.

    python bench/bench_library.py                        # Walk(slow), about 8 minutes on 2 shared cores
    python bench/bench_library.py --target Jump --no-write

Each side builds the target's RigidRobustRollout (first sample, 100-step chunk, push gradient) in a
fresh private compile cache: C bytes and gcc wall seconds from the compile log, gcc CPU seconds
(the children's rusage), then runs the same scenarios (rollouts to their horizon and one gradient
call), interleaved rounds, median run time. The outputs of both sides are compared (they are the
same expressions, so equal). The library side's gcc includes the robot library, which the other
targets and every sequence stepper then reuse: the per-target figures are the ones to scale.

Prints a table and replaces (or appends) the section "A1 robot library" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
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
from mpgspec.pipeline.stages import compile_project  # noqa: E402
from mpgspec.robust import library, rigid  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## A1 robot library"
NAMES = ["mass_scale", "friction"]


def build(prim, settings, inline: bool) -> tuple[rigid.RigidRobustRollout, dict]:
    """The target's robust rollout built in a fresh cache; its compile figures."""
    cache, log = tempfile.mkdtemp(prefix="mpgspec-lib-"), tempfile.mktemp(suffix=".jsonl")
    os.environ["MPGSPEC_CACHE"], os.environ["MPGSPEC_JIT_LOG"] = cache, log
    library._BUILT.clear()
    real = rigid.library_for
    if inline:
        rigid.library_for = lambda p, s: None
    try:
        c0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        rr = rigid.RigidRobustRollout(prim, NAMES, "trunk", True, 4, settings, 1.0, 0.2)
        wall, c1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    finally:
        rigid.library_for = real
    recs = [json.loads(line) for line in open(log)]
    return rr, {"libraries": len(recs), "c_bytes": sum(r["c_bytes"] for r in recs),
                "robot_lib_gcc_s": sum(r["gcc_s"] for r in recs if r["name"].startswith("robot_")),
                "gcc_cpu_s": (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime), "build_s": wall,
                "robot_lib_bytes": sum(r["c_bytes"] for r in recs if r["name"].startswith("robot_"))}


def scenarios(prim, rr, n: int, rng) -> tuple:
    x0 = np.asarray(prim.x_star(0.0), float).ravel()
    X0 = np.tile(x0, (n, 1))
    TH = np.column_stack([rng.uniform(0.9, 1.1, n), rng.uniform(0.4, 0.8, n)])
    D = rng.uniform(-7.5, 7.5, (n, 3, rr.K)) * np.array([1, 1, 0])[None, :, None]
    return X0, np.zeros(n), TH, D


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", default="Walk(slow)")
    ap.add_argument("--rollouts", type=int, default=32)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t_start = time.perf_counter()
    spec = load_project(SPEC)
    prims = compile_project(spec)
    settings, prim = settings_for(spec), prims[a.target]
    sides = {}
    for name, inline in (("inline", True), ("library", False)):
        print(f"building {a.target} ({name}) ...", flush=True)
        sides[name] = build(prim, settings, inline)
    rng = np.random.default_rng(0)
    args = scenarios(prim, sides["inline"][0], a.rollouts, rng)
    steps = min(200, sides["inline"][0].N)
    limit = np.full(a.rollouts, steps)
    grad_args = (*args, [0] * a.rollouts, [steps] * a.rollouts)
    run = dict(tol=1e9, until_entry=False)  # every rollout runs its steps: h decides none
    outs = {k: rr.run(*args, limit, **run)[0] for k, (rr, _) in sides.items()}
    same = np.array_equal(outs["inline"], outs["library"], equal_nan=True)
    timed = {f"run {k}": (lambda rr=rr: rr.run(*args, limit, **run)) for k, (rr, _) in sides.items()}
    if sides["inline"][0].grad is not None:
        timed.update({f"grad {k}": (lambda rr=rr: rr.gradients(*grad_args)) for k, (rr, _) in sides.items()})
        g = {k: rr.gradients(*grad_args) for k, (rr, _) in sides.items()}
        gdiff = float(np.abs(g["inline"] - g["library"]).max())
    t = {k: statistics.median(v) for k, v in rounds(timed, a.repeats).items()}
    i, lib = sides["inline"][1], sides["library"][1]
    rows = [("C bytes compiled for the target", f"{i['c_bytes'] / 1e6:.2f} MB",
             f"{lib['c_bytes'] / 1e6:.2f} MB (of which the robot library {lib['robot_lib_bytes'] / 1e6:.2f} MB, once "
             f"per robot); without it {(lib['c_bytes'] - lib['robot_lib_bytes']) / i['c_bytes']:.2f}x"),
            ("gcc CPU seconds", f"{i['gcc_cpu_s']:.1f} s",
             f"{lib['gcc_cpu_s']:.1f} s, the robot library's {lib['robot_lib_gcc_s']:.1f} s (wall) included"),
            ("libraries", str(i["libraries"]), str(lib["libraries"])),
            (f"{a.rollouts} rollouts x {steps} steps", f"{t['run inline'] * 1e3:.0f} ms",
             f"{t['run library'] * 1e3:.0f} ms, **{t['run inline'] / t['run library']:.2f}x** faster; samples equal: {same}")]
    if "grad inline" in t:
        rows.append((f"push gradient, {a.rollouts} rollouts", f"{t['grad inline'] * 1e3:.0f} ms",
                     f"{t['grad library'] * 1e3:.0f} ms, **{t['grad inline'] / t['grad library']:.2f}x**; "
                     f"largest difference {gdiff:.1e}"))
    table = markdown_table([(m, f"inline {x}; library {y}") for m, x, y in rows])
    mach = common.machine(casadi=ca.__version__, revision=common.revision(ROOT))
    common.publish(HEADING, mach, f"bench_library.py --target '{a.target}'", a.repeats, time.perf_counter() - t_start,
                   table, not a.no_write)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
