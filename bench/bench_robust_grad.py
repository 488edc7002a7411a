"""Benchmark of the push gradient of the adversarial search: the reverse sweep chunk by chunk against
one reverse pass over the whole horizon.

    python bench/bench_robust_grad.py                      # Walk(in_place) and Walk(slow), 3 rounds
    python bench/bench_robust_grad.py --targets 'Walk(fast)' --repeats 5
    options: --no-write

specs/a1's nominal graph is built first (its oracle calls from the result cache when they are
there); each target's robust check (mpgspec.robust.cells.run_target) runs once in this process and
its search's first gradient call (every live cell's binding h sample and RoA margin at entry) is
kept. That call is then timed, in interleaved rounds, two ways:

  chunks   as verify runs it (RobustRollout.gradients): the forward chunks up to each sample's
           chunk, then the chunks' compiled adjoints from there back to switch-in;
  horizon  the baseline: one compiled reverse pass over the whole horizon (N steps) per sample,
           whatever the sample's step.

Rows: the median time of each, the median per-round ratio, the horizon and the samples' steps, and
whether both give the same gradient, bit for bit (they must: the same operations in the same order).
Prints a table and replaces (or appends) the section "Robust search: the gradient up to its sample" of
bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402
import common  # noqa: E402  (bench/common.py)
from common import markdown_table, med_ratio, rounds  # noqa: E402

from mpgspec.oracle.jit import compile_many, cse  # noqa: E402
from mpgspec.robust.cells import run_target  # noqa: E402
from mpgspec.robust.rollout import RobustRollout  # noqa: E402

HEADING = "## Robust search: the gradient up to its sample"


def horizon_gradient(rr: RobustRollout) -> ca.Function:
    """The baseline: (x0, t0, theta, D, w) -> d(w' vec(Y))/d vec(D) by one reverse pass over all N steps."""
    step, first = rr._reverse_parts()
    x0, t0 = ca.MX.sym("x0", rr.prim.system.nx), ca.MX.sym("t0")
    TH, D = ca.MX.sym("theta", rr.nth), ca.MX.sym("D", rr.nd, rr.K)
    n, S, on = np.arange(rr.N), np.zeros((rr.K, rr.N)), rr.seg < rr.K
    S[rr.seg[on], n[on]] = 1.0
    _, outs = step.mapaccum("robust_acc", rr.N)(ca.vertcat(x0, t0, ca.MX(0), x0, TH), ca.mtimes(D, ca.DM(S)))
    Y = ca.horzcat(first(x0, t0, 0, TH, D[:, 0])[0], outs)
    w = ca.MX.sym("w", Y.numel())
    fn = cse(ca.Function(rr._name + "_horizon_grad", [x0, t0, TH, D, w], [ca.gradient(ca.dot(w, ca.vec(Y)), ca.vec(D))]))
    return compile_many([fn], rr.GRAD_FLAGS, libs=rr.libs)[0] if rr.settings.jit else fn


def by_horizon(rr: RobustRollout, fn: ca.Function, X0, T0, TH, D, rows, ks) -> np.ndarray:
    n = len(X0)
    W = np.zeros(((rr.nh + 1) * (rr.N + 1), n))
    W[np.asarray(ks) * (rr.nh + 1) + np.asarray(rows), np.arange(n)] = 1.0
    G = rr._call(fn, n, [X0.T, T0[None, :], rr._th(TH, n), rr._d(D, n), W])
    return G.T.reshape(n, rr.K, rr.nd).transpose(0, 2, 1)


def first_search_call(prims, job):
    """(the rollout, the arguments of its search's first gradient call) of one target's check."""
    seen = []
    orig = RobustRollout.gradients

    def keep(self, *args):
        if not seen:
            seen.append((self, args))
        return orig(self, *args)
    RobustRollout.gradients = keep
    try:
        run_target(prims, job)
    finally:
        RobustRollout.gradients = orig
    return seen[0] if seen else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets", nargs="+", default=["Walk(in_place)", "Walk(slow)"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    T0 = time.perf_counter()
    mach = common.machine(casadi=ca.__version__, numpy=np.__version__, revision=common.revision(ROOT))
    cp, jobs = common.a1_target_jobs(args.targets)
    fns, facts = {}, {}
    for job in jobs.values():
        got = first_search_call(cp.prims, job)
        if got is None:
            print(f"{job.target}: its search takes no gradient", flush=True)
            continue
        rr, a = got
        base = horizon_gradient(rr)
        same = np.array_equal(rr.gradients(*a), by_horizon(rr, base, *a))
        facts[job.target] = {"N": rr.N, "ks": sorted(int(k) for k in a[5]), "same": same}
        print(f"{job.target}: {len(a[5])} samples at steps {facts[job.target]['ks']} of {rr.N}; equal: {same}", flush=True)
        fns[f"chunks {job.target}"] = lambda rr=rr, a=a: rr.gradients(*a)
        fns[f"horizon {job.target}"] = lambda rr=rr, base=base, a=a: by_horizon(rr, base, *a)
    times = rounds(fns, args.repeats)
    med = statistics.median
    rows = []
    for name, f in facts.items():
        c, h = times[f"chunks {name}"], times[f"horizon {name}"]
        rows += [(f"{name}: one reverse pass over the horizon, {len(f['ks'])} samples (horizon)", f"{med(h):.2f} s"),
                 (f"{name}: forward chunks, then their adjoints back from each sample (chunks)", f"{med(c):.2f} s"),
                 (f"**{name}: horizon / chunks**", f"**{med_ratio(h, c):.2f}x**"),
                 (f"{name}: samples' steps (of {f['N']})", f"{f['ks'][0]}-{f['ks'][-1]}, median {int(np.median(f['ks']))}"),
                 (f"{name}: gradients equal, bit for bit", str(f["same"]))]
    common.publish(HEADING, mach, "bench_robust_grad.py", args.repeats, time.perf_counter() - T0,
                   markdown_table(rows), not args.no_write)
    return 0 if all(f["same"] for f in facts.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
