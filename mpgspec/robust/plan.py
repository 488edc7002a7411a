"""Planning on robust edges only, from a report's `robust` section."""
from __future__ import annotations

from ..errors import UsageError
from ..report.read import ReportGraph


def robust_report_graph(report: dict) -> ReportGraph:
    """The report's graph restricted to the edges that survived uncertainty, with their robust class,
    t_A windows, weights and switch-in clocks (the nominal t_B of each robust t_A row, the cell checked)."""
    rob = report.get("robust")
    if not rob:
        raise UsageError("the report has no robust graph: the project declares no `uncertainty`")
    keep = {(e["from"], e["to"]): e for e in rob.get("edges", []) if e.get("survives")}
    edges = []
    for e in report.get("edges", []):
        r = keep.get((e["from"], e["to"]))
        if r is not None:
            nominal = {k: v for k, v in e.items() if k != "margin"}  # the nominal margin says nothing robust
            edges.append({**nominal, "class": r["robust_class"], **(r.get("robust_weights") or {})})
    trs = []
    for t in report.get("transitions", []):
        r = keep.get((t["from"], t["to"]))
        if r is not None:
            ok = {i for i, safe in zip(r["cells"]["row"], r["cells"]["robust_safe"]) if safe}
            best = [tb if i in ok else None for i, tb in enumerate(t.get("best_t_B", []))]
            trs.append({**t, "windows": r.get("robust_windows", []), "best_t_B": best})
    return ReportGraph({**report, "edges": edges, "transitions": trs})


def report_lookup_table(g: ReportGraph, weight: str = "duration") -> dict[str, dict[str, str | None]]:
    """table[current][goal] = next primitive on the shortest path of g's planner graph (as
    mpgspec.plan.planner.lookup_table, for a graph read from a report)."""
    from ..plan.planner import next_table

    return next_table(g.planner_graph(), weight)
