"""What the oracle's short first steps cost and decide: Algorithm 1's calls with the ramp against whole steps.

    python bench/bench_ramp.py [--project a1|anymal|pendulum] [--repeats 3] [--reference 40] [--no-write]

After a switch-in and after a contact schedule's lift-off the oracle's steps grow from dt/16
(oracle.flow.RAMP). In one process, every oracle call of Algorithm 1 (each source's setpoint on its
t_A grid, every target on its t_B grid) is made per round twice, through primitives compiled with
the ramp and through the same primitives compiled with whole steps (RAMP = 1). Prints the median
per-round time ratio, the verdicts of both and how they differ, and checks the decided cells that
moved (every one that became safe, and a spread of the rest up to --reference in all) against a
reference: the same closed loop stepped at dt/100 (oracle.flow's switched_flow, no error
bookkeeping) over the rollout up to the decision, each active safety function read at every
reference step. A verdict agrees with it when an unsafe rollout's named function goes below zero in
the reference before the oracle's decision plus dt, and a safe rollout's functions stay at or above
zero until its entry into E.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPGSPEC_CACHE", tempfile.mkdtemp(prefix="mpgspec-bench-"))

import common  # noqa: E402  (bench/common.py)
from bench_oracle import example, own_grid_points  # noqa: E402

from mpgspec.oracle import SafetyOracle  # noqa: E402
from mpgspec.oracle import flow  # noqa: E402

HEADING = "## Oracle: short first steps after a switch-in or a lift-off"
FINE = 100
"""Reference steps per oracle step."""


def _fresh(prims: dict) -> dict:
    """Copies of the primitives without their compiled chunks (a chunk is built at the RAMP in force)."""
    return {n: dataclasses.replace(p, cache={}) for n, p in prims.items()}


def _reference(prim, x0: np.ndarray, t0: float, dt: float, ev) -> str:
    """'agrees' or 'differs': the rollout stepped at dt / FINE up to the oracle's decision (plus dt),
    its named function (unsafe) or every function (safe) read at each reference step."""
    horizon = float(ev.t_stop) + (dt if ev.status == "unsafe" else 0.0)
    n = max(int(np.ceil(horizon / (dt / FINE))), 1)
    X = flow.switched_flow(prim, x0, t0, dt / FINE, n)
    names = prim.h_names
    lows = np.full(len(names), np.inf)
    for k in range(n + 1):
        s = k * dt / FINE
        h = np.asarray(prim.h(X[:, k], t0 + s, s, x0), float).ravel()
        act = np.asarray(flow.active(prim, flow.wrap(prim, t0 + s), X[:, k], s), float).ravel() if names else []
        lows = np.minimum(lows, np.where(np.asarray(act) > 0.5, h, np.inf))
    if ev.status == "unsafe":
        return "agrees" if ev.violated in names and lows[names.index(ev.violated)] < 0 else "differs"
    return "agrees" if (lows >= 0).all() else "differs"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--project", choices=("a1", "anymal", "pendulum"), default="a1")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--reference", type=int, default=40,
                    help="differing cells checked against the reference (every one that became safe, then a spread)")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    prims, s = example(args.project)
    pts = own_grid_points(prims)
    ramp = flow.RAMP
    kinds = {"ramp": (ramp, _fresh(prims)), "whole": (1.0, _fresh(prims))}
    oracles: dict[str, dict] = {}
    evidence: dict[str, list] = {}

    def run(kind):
        flow.RAMP = kinds[kind][0]  # read where a step is built (with the oracle), not after
        try:
            if kind not in oracles:
                oracles[kind] = {b: SafetyOracle(kinds[kind][1][b], s) for b in pts}
            evidence[kind] = [(b, i, e) for b, (x0s, t0s) in pts.items()
                              for i, e in enumerate(oracles[kind][b].evaluate(x0s, t0s))]
        finally:
            flow.RAMP = ramp

    for kind in kinds:  # compile and warm up outside the timed rounds
        run(kind)
    times = common.rounds({k: (lambda k=k: run(k)) for k in kinds}, args.repeats)
    r = common.med_ratio(times["ramp"], times["whole"])
    med = {k: float(np.median(v)) for k, v in times.items()}
    st = ("safe", "unsafe", "inconclusive")
    count = {k: [sum(e.status == x for _b, _i, e in v) for x in st] for k, v in evidence.items()}
    moves: dict[tuple[str, str], int] = {}
    differing = []
    for (b, i, e_r), (_b, _i, e_w) in zip(evidence["ramp"], evidence["whole"]):
        if e_r.status != e_w.status:
            moves[(e_w.status, e_r.status)] = moves.get((e_w.status, e_r.status), 0) + 1
            if e_r.status != "inconclusive":
                differing.append((b, i, e_r))
    steps = {k: sum(e.steps for _b, _i, e in v) for k, v in evidence.items()}
    safe = [d for d in differing if d[2].status == "safe"]  # every new safe verdict, then a spread of the rest
    rest = [d for d in differing if d[2].status != "safe"]
    n_rest = max(args.reference - len(safe), 0)
    checked = safe + rest[:: max(1, int(np.ceil(len(rest) / max(n_rest, 1))))][:n_rest]
    t_ref = time.perf_counter()
    verdicts = {}
    for b, i, e in checked:
        x0s, t0s = pts[b]
        verdicts.setdefault(_reference(prims[b], x0s[i], float(t0s[i]), s.dt, e), []).append(f"{b} {e.status}")
    rows = [("oracle calls per round (Algorithm 1's grids)", f"{len(evidence['ramp'])}"),
            ("oracle steps, ramp; whole steps",
             f"{steps['ramp']}; {steps['whole']} ({steps['ramp'] / steps['whole']:.3f}x)"),
            ("**oracle time, ramp / whole steps**",
             f"**{r:.2f}x** ({med['ramp']:.1f} s vs {med['whole']:.1f} s per round)"),
            ("verdicts safe / unsafe / inconclusive, ramp; whole steps",
             f"{' / '.join(map(str, count['ramp']))}; {' / '.join(map(str, count['whole']))}"),
            ("verdicts that moved (whole steps -> ramp)",
             ", ".join(f"{a} -> {b}: {n}" for (a, b), n in sorted(moves.items())) or "none"),
            (f"decided cells that moved, checked at dt/{FINE} ({time.perf_counter() - t_ref:.0f} s)",
             f"{len(checked)} of {len(differing)}: {len(verdicts.get('agrees', []))} agree, "
             f"{len(verdicts.get('differs', []))} differ" + (f" ({', '.join(verdicts['differs'])})"
                                                            if verdicts.get("differs") else ""))]
    common.publish_rows(HEADING + ("" if args.project == "a1" else f" ({args.project})"), "bench_ramp.py",
                        args.repeats, t_all, rows, not args.no_write)
    return 1 if verdicts.get("differs") else 0


if __name__ == "__main__":
    sys.exit(main())
