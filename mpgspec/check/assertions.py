"""Evaluate a project's assertions: required and forbidden edges, plans, reachability, sequences."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import networkx as nx

from ..certify.roa import RANK
from ..graph.transition import MotionPrimitiveGraph
from ..plan.planner import plan_graph, shortest_plan
from ..spec.models import (ForbidEdge, RequireConclusive, RequireEdge, RequirePlan, RequireReachable,
                           RequireSimulation)


@dataclass
class AssertionResult:
    """One assertion: status is pass, fail or error; message says what was found."""

    index: int
    kind: str
    description: str
    status: str
    message: str
    primitive: str | None = field(default=None, compare=False)
    """The primitive whose spec the assertion comes from (roa_level), to locate it; not reported."""

    def to_dict(self) -> dict:
        return {k: v for k, v in asdict(self).items() if k != "primitive"}


def _edge_text(a, b):
    return f"{a} -> {b}"


def _not_certified(tr) -> str:
    """Why an edge is not certified: how many of the safe cells it rests on are proved."""
    safe = tr.rests_on()
    n = sum(c.method == "certified" for c in safe)
    return (f"edge {_edge_text(tr.source, tr.target)} is {tr.method}, not certified: "
            f"{n} of {len(safe)} safe cells certified")


def _run_text(run) -> str:
    """What happened in a sequence run: safe, the first violation, or why it stopped (a state that
    blew up, an unverified hand-over); a run that failed without a violation is unsafe too."""
    if run.safe:
        return "safe throughout"
    parts = []
    first = run.violations[0] if run.violations else None
    if isinstance(first, dict):
        t = first.get("t")
        when = f" at t = {t:.3f} s" if isinstance(t, (int, float)) else ""
        parts.append(f"violated {first.get('h', '?')} of {first.get('primitive', '?')}{when}")
    if run.failed:
        parts.append(str(run.failed))
    return "; ".join(parts) or "unsafe"


def evaluate_assertions(assertions, g: MotionPrimitiveGraph, runs: dict) -> list[AssertionResult]:
    """Check every assertion against the built graph and the sequence runs (mode -> SequenceRun)."""
    out = []
    G = plan_graph(g)
    for i, a in enumerate(assertions):
        if isinstance(a, RequireEdge):
            e = a.edge
            tr = g.edge(e.from_, e.to)
            want = f" of class {e.class_}" if e.class_ else ""
            desc = f"edge {_edge_text(e.from_, e.to)}{want}" + (", certified" if e.evidence == "certified" else "")
            if tr is None:
                ok, msg = False, "no transition was verified"
            elif e.class_ and int(tr.cls) != e.class_:
                ok, msg = False, f"found class {int(tr.cls)}"
            elif e.evidence == "certified" and tr.method != "certified":
                ok, msg = False, _not_certified(tr)
            else:
                ok, msg = True, f"class {int(tr.cls)}" + (", certified" if e.evidence == "certified" else "")
            out.append(AssertionResult(i, "edge", desc, "pass" if ok else "fail", msg))
        elif isinstance(a, ForbidEdge):
            e = a.no_edge
            tr = g.edge(e.from_, e.to)
            out.append(AssertionResult(i, "no_edge", f"no edge {_edge_text(e.from_, e.to)}",
                                       "pass" if tr is None else "fail",
                                       "no transition" if tr is None else f"a class {int(tr.cls)} transition exists"))
        elif isinstance(a, RequirePlan):
            p = a.plan
            plan = shortest_plan(g, p.from_, p.to, p.weight, G)
            desc = f"plan {p.from_} => {p.to}" + (f" with {p.weight} <= {p.max_cost:g}" if p.max_cost is not None else "")
            if not plan.found:
                ok, msg = False, "unreachable"
            elif p.max_cost is not None and plan.cost > p.max_cost:
                ok, msg = False, f"cheapest costs {plan.cost:.3g}: {' -> '.join(plan.path)}"
            else:
                ok, msg = True, f"{' -> '.join(plan.path)} (cost {plan.cost:.3g})"
            out.append(AssertionResult(i, "plan", desc, "pass" if ok else "fail", msg))
        elif isinstance(a, RequireReachable):
            src = a.reachable_from
            missing = sorted(set(G.nodes) - nx.descendants(G, src) - {src})
            out.append(AssertionResult(i, "reachable_from", f"every primitive reachable from {src}",
                                       "fail" if missing else "pass",
                                       f"unreachable: {', '.join(missing)}" if missing else "all reachable"))
        elif isinstance(a, RequireConclusive):
            per = {k: sum(e.status == "inconclusive" for row in tr.evidence for e in row)
                   for k, tr in g.transitions.items()}
            n = sum(per.values())
            worst = sorted(((v, k) for k, v in per.items() if v), reverse=True)[:3]
            where = ", ".join(f"{a} -> {b}: {v}" for v, (a, b) in worst)
            out.append(AssertionResult(i, "max_inconclusive", f"at most {a.max_inconclusive} inconclusive oracle calls",
                                       "pass" if n <= a.max_inconclusive else "fail",
                                       f"{n} inconclusive" + (f" ({where})" if where else "")))
        elif isinstance(a, RequireSimulation):
            run = runs.get(a.simulation_safe)
            desc = f"{a.simulation_safe} sequence is {'safe' if a.expect else 'unsafe'}"
            if run is None:
                out.append(AssertionResult(i, "simulation_safe", desc, "error", "the project has no sequence"))
                continue
            ok = run.safe == a.expect
            msg = _run_text(run)
            out.append(AssertionResult(i, "simulation_safe", desc, "pass" if ok else "fail", msg))
    return out


def roa_requirements(spec, roa: dict, start: int) -> list[AssertionResult]:
    """`roa.require` of each primitive as an assertion on the level of evidence of its radius
    (roa: name -> the sized region's record, with level, method and radius)."""
    out = []
    for inst in spec.primitives:
        need = inst.spec.roa.require
        if need is None:
            continue
        rec = roa[inst.name]
        ok = RANK[rec.level] >= RANK[need]
        out.append(AssertionResult(start + len(out), "roa_level", f"E of {inst.name} is {need}",
                                   "pass" if ok else "fail", f"{rec.level} by {rec.method}, r = {rec.radius:.4g}",
                                   primitive=inst.name))
    return out
