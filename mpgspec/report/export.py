"""The motion primitive graph of a report as Graphviz DOT and GraphML, for use outside mpgspec.

Both are built from the report dict alone, in the paper's notation (Table I, Definition 3):
box = fixed, circle = periodic, diamond = transient; solid = Class 1, dashed = Class 2. Each edge
carries its evidence (certified or simulated) and the t_A intervals proved for every t_A. With a robust
graph in the report, an edge lost under uncertainty (nominal only) is vermillion in DOT and carries
`robust = false` in GraphML.
"""
from __future__ import annotations

import math

import networkx as nx

from ..plan.planner import WEIGHTS
from .proved import proved_text, proved_windows

SHAPES = {"fixed": "box", "periodic": "circle", "transient": "diamond"}
STYLES = {1: "solid", 2: "dashed"}
NOMINAL_ONLY = "#D55E00"
EDGE_WEIGHTS = WEIGHTS


def _q(s) -> str:
    """A quoted DOT identifier or string."""
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _num(v) -> str:
    """A number for a label; None (a non-finite number in the report) as '?'."""
    if v is None:
        return "?"
    try:
        return f"{float(v):.4g}"
    except (TypeError, ValueError):
        return str(v)


def _float(v) -> float | None:
    """A finite float, or None (GraphML gets no attribute then)."""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _methods(report: dict) -> dict[tuple[str, str], dict]:
    return {(t["from"], t["to"]): t for t in report.get("transitions", [])}


def _survives(report: dict) -> dict[tuple[str, str], bool]:
    """(from, to) -> whether the nominal edge survives the project's uncertainty (empty without `robust`)."""
    return {(e["from"], e["to"]): bool(e.get("survives")) for e in (report.get("robust") or {}).get("edges", [])}


def to_dot(report: dict) -> str:
    """Graphviz DOT of the graph; edges are labelled with their transition duration."""
    name = report.get("project", {}).get("name", "mpg")
    trs = _methods(report)
    survives = _survives(report)
    lines = [f"digraph {_q(name)} {{", f"  label={_q(f'motion primitive graph: {name}')};", "  labelloc=t;",
             '  node [fontname="Helvetica", style=filled, fillcolor="#f4f4f4"];',
             '  edge [fontname="Helvetica", fontsize=10];']
    for p in report.get("primitives", []):
        tip = f"{p['class']}" + (f", period {_num(p['period'])} s" if p.get("period") is not None else "")
        if p.get("domain"):
            tip += f", domain [{_num(p['domain'][0])}, {_num(p['domain'][1])}] s"
        lines.append(f"  {_q(p['name'])} [shape={SHAPES.get(p['class'], 'ellipse')}, tooltip={_q(tip)}];")
    for e in report.get("edges", []):
        attrs = [f"style={STYLES.get(e['class'], 'dotted')}"]
        if e.get("duration") is not None:
            attrs.append(f"label={_q(_num(e['duration']) + ' s')}")
        tr = trs.get((e["from"], e["to"]))
        tip = f"Class {e['class']}" + (f", {tr['method']}" if tr else "")
        if tr and e["class"] == 2:
            tip += ", t_A windows " + " ".join(f"[{_num(a)}, {_num(b)}]" for a, b in tr["windows"])
        if proved_text(tr):
            tip += ", " + proved_text(tr)
        if survives.get((e["from"], e["to"])) is False:
            tip += ", nominal only (lost under uncertainty)"
            attrs += [f"color={_q(NOMINAL_ONLY)}", f"fontcolor={_q(NOMINAL_ONLY)}"]
        attrs.append(f"tooltip={_q(tip)}")
        lines.append(f"  {_q(e['from'])} -> {_q(e['to'])} [{', '.join(attrs)}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def to_networkx(report: dict) -> nx.DiGraph:
    """The graph with scalar attributes only (GraphML cannot hold lists or None)."""
    G = nx.DiGraph(project=report.get("project", {}).get("name", ""),
                   schema_version=str(report.get("schema_version", "")))
    for p in report.get("primitives", []):
        attrs = {"class": p["class"], "shape": SHAPES.get(p["class"], "ellipse"), "controller": p.get("controller", ""),
                 "roa_radius": p.get("roa_radius"), "roa_method": p.get("roa_method", ""), "period": p.get("period"),
                 "next": p.get("next")}
        if p.get("domain"):
            attrs["domain_start"], attrs["domain_end"] = (_float(v) for v in p["domain"][:2])
        attrs["safety_functions"] = ",".join(p.get("safety_functions", []))
        G.add_node(p["name"], **{k: v for k, v in attrs.items() if v is not None})
    trs = _methods(report)
    survives = _survives(report)
    for e in report.get("edges", []):
        tr = trs.get((e["from"], e["to"]))
        attrs = {"class": int(e["class"]), "style": STYLES.get(e["class"], "dotted"),
                 **{k: _float(e[k]) for k in EDGE_WEIGHTS if _float(e.get(k)) is not None}}
        if tr:
            attrs["method"] = tr["method"]
            attrs["windows"] = len(tr["windows"])
            attrs["safe_cells"], attrs["total_cells"] = tr["counts"]["safe"], tr["counts"]["total"]
            attrs["certified_safe_cells"] = tr["counts"].get("certified_safe", 0)
            if proved_windows(tr):
                attrs["certified_windows"] = " ".join(f"[{float(a)!r}, {float(b)!r}]" for a, b in proved_windows(tr))
        if (e["from"], e["to"]) in survives:
            attrs["robust"] = survives[(e["from"], e["to"])]
        G.add_edge(e["from"], e["to"], **attrs)
    return G


def to_graphml(report: dict) -> str:
    """GraphML text of the graph (networkx writer)."""
    return "\n".join(nx.generate_graphml(to_networkx(report))) + "\n"
