"""The reserves at every switch the A1's Table II graph run can make: for each edge the run takes, the
cells the executor may switch through (the sequence's switching rule, `reserve` and `keep`, as
mpgspec.execute.crosscheck.executor.ExecutorPlan applies them; a transient's hand-over at every
verified clock), their largest |u| against the inputs' bound and their least friction-cone value
(the least sampled value of the oracle's rollout from switch-in until it entered E_B). Read from a
verified report, not a timing.

    mpgspec verify specs/a1 && python bench/bench_switch_reserve.py [--report reports/a1/report.json] [--no-write]

Prints a table and replaces (or appends) the section "A1 Table II: reserves at the switches" of
bench/RESULTS.md; exit 1 when a switch asks more than 0.8 of the bound.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import markdown_table, revision, write_section  # noqa: E402

HEADING = "## A1 Table II: reserves at the switches"
SHARE = 0.8


def reserves(report: dict) -> list[dict]:
    """Per edge the graph run takes (in the order first taken): the rows it may switch through and their
    peak |u| and least friction-cone value, and the edge's peak_input weight (over every row)."""
    from mpgspec.graph.transition import executor_clocks
    from mpgspec.report.read import ReportGraph

    g = ReportGraph(report)
    table, cls = report["lookup_table"], {p["name"]: p["class"] for p in report["primitives"]}
    bound = [max(abs(lo), abs(hi)) for lo, hi in report["system"]["input_bounds"].values()]
    trs = {(t["from"], t["to"]): t for t in report["transitions"]}
    taken = []
    for s in report["sequence"]["runs"]["graph"]["switches"]:
        if s.get("from") and (s["from"], s["to"]) not in taken:
            taken.append((s["from"], s["to"]))
    out = []
    for a, b in taken:
        tr, t = g.edge(a, b), trs[(a, b)]
        transient = cls[a] == "transient"
        clocks = executor_clocks(tr, transient, table.get("switch", "first"), table.get("reserve"), bound,
                                 table.get("keep"))
        fams = [f.split("[")[0] for f in t["h_families"]]
        cells = t["cells"]
        rows = []
        for i, t_b in enumerate(clocks):
            if t_b is None:
                continue
            j = int(np.argmin(np.abs(np.asarray(t["t_B"]) - t_b)))
            peak = max(float(g_[i][j] or 0.0) for g_ in cells["peak_input"])
            fc = [cells["min_margins"][k][i][j] for k, f in enumerate(fams) if f == "friction_cone"]
            rows.append({"t_A": float(t["t_A"][i]), "t_B": float(t_b), "peak": peak,
                         "friction": min(fc) if fc and fc[0] is not None else None})
        edge = next(e for e in report["edges"] if (e["from"], e["to"]) == (a, b))
        out.append({"edge": f"{a} -> {b}", "handover": transient, "rows": rows, "bound": max(bound),
                    "edge_peak": edge.get("peak_input")})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--report", default=str(ROOT / "reports" / "a1" / "report.json"))
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    path = Path(a.report)
    if not path.is_file():
        print(f"no report at {path}: run `mpgspec verify specs/a1` first", file=sys.stderr)
        return 2
    report = json.loads(path.read_text(encoding="utf-8"))
    res = reserves(report)
    table, worst, least = [], 0.0, np.inf
    for e in res:
        peak = max((r["peak"] for r in e["rows"]), default=float("nan"))
        fr = min((r["friction"] for r in e["rows"] if r["friction"] is not None), default=None)
        worst, least = max(worst, peak / e["bound"]), min(least, fr if fr is not None else np.inf)
        where = ", ".join(f"{r['t_A']:g}" for r in e["rows"])
        kind = "hand-over at" if e["handover"] else "t_A"
        table.append((f"{e['edge']} ({kind} {where}): peak |u|, least friction cone; edge peak_input over every row "
                      f"{e['edge_peak']:.4g}",
                      f"{peak:.4g} N m ({peak / e['bound']:.2f} of the limit), "
                      + (f"{fr:.3g} N" if fr is not None else "no friction cone")))
    table += [(f"**largest share of the limit at a switch (bar: <= {SHARE})**", f"**{worst:.2f}**"),
              ("**least friction-cone value at a switch (bar: >= 5 N)**", f"**{least:.3g} N**")]
    text = markdown_table(table)
    print(text)
    import datetime

    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    lt = report["lookup_table"]
    head = (f"{when}, {revision(ROOT)}; `python bench/bench_switch_reserve.py` on {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path} "
            f"(switch: {lt.get('switch')}, reserve: {lt.get('reserve')}, keep: {lt.get('keep')}). Simulated (the nominal oracle's rollouts), "
            "per edge of the graph run over the cells its executor may switch through.")
    if not a.no_write:
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, f"{HEADING}\n\n{head}\n\n{text}\n")
    return 0 if worst <= SHARE + 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
