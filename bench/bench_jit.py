"""Benchmark of the A1's compile work: CasADi's common-subexpression elimination (cse) and gcc run
side by side, for one target primitive.

    python bench/bench_jit.py                      # Walk(slow): about 8 minutes on 2 shared cores
    python bench/bench_jit.py --target Stand --no-write

Everything runs in one process on specs/a1 (closed loops compiled, E not sized: the margin's
ellipsoid does not change the code's size). For the target's robust rollout (first sample, chunk of
100 steps, the chunk's adjoint the push gradient sweeps back through) and its oracle chunk (the project's chunk length and error
estimate; its large loop always has cse, the row tries cse on the MX graph around it too), and the period of its hybrid flow (the Floquet verifiers'), built with and without cse
(oracle/jit.CSE), each in a fresh private compile cache:
C bytes (from the MPGSPEC_JIT_LOG compile log) and gcc CPU seconds (one library at a time, with and
without cse interleaved: CPU time is less disturbed than wall time by other work), run time per call (median of
interleaved rounds) and the largest difference between the outputs on random inputs near the
primitive's setpoint. Then the robust first sample and chunk (two libraries of similar size), and
all three robust libraries, with cse, compiled one after the other (n_jobs=1) and side by side
(compile_many, one gcc per usable core), wall time: the largest library bounds the second.

Prints a table and replaces (or appends) the section "A1 compile work (cse, parallel gcc)" of
bench/RESULTS.md.
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

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)
from common import markdown_table, rounds, stamp, write_section  # noqa: E402

from mpgspec.api import settings_for  # noqa: E402
from mpgspec.certify.hybrid_orbit import HybridFlow  # noqa: E402
from mpgspec.check.assumptions import HYBRID_DT  # noqa: E402
from mpgspec.cores import usable_cores  # noqa: E402
from mpgspec.oracle import integrator, jit  # noqa: E402
from mpgspec.oracle.integrator import build_chunk, initial_state  # noqa: E402
from mpgspec.pipeline.stages import compile_project  # noqa: E402
from mpgspec.robust.rigid import RigidRobustRollout  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## A1 compile work (cse, parallel gcc)"
NOTE = ("See the docstring of bench/bench_jit.py for the meaning of each row. gcc run side by side gains only "
        "where cores are free: with the machine's load average above its core count (see above) the other work "
        "takes the second core; on a quiet 2-core machine two gcc at once took 5.9 s against 11.1 s one after "
        "the other (measured earlier on this machine). The oracle chunk's row tries cse on its MX graph too; the code "
        "keeps cse on small SX bodies only.")


def log(msg: str) -> None:
    print(msg, flush=True)


def functions(spec, prim, st, use_cse: bool) -> tuple[dict[str, ca.Function], RigidRobustRollout]:
    """The target's robust first/chunk/grad and its oracle chunk, uncompiled, with or without cse."""
    jit.CSE = use_cse
    try:
        unc = spec.project.uncertainty
        raw = dataclasses.replace(st, jit=False)
        rr = RigidRobustRollout(prim, list(unc.parameters), "trunk", True, unc.disturbance.segments, raw,
                                st.horizon, unc.disturbance.force.duration)
        prim.cache.clear()  # the oracle's chunk is remembered on the primitive
        integrator.cse_sx = jit.cse  # a trial: the chunk's MX body with cse too (the code: SX bodies only)
        ch = build_chunk(prim, st.dt, st.chunk, False, st.jit_flags, error=st.error)
        prim.cache.clear()
    finally:
        jit.CSE, integrator.cse_sx = True, jit.cse_sx
    fns = {"robust first": rr.first, "robust chunk": rr.chunk, "robust gradient": rr.grad, "oracle chunk": ch.fn}
    return {k: f for k, f in fns.items() if f is not None}, rr  # a held law (Stand): no gradient


def compile_logged(fns: list[ca.Function], flags, n_jobs: int) -> tuple[list[ca.Function], list[dict], float, float]:
    """fns compiled in a fresh private cache: the libraries, the compile log's lines, the wall time and
    the CPU seconds of the compiler processes (less sensitive than wall time to other work)."""
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MPGSPEC_CACHE"] = str(Path(tmp) / "cache")
        os.environ["MPGSPEC_JIT_LOG"] = str(Path(tmp) / "log.jsonl")
        r0, t = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        out = jit.compile_many(fns, flags, n_jobs=n_jobs)
        wall, r1 = time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN)
        recs = [json.loads(line) for line in Path(os.environ["MPGSPEC_JIT_LOG"]).read_text().splitlines()]
        # the libraries stay loaded after their files are gone
    return out, recs, wall, (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)


