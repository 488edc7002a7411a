"""The shortest safe sequence between two primitives of a project, from its verified report or
from a rebuilt graph (the nominal one, or the robust one that withstood the project's uncertainty)."""
from __future__ import annotations

from pathlib import Path

from ..errors import UsageError, unknown_primitive
from ..plan.planner import hops, plan_graph, shortest_path, shortest_plan, takeable
from ..report.read import ReportGraph
from .reuse import Notify, load_one, quick_report, rebuild, verified


def _robust_graph(spec):
    """The robust graph of a project that declares `uncertainty`."""
    from ..robust.graph import robust_stage

    if spec.project.uncertainty is None:
        raise UsageError(f"{spec.name} declares no `uncertainty`: there is no robust graph to plan on")
    return robust_stage(*rebuild(spec)).graph


def plan_project(project, source: str, goal: str, weight: str = "duration", out="reports", rebuild_: bool = False,
                 robust: bool = False, notify: Notify | None = None) -> dict:
    """from, to, weight, path (None when unreachable), cost, each hop with its class and the t_A
    windows to wait for (Class 2), and source: the report.json read, or 'rebuilt'."""
    report = quick_report(project, out, rebuild_)
    spec = None if report is not None else load_one(project)
    name = report["project"]["name"] if report is not None else spec.name
    names = [p["name"] for p in report["primitives"]] if report is not None else [p.name for p in spec.primitives]
    for n in (source, goal):
        if n not in names:
            raise unknown_primitive(n, names)
    if report is None:
        report = verified(spec, out, rebuild_, notify)
    if report is not None:
        if robust:
            from ..robust.plan import robust_report_graph

            g = robust_report_graph(report)
        else:
            g = ReportGraph(report)
        G = g.planner_graph()
        path, cost = shortest_path(G, source, goal, weight)
        edge, where = g.edge, str(Path(out) / name / "report.json")
    else:
        graph = _robust_graph(spec) if robust else rebuild(spec)[1].graph
        G = plan_graph(graph)
        plan = shortest_plan(graph, source, goal, weight, G)
        path, cost, edge, where = plan.path, plan.cost, graph.edge, "rebuilt"
    doc = {"from": source, "to": goal, "weight": weight, "path": path, "cost": cost, "hops": hops(edge, path),
           "source": where}
    if path is None:
        doc["why"] = unreachable(G, source, goal, weight, robust)
    return doc


def unreachable(G, source: str, goal: str, weight: str, robust: bool) -> str:
    """Why no plan exists: what the source reaches, and which edges enter the goal."""
    import networkx as nx

    kind = "robust " if robust else ""
    usable = takeable(G, weight)
    reach = sorted(nx.descendants(usable, source)) if source in usable else []
    into = sorted(a for a, _b in usable.in_edges(goal)) if goal in usable else []
    text = (f"{source} reaches {', '.join(reach)} through {kind}edges" if reach else f"{source} has no {kind}edge out")
    text += "; " + (f"{goal} is entered only from {', '.join(into)}" if into else f"no {kind}edge enters {goal}")
    return text + (" (edges without a margin are not taken by --weight margin)" if weight == "margin" else "")
