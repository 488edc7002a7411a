"""Benchmark of the loop library (mpgspec/oracle/looplib.py): A1 primitives' oracle (judged) chunk and
trace chunk with the closed loop and jump inlined in each against both calling one compiled loop
library, and the cross-check's law in CasADi's virtual machine against the library (per call, and
one second of a MuJoCo replay of the first primitive), in one process.

    python bench/bench_looplib.py                               # Walk(slow) and Stand, a few minutes
    python bench/bench_looplib.py --prims 'Walk(slow)' Jump --no-write

Each side builds its chunks in a fresh private compile cache: C bytes from the compile log, gcc CPU
seconds from the children's rusage (the library side includes the library, which every later
chunk, the gait's period map and the cross-check reuse). Run times are medians over interleaved
rounds; the outputs of both sides are compared bit for bit.

Prints a table and replaces (or appends) the section "A1 loop library" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import dataclasses
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
from mpgspec.execute.crosscheck import CrossCheckSettings  # noqa: E402
from mpgspec.execute.crosscheck.mjcf import build_robot  # noqa: E402
from mpgspec.execute.crosscheck.replay import replay  # noqa: E402
from mpgspec.oracle import looplib  # noqa: E402
from mpgspec.oracle.integrator import build_chunk, start_states  # noqa: E402
from mpgspec.oracle.judged import build_judged_chunk  # noqa: E402
from mpgspec.pipeline.stages import compile_project  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## A1 loop library"
K = 16


def build(prim, settings, inline: bool) -> tuple:
    """(a copy of prim with its judged and trace chunks built in a fresh cache, compile figures)."""
    cache, log = tempfile.mkdtemp(prefix="mpgspec-ll-"), tempfile.mktemp(suffix=".jsonl")
    os.environ["MPGSPEC_CACHE"], os.environ["MPGSPEC_JIT_LOG"] = cache, log
    p = dataclasses.replace(prim, cache={"looplib": None} if inline else {})
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if not inline:
        looplib.attach(p)
    judged = build_judged_chunk(p, settings.dt, K, settings.chunk, settings.h_tolerance, 1.0)
    build_chunk(p, settings.dt, 64, with_state=True, boundaries=False)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    recs = [json.loads(line) for line in open(log)]
    return p, judged, {"c_bytes": sum(r["c_bytes"] for r in recs),
                       "lib_bytes": sum(r["c_bytes"] for r in recs if r["name"].startswith(("loop_", "margin_"))),
                       "gcc_cpu_s": (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)}


def starts(prim, settings, judged, n: int) -> np.ndarray:
    t0s = np.linspace(0.0, float(prim.period or 0.0), n, endpoint=False)
    X = np.array([prim.x_star(t) for t in t0s])
    return np.vstack([start_states(prim, X, t0s), judged.lay.start(np.full(n, settings.horizon))])


def compare(name: str, prim, settings, n: int, repeats: int) -> list[tuple[str, str]]:
    """The rows of one primitive."""
    sides = {k: build(prim, settings, k == "inline") for k in ("inline", "library")}
    Z = starts(prim, settings, sides["inline"][1], n)
    outs = {k: judged.run(Z.copy()).copy() for k, (_p, judged, _f) in sides.items()}
    same = np.array_equal(outs["inline"], outs["library"], equal_nan=True)
    timed = {k: (lambda j=judged: j.run(Z.copy())) for k, (_p, judged, _f) in sides.items()}
    law, lib_p = None, sides["library"][0]
    if looplib.law(lib_p) is not None:
        x, xs = prim.x_star(0.1), prim.x_star(0.0)
        law = looplib.law(lib_p)
        timed["vm"] = lambda: [lib_p.loop(x, 0.1, 0.1, xs) for _ in range(100)]
        timed["law"] = lambda: [law(x, 0.1, 0.1, xs) for _ in range(100)]
    t = {k: statistics.median(v) for k, v in rounds(timed, repeats).items()}
    i, lib = sides["inline"][2], sides["library"][2]
    rows = [(f"{name}: C bytes (judged + trace chunk)", f"inline {i['c_bytes'] / 1e6:.2f} MB; library "
             f"{lib['c_bytes'] / 1e6:.2f} MB (of which the loop library {lib['lib_bytes'] / 1e6:.2f} MB), "
             f"**{i['c_bytes'] / lib['c_bytes']:.2f}x** less"),
            (f"{name}: gcc CPU seconds", f"inline {i['gcc_cpu_s']:.1f} s; library {lib['gcc_cpu_s']:.1f} s, "
             f"**{i['gcc_cpu_s'] / max(lib['gcc_cpu_s'], 1e-9):.2f}x** less"),
            (f"{name}: judged chunk, {n} rollouts x {K} steps", f"inline {t['inline'] * 1e3:.1f} ms; library "
             f"{t['library'] * 1e3:.1f} ms ({t['inline'] / t['library']:.2f}x); outputs bit-identical: {same}")]
    if law is not None:
        rows.append((f"{name}: cross-check law, 100 calls", f"virtual machine {t['vm'] * 1e3:.1f} ms; library "
                     f"{t['law'] * 1e3:.1f} ms, **{t['vm'] / t['law']:.1f}x** faster"))
    return rows, same


def replay_rows(prims: dict, name: str, duration: float, repeats: int) -> tuple[list, bool]:
    """One replay in MuJoCo of `name` from x*(0) for `duration` s: its law in CasADi's virtual machine
    (no library attached) against the loop library; the replays' states must be equal."""
    xs = CrossCheckSettings()
    robot = build_robot(prims[name].system, xs)
    sides = {"vm": dataclasses.replace(prims[name], cache={"looplib": None}),
             "library": dataclasses.replace(prims[name], cache={})}
    looplib.attach(sides["library"])
    switches = [{"t": 0.0, "to": name, "clock": 0.0}]
    runs = {k: replay(robot, {name: p}, switches, duration, xs) for k, p in sides.items()}
    same = np.array_equal(runs["vm"].x, runs["library"].x, equal_nan=True)
    t = {k: statistics.median(v) for k, v in rounds(
        {k: (lambda p=p: replay(robot, {name: p}, switches, duration, xs)) for k, p in sides.items()}, repeats).items()}
    return [(f"{name}: cross-check replay, {duration:g} s", f"virtual machine {t['vm']:.2f} s; library "
             f"{t['library']:.2f} s, **{t['vm'] / t['library']:.2f}x** faster; states equal: {same}")], same


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prims", nargs="+", default=["Walk(slow)", "Stand"])
    ap.add_argument("--rollouts", type=int, default=32)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t_start = time.perf_counter()
    spec = load_project(SPEC)
    prims, settings = compile_project(spec), settings_for(spec)
    rows, ok = [], True
    for name in a.prims:
        print(f"building {name} ...", flush=True)
        r, same = compare(name, prims[name], settings, a.rollouts, a.repeats)
        rows += r
        ok = ok and same
    r, same = replay_rows(prims, a.prims[0], 1.0, a.repeats)
    rows += r
    ok = ok and same
    table = markdown_table(rows)
    mach = common.machine(casadi=ca.__version__, revision=common.revision(ROOT))
    common.publish(HEADING, mach, "bench_looplib.py --prims " + " ".join(f"'{p}'" for p in a.prims), a.repeats,
                   time.perf_counter() - t_start, table, not a.no_write)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