def inputs(fn: ca.Function, prim, rr, rng, n: int) -> list[list[np.ndarray]]:
    """n random argument lists near the setpoint: x0 perturbed by 1e-3, theta near (1, 0.6), the push
    within +-20 N, the weights in [0, 1]; the oracle chunk's z from initial_state."""
    x0 = np.asarray(prim.x_star(0.0), float).ravel()
    out = []
    for _ in range(n):
        x = x0 + 1e-3 * rng.standard_normal(x0.size)
        th = np.array([1.0, 0.6]) + 0.05 * rng.uniform(-1, 1, 2)
        if fn.name().endswith("_first"):
            args = [x, 0.0, 0.0, th, 20 * rng.uniform(-1, 1, (3, rr.K))]
        elif fn.name().endswith("_chunk"):
            z = np.concatenate([x, [0.0, 0.0], x, th, np.zeros(rr.nz - 2 * x.size - 4)])
            args = [z, 20 * rng.uniform(-1, 1, (3, rr.CHUNK))]
        elif fn.name().endswith("_grad"):  # a chunk's adjoint: (z, pushes, weights of z_L, weights of the outputs)
            z = np.concatenate([x, [0.0, 0.0], x, th, np.zeros(rr.nz - 2 * x.size - 4)])
            args = [z, 20 * rng.uniform(-1, 1, (3, rr.CHUNK)), rng.uniform(0, 1, fn.size1_in(2)),
                    rng.uniform(0, 1, (fn.size1_in(3), fn.size2_in(3)))]
        else:
            args = [np.concatenate([initial_state(prim, x, 0.0), np.zeros(fn.size1_in(0) - 2 * x.size - 2)])]
        out.append(args)
    return out


def max_diff(f: ca.Function, g: ca.Function, args: list) -> float:
    worst = 0.0
    for a in args:
        for y0, y1 in zip(f.call(a), g.call(a)):
            d = np.abs(np.asarray(y0) - np.asarray(y1))
            finite = np.isfinite(np.asarray(y0)) & np.isfinite(np.asarray(y1))
            if (np.isfinite(np.asarray(y0)) != np.isfinite(np.asarray(y1))).any():
                return float("inf")
            worst = max(worst, float(d[finite].max()) if finite.any() else 0.0)
    return worst


