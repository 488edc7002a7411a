"""Benchmark of the A1's compile work: CasADi's common-subexpression elimination (cse) and gcc run
side by side, for one target primitive.

    python bench/bench_jit.py                      # Walk(slow): about 8 minutes on 2 shared cores
    python bench/bench_jit.py --target Stand --no-write

Everything runs in one process on specs/a1 (closed loops compiled, E not sized: the margin's
ellipsoid does not change the code's size). For the target's robust rollout (first sample, chunk of
100 steps, gradient wrt the push) and its oracle chunk (the project's chunk length and error
estimate; its large loop always has cse, the row tries cse on the MX graph around it too), and the period of its hybrid flow (the Floquet verifiers'), built with and without cse
(oracle/jit.CSE), each in a fresh private compile cache:
C bytes and gcc seconds (from the MPGSPEC_JIT_LOG compile log), run time per call (median of
interleaved rounds) and the largest difference between the outputs on random inputs near the
primitive's setpoint. Then the three robust libraries (with cse) compiled one after the other
(n_jobs=1) and side by side (compile_many, one gcc per usable core), wall time.

Prints a table and replaces (or appends) the section "A1 compile work (cse, parallel gcc)" of
bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
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
from mpgspec.oracle import integrator, jit  # noqa: E402
from mpgspec.oracle.integrator import build_chunk, initial_state  # noqa: E402
from mpgspec.pipeline.stages import compile_project  # noqa: E402
from mpgspec.robust.rigid import RigidRobustRollout  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC = ROOT / "specs" / "a1" / "project.yaml"
HEADING = "## A1 compile work (cse, parallel gcc)"


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


def compile_logged(fns: list[ca.Function], flags, n_jobs: int) -> tuple[list[ca.Function], list[dict], float]:
    """fns compiled in a fresh private cache: the libraries, the compile log's lines, the wall time."""
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MPGSPEC_CACHE"] = str(Path(tmp) / "cache")
        os.environ["MPGSPEC_JIT_LOG"] = str(Path(tmp) / "log.jsonl")
        t = time.perf_counter()
        out = jit.compile_many(fns, flags, n_jobs=n_jobs)
        wall = time.perf_counter() - t
        recs = [json.loads(line) for line in Path(os.environ["MPGSPEC_JIT_LOG"]).read_text().splitlines()]
        # the libraries stay loaded after their files are gone
    return out, recs, wall


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
        elif fn.name().endswith("_grad"):
            args = [x, 0.0, th, 20 * rng.uniform(-1, 1, (3, rr.K)), rng.uniform(0, 1, fn.size1_in(4))]
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
    ap.add_argument("--repeats", type=int, default=5, help="rounds of the run-time measurement")
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
    libs, recs = {}, {}
    for c in (False, True):
        names = list(built[c][0])
        out, rec, _ = compile_logged([built[c][0][k] for k in names], st.jit_flags, n_jobs=1)
        libs[c], recs[c] = dict(zip(names, out)), dict(zip(names, rec))
        log(f"cse={c}: " + ", ".join(f"{k} {r['c_bytes'] / 1e6:.2f} MB {r['gcc_s']:.1f} s" for k, r in recs[c].items()))
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
        steps = {"robust chunk": rr.CHUNK, "oracle chunk": st.chunk}.get(k, 1)
        per = "us per step" if steps > 1 else "ms per call"
        scale = 1e6 / steps if steps > 1 else 1e3
        rows.append((f"{k}: C bytes without / with cse (ratio)",
                     f"{r0['c_bytes'] / 1e6:.2f} / {r1['c_bytes'] / 1e6:.2f} MB ({r1['c_bytes'] / r0['c_bytes']:.2f})"))
        rows.append((f"{k}: gcc s without / with cse (ratio)",
                     f"{r0['gcc_s']:.1f} / {r1['gcc_s']:.1f} s ({r1['gcc_s'] / r0['gcc_s']:.2f})"))
        rows.append((f"{k}: {per} without / with cse (speed-up)",
                     f"{statistics.median(t['plain']) * scale:.1f} / {statistics.median(t['cse']) * scale:.1f} "
                     f"({statistics.median(a / b for a, b in zip(t['plain'], t['cse'])):.2f}x)"))
        rows.append((f"{k}: largest output difference with / without cse", f"{diff:.1e}"))
        log(rows[-4][1] + " | " + rows[-3][1] + " | " + rows[-2][1] + " | " + rows[-1][1])
    robust = [f for k, f in built[True][0].items() if k.startswith("robust")]
    _, _, seq = compile_logged(robust, st.jit_flags, n_jobs=1)
    _, _, par = compile_logged(robust, st.jit_flags, n_jobs=jit.jobs())
    rows.append((f"robust first + chunk (+ gradient), cse, gcc wall: one at a time / {jit.jobs()} at once",
                 f"{seq:.1f} / {par:.1f} s ({seq / par:.2f}x)"))
    gcc0 = sum(r["gcc_s"] for r in recs[False].values())
    gcc1 = sum(r["gcc_s"] for r in recs[True].values())
    rows.append(("all four functions, gcc s without cse, sequential / with cse, parallel",
                 f"{gcc0:.1f} / {par + recs[True]['oracle chunk']['gcc_s']:.1f} s (cse alone: {gcc1:.1f} s)"))
    rows += hybrid_rows(prim, rng)
    table = markdown_table(rows)
    print(table)
    if not args.no_write:
        head = (f"{args.target}; " + stamp(mach, "python bench/bench_jit.py" + (f" --target '{args.target}'"
                if args.target != "Walk(slow)" else ""), False, args.repeats, time.perf_counter() - T0))
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, HEADING + "\n\n" + head + "\n\n" + table + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
