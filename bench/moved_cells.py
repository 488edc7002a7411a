"""Which oracle verdicts a change moved, and whether the new ones hold against a finer reference.

    python bench/moved_cells.py OLD/report.json NEW/report.json [--project a1] [--limit 60] [--no-write]

Not a timing. Compares the Algorithm-1 cells of two reports of the same project (every edge's grid,
cell by cell) and runs each cell whose status differs again with this checkout's oracle, from the
source's setpoint x_A*(t_A) at t_B. Every decided verdict (up to --limit, every safe one first) is
checked against the same closed loop stepped at dt/100 up to the decision (bench_ramp._reference): an
unsafe one's named function must go below zero there, a safe one's functions must stay at or above
zero until E. Writes the section "Oracle: verdicts a change moved, checked at dt/100" of RESULTS.md
(exit 1 when one disagrees).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_ramp  # noqa: E402  (sets MPGSPEC_CACHE like the other benchmarks)
import common  # noqa: E402
from bench_oracle import example  # noqa: E402

from mpgspec.oracle import SafetyOracle  # noqa: E402

HEADING = "## Oracle: verdicts a change moved, checked at dt/100"
STATUS = ("safe", "unsafe", "inconclusive")


def moved(old: dict, new: dict) -> list[tuple]:
    """(A, B, t_A, t_B, old status, new status) of every cell whose status differs."""
    before = {(x["from"], x["to"]): x for x in old["transitions"]}
    out = []
    for x in new["transitions"]:
        y = before.get((x["from"], x["to"]))
        if y is None or y["t_A"] != x["t_A"] or y["t_B"] != x["t_B"]:
            continue
        for i, (r1, r2) in enumerate(zip(y["cells"]["status"], x["cells"]["status"])):
            for j, (c1, c2) in enumerate(zip(r1, r2)):
                if c1 != c2:
                    out.append((x["from"], x["to"], x["t_A"][i], x["t_B"][j], STATUS[int(c1)], STATUS[int(c2)]))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--project", default="a1")
    ap.add_argument("--limit", type=int, default=60)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    cells = moved(json.loads(Path(args.old).read_text()), json.loads(Path(args.new).read_text()))
    prims, s = example(args.project)
    counts: dict[tuple[str, str], int] = {}
    for *_, a, b in cells:
        counts[(a, b)] = counts.get((a, b), 0) + 1
    decided = sorted((c for c in cells if c[5] != "inconclusive"), key=lambda c: c[5] != "safe")[: args.limit]
    result: dict[str, list[str]] = {}
    again = 0
    for a, b, t_a, t_b, _old, was in decided:
        x0 = prims[a].x_star(t_a)
        ev = SafetyOracle(prims[b], s)(x0, t_b)
        again += ev.status == was
        verdict = bench_ramp._reference(prims[b], x0, t_b, s.dt, ev) if ev.status != "inconclusive" else "undecided"
        result.setdefault(verdict, []).append(f"{a} -> {b} t_A {t_a:.3g} t_B {t_b:.3g} {ev.status}")
        print(a, "->", b, f"{t_a:.3g} {t_b:.3g}", ev.status, f"{ev.t_stop:.4g}", ev.violated, verdict, flush=True)
    moves = ", ".join(f"{a} -> {b}: {n}" for (a, b), n in sorted(counts.items())) or "none"
    rows = [("cells that moved (old -> new status)", moves),
            ("decided ones run again, same status", f"{again} of {len(decided)}"),
            (f"checked at dt/{bench_ramp.FINE}: agree / differ",
             f"{len(result.get('agrees', []))} / {len(result.get('differs', []))}"
             + (f" ({'; '.join(result['differs'])})" if result.get("differs") else ""))]
    common.publish_rows(HEADING, f"moved_cells.py {args.old} {args.new}", 1, t_all, rows, not args.no_write)
    return 1 if result.get("differs") else 0


if __name__ == "__main__":
    sys.exit(main())