def hybrid_rows(prim, rng) -> list[tuple[str, str]]:
    """The period of the target's hybrid flow (Floquet verifiers), with and without cse."""
    if prim.period is None:
        return []
    flows, recs = {}, {}
    for c in (False, True):
        jit.CSE = c
        try:
            with tempfile.TemporaryDirectory() as tmp:
                os.environ["MPGSPEC_CACHE"] = str(Path(tmp) / "cache")
                os.environ["MPGSPEC_JIT_LOG"] = str(Path(tmp) / "log.jsonl")
                flows[c] = HybridFlow(prim, HYBRID_DT)
                recs[c] = json.loads(Path(os.environ["MPGSPEC_JIT_LOG"]).read_text().splitlines()[-1])
        finally:
            jit.CSE = True
    x0 = np.asarray(prim.x_star(0.0), float).ravel()
    diff = max(float(np.abs(flows[False].states(x) - flows[True].states(x)).max())
               for x in (x0 + 1e-3 * rng.standard_normal(x0.size) for _ in range(3)))
    r0, r1 = recs[False], recs[True]
    return [("hybrid period: C bytes without / with cse (ratio)",
             f"{r0['c_bytes'] / 1e6:.2f} / {r1['c_bytes'] / 1e6:.2f} MB ({r1['c_bytes'] / r0['c_bytes']:.2f})"),
            ("hybrid period: gcc s without / with cse (ratio)",
             f"{r0['gcc_s']:.1f} / {r1['gcc_s']:.1f} s ({r1['gcc_s'] / r0['gcc_s']:.2f})"),
            ("hybrid period: largest state difference with / without cse", f"{diff:.1e}")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--target", default="Walk(slow)")
    ap.add_argument("--repeats", type=int, default=21, help="rounds of the run-time measurement")
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    T0 = time.perf_counter()
    mach = common.machine(casadi=ca.__version__, numpy=np.__version__)
    mach["revision"] = common.revision(ROOT)
    spec = load_project(SPEC)
    st = settings_for(spec)
    prim = compile_project(spec)[args.target]
    log(f"compiled the closed loops ({time.perf_counter() - T0:.0f} s)")
    built = {c: functions(spec, prim, st, c) for c in (False, True)}
    rr = built[True][1]
    libs, recs = {False: {}, True: {}}, {False: {}, True: {}}
    for k in built[True][0]:  # one function at a time, with and without cse interleaved
        for c in (False, True):
            (lib,), (rec,), _, cpu = compile_logged([built[c][0][k]], st.jit_flags, n_jobs=1)
            libs[c][k], recs[c][k] = lib, {**rec, "cpu_s": cpu}
        log(f"{k}: " + ", ".join(f"cse={c} {recs[c][k]['c_bytes'] / 1e6:.2f} MB {recs[c][k]['cpu_s']:.1f} "
                                 f"gcc CPU s" for c in (False, True)))
    rng = np.random.default_rng(0)
    rows = []
    for k in built[True][0]:
        f0, f1 = libs[False][k], libs[True][k]
        args_k = inputs(f1, prim, rr, rng, 1 if k == "robust gradient" else 5)
        diff = max(max_diff(f0, f1, args_k), max_diff(built[False][0][k], libs[True][k], args_k[:1])
                   if k != "robust gradient" else 0.0)
        R = 1 if k == "robust gradient" else args.repeats
        t = rounds({"plain": lambda: f0.call(args_k[0]), "cse": lambda: f1.call(args_k[0])}, R)
        r0, r1 = recs[False][k], recs[True][k]
        steps = {"robust chunk": rr.CHUNK, "robust gradient": rr.CHUNK, "oracle chunk": st.chunk}.get(k, 1)
        per = "us per step" if steps > 1 else "ms per call"
        scale = 1e6 / steps if steps > 1 else 1e3
        rows.append((f"{k}: C bytes without / with cse (ratio)",
                     f"{r0['c_bytes'] / 1e6:.2f} / {r1['c_bytes'] / 1e6:.2f} MB ({r1['c_bytes'] / r0['c_bytes']:.2f})"))
        rows.append((f"{k}: gcc CPU s without / with cse (ratio)",
                     f"{r0['cpu_s']:.1f} / {r1['cpu_s']:.1f} s ({r1['cpu_s'] / r0['cpu_s']:.2f})"))
        rows.append((f"{k}: {per} without / with cse (speed-up)",
                     f"{statistics.median(t['plain']) * scale:.1f} / {statistics.median(t['cse']) * scale:.1f} "
                     f"({statistics.median(a / b for a, b in zip(t['plain'], t['cse'])):.2f}x)"))
        rows.append((f"{k}: largest output difference with / without cse", f"{diff:.1e}"))
        log(rows[-4][1] + " | " + rows[-3][1] + " | " + rows[-2][1] + " | " + rows[-1][1])
    robust = [f for k, f in built[True][0].items() if k.startswith("robust")]
    for label, fns, R in (("robust first + chunk (similar sizes)", robust[:2], 3),
                          ("robust first + chunk (+ gradient)", robust, 1)):
        walls = {1: [], usable_cores(): []}  # interleaved rounds: one at a time, then side by side
        for _ in range(R):
            for n in walls:
                walls[n].append(compile_logged(fns, st.jit_flags, n_jobs=n)[2])
        seq, par = statistics.median(walls[1]), statistics.median(walls[usable_cores()])
        ratio = statistics.median(a / b for a, b in zip(walls[1], walls[usable_cores()]))
        rows.append((f"{label}, cse, gcc wall: one at a time / {usable_cores()} at once",
                     f"{seq:.1f} / {par:.1f} s ({ratio:.2f}x; {R} round{'s' if R > 1 else ''})"))
        log(rows[-1][1])
    gcc0 = sum(r["cpu_s"] for r in recs[False].values())
    gcc1 = sum(r["cpu_s"] for r in recs[True].values())
    rows.append(("gcc CPU s of all four, without / with cse (ratio)", f"{gcc0:.1f} / {gcc1:.1f} s ({gcc1 / gcc0:.2f})"))
    rows += hybrid_rows(prim, rng)
    table = markdown_table(rows)
    print(table)
    if not args.no_write:
        head = (f"{args.target}; " + stamp(mach, "bench_jit.py" + (f" --target '{args.target}'"
                if args.target != "Walk(slow)" else ""), False, args.repeats, time.perf_counter() - T0))
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, HEADING + "\n\n" + head + "\n\n" + table + "\n\n" + NOTE + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
