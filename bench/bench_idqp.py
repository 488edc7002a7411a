"""Benchmark of the A1's held ID-QP: the per-step cost of Stand's oracle step against a joint-PD step.

    python bench/bench_idqp.py            # about 1 minute on 2 cores
    python bench/bench_idqp.py --quick    # 3 rounds
    options: --repeats R, --no-continuous (skip the per-evaluation variant), --no-write

The target (issue 8): "The ID-QP, where used, is solved at a control rate with the input held
between solves (as a robot's controller runs; say which rate) and warm-started, and its per-step
cost is measured against a PD step; target <= 5x."

Everything runs in one process on a copy of specs/a1 with only Lie and Stand (the walks are left
out), with the project's oracle settings (dt 1 ms, step doubling, accuracy low) and a private,
cold compile cache. Measured, in interleaved rounds (a row is the median over rounds, a ratio the
median of per-round ratios):

  Stand   oracle call Lie -> Stand: SafetyOracle(Stand)(x_Lie*(0), 0), the ID-QP solved at the
          start of every 1 ms step (1 kHz, stand.yaml) and held over it, warm-started;
  Lie     oracle call Stand -> Lie (joint PD with gravity compensation and the cubic profile);
  per step = call time / steps taken; the ratio Stand / Lie is the target (<= 5);
  and the compiled work alone: each primitive's oracle chunk (K = 64 steps) called zero-copy 32
  times in sequence from the same start (2048 steps), per step, and its ratio.

For information, Stand with the law solved at every evaluation of the closed loop (18 per step
under step doubling: RK4 stages, both ends, rate differences, the companion), as the oracle ran it
before the control rate, though with the ID-QP's closed-form shortcut (the same primitive with
`sampled` removed), measured the same way.

Prints a table and replaces (or appends) the section "A1 ID-QP (held)" of bench/RESULTS.md. Exit
code 0 when the ratio of oracle calls is at most 5 and both verdicts are 1, else 1.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

_JIT_DIR = tempfile.mkdtemp(prefix="bench-idqp-jit-")
os.environ["MPGSPEC_CACHE"] = _JIT_DIR

import casadi as ca  # noqa: E402
import common  # noqa: E402  (bench/common.py)
import yaml  # noqa: E402
from common import markdown_table, med_ratio, pd_lie, rounds, stamp, write_section  # noqa: E402

from mpgspec.api import compile_project, settings_for  # noqa: E402
from mpgspec.oracle.integrator import build_chunk  # noqa: E402
from mpgspec.oracle.oracle import SafetyOracle  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

SPEC_DIR = ROOT / "specs" / "a1"
HEADING = "## A1 ID-QP (held)"
TARGET = 5.0
N_CHUNKS = 32


def log(msg: str) -> None:
    print(msg, flush=True)


def lie_and_stand(tmp: Path) -> Path:
    """specs/a1 copied to tmp with only Lie and Stand, without assertions and sequence."""
    dst = tmp / "a1"
    shutil.copytree(SPEC_DIR, dst, ignore=shutil.ignore_patterns("gaits", "walk*.yaml", "gaits.yaml"))
    pd_lie(dst)  # the baseline: the paper's joint-PD Lie
    proj = yaml.safe_load((dst / "project.yaml").read_text())
    proj["primitives"] = ["primitives/lie.yaml", "primitives/stand.yaml"]
    proj.pop("assertions", None)
    proj.pop("sequence", None)
    proj.pop("uncertainty", None)  # its robust assertions name the walks, Jump and Land
    (dst / "project.yaml").write_text(yaml.safe_dump(proj, sort_keys=False))
    return dst / "project.yaml"


class ChunkLoop:
    """An oracle chunk (one column) called zero-copy n times in sequence, each call fed the previous
    end state: the compiled work of a rollout without the oracle's Python."""

    def __init__(self, chunk, z0: np.ndarray):
        f = chunk.mapped(1)
        self.buf, self.ev = f.buffer()
        self.zin, self.zf, self.out = np.zeros(f.nnz_in(0)), np.zeros(f.nnz_out(0)), np.zeros(f.nnz_out(1))
        self.buf.set_arg(0, memoryview(self.zin))
        self.buf.set_res(0, memoryview(self.zf))
        self.buf.set_res(1, memoryview(self.out))
        self.z0 = z0

    def run(self, n: int) -> np.ndarray:
        self.zin[:] = self.z0
        for _ in range(n):
            self.ev()
            self.zin[:] = self.zf
        return self.zf


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 rounds")
    ap.add_argument("--repeats", type=int, default=None, help="measurement rounds (default 7, quick 3)")
    ap.add_argument("--no-continuous", action="store_true", help="skip Stand with the law solved at every evaluation")
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    R = args.repeats or (3 if args.quick else 7)
    tmp = Path(tempfile.mkdtemp(prefix="bench-idqp-"))
    try:
        return _run(args, R, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(_JIT_DIR, ignore_errors=True)


def _run(args, R: int, tmp: Path) -> int:
    T0 = time.perf_counter()
    mach = common.machine(casadi=ca.__version__, numpy=np.__version__)
    mach["revision"] = common.revision(ROOT)
    spec = load_project(lie_and_stand(tmp))
    prims = compile_project(spec)
    st = settings_for(spec)
    lie, stand = prims["Lie"], prims["Stand"]
    cases = {"Stand": (stand, lie.x_star(0.0)), "Lie": (lie, stand.x_star(0.0))}
    if not args.no_continuous:
        cont = dataclasses.replace(stand, name="Stand_continuous", sampled=None, loop_u=None, cache={})
        cases["Stand, law at every evaluation"] = (cont, lie.x_star(0.0))
    log(f"A1 Lie and Stand; oracle dt={st.dt:g}, error={st.error}, refinements={st.refinements}, K={st.chunk}; "
        f"Stand's ID-QP: {stand.info['id_qp']}")
    jit, oracles, loops, evs = {}, {}, {}, {}
    for name, (p, x0) in cases.items():
        t = time.perf_counter()
        oracles[name] = SafetyOracle(p, st)
        ch = build_chunk(p, st.dt, st.chunk, st.jit, st.jit_flags, error=st.error)
        jit[name] = time.perf_counter() - t
        evs[name] = oracles[name](x0, 0.0)
        loops[name] = ChunkLoop(ch, ch.start(x0[None], [0.0])[:, 0])
        loops[name].run(1)
        e = evs[name]
        log(f"{name}: JIT {jit[name]:.1f} s; verdict {e.verdict} ({e.status}), {e.reason.value} at {e.t_stop:.3f} s, "
            f"{e.steps} steps")
    fns = {}
    for name, (p, x0) in cases.items():
        fns[f"oracle {name}"] = lambda o=oracles[name], x0=x0: o(x0, 0.0)
        fns[f"chunks {name}"] = lambda lp=loops[name]: lp.run(N_CHUNKS)
    times = rounds(fns, R)
    steps = {n: evs[n].steps for n in cases}
    n_chunk_steps = N_CHUNKS * st.chunk
    per = {n: [v / steps[n] for v in times[f"oracle {n}"]] for n in cases}
    per_c = {n: [v / n_chunk_steps for v in times[f"chunks {n}"]] for n in cases}
    med = statistics.median
    ratio = med_ratio(per["Stand"], per["Lie"])
    ratio_c = med_ratio(per_c["Stand"], per_c["Lie"])
    rows = []
    for n in cases:
        e = evs[n]
        rows.append((f"{n}: oracle call ({e.steps} steps; verdict {e.verdict}, {e.reason.value} at {e.t_stop:.3f} s)",
                     f"{med(times[f'oracle {n}']) * 1e3:,.1f} ms, {med(per[n]) * 1e6:,.1f} us/step"))
        rows.append((f"{n}: compiled chunks alone, {n_chunk_steps} steps zero-copy",
                     f"{med(times[f'chunks {n}']) * 1e3:,.1f} ms, {med(per_c[n]) * 1e6:,.1f} us/step; "
                     f"JIT {jit[n]:.1f} s"))
    rows.append(("**Stand step (held ID-QP, 1 kHz) / Lie step (joint PD)**, oracle calls (target <= 5)",
                 f"**{ratio:.2f}x**"))
    rows.append(("Stand step / Lie step, compiled chunks alone", f"{ratio_c:.2f}x"))
    if not args.no_continuous:
        n = "Stand, law at every evaluation"
        rows.append(("Stand step with the law at every loop evaluation (no hold) / Lie step, oracle calls",
                     f"{med_ratio(per[n], per['Lie']):.1f}x "
                     f"(compiled chunks: {med_ratio(per_c[n], per_c['Lie']):.1f}x)"))
    table = markdown_table(rows)
    head = (stamp(mach, "bench_idqp.py", args.quick, R, time.perf_counter() - T0) + " specs/a1 with Lie and "
            f"Stand only, oracle dt={st.dt:g}, error={st.error}, K={st.chunk}, cold JIT cache. Stand's ID-QP is "
            f"solved at {stand.info['id_qp']['control_rate']} (once per step: judged rollout and step-doubling "
            f"companion one solve each) and held over the step, warm-started; when no inequality is active its "
            f"optimum comes from the equality-constrained KKT system in closed form, else qrqp runs.")
    section = (f"{HEADING}\n\n{head}\n\n{table}\n\n"
               "See the docstring of bench/bench_idqp.py for the meaning of each row.\n")
    log("\n" + section)
    if not args.no_write:
        out = ROOT / "bench" / "RESULTS.md"
        write_section(out, HEADING, section)
        log(f"wrote the '{HEADING[3:]}' section of {out.relative_to(ROOT)}")
    ok = ratio <= TARGET and evs["Stand"].verdict == 1 and evs["Lie"].verdict == 1
    log(f"target: held ID-QP step within {TARGET:g}x of a PD step {'met' if ok else 'MISSED'} ({ratio:.2f}x)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
