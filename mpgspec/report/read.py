"""Read verified results back: a report.json, whether it still belongs to the specs, and the
planner's graph rebuilt from it (only the edges the planner may take, with their weights).

A report is used only when trust.check_report accepts it (its integrity record under this machine's
key, then its structure); otherwise reading it raises trust.ReportError, which names the file and
the key path.

Kept light (json and networkx) so that `mpgspec plan` answers from a report in well under a second.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import networkx as nx

from ..plan.planner import WEIGHTS
from .trust import ReportError, check_graph, check_report


def _read_json(path: Path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def load_report(path) -> dict:
    """A report.json (or the folder holding one) as a dict; ReportError when it is refused."""
    p = Path(path)
    if p.is_dir():
        p = p / "report.json"
    report = _read_json(p)
    check_report(report, p)
    return report


def report_status(report_path, project_file, strict: bool = False) -> tuple[dict | None, str]:
    """(report, '') when the report at report_path was verified from the project's current spec
    files and is accepted by its checks, else (None, why not). strict: a current report that the
    checks refuse raises ReportError instead (plan and simulate stop on it rather than rebuild)."""
    from ..spec.digest import spec_digest

    p = Path(report_path)
    if not p.is_file():
        return None, f"no verified results at {p}"
    try:
        report = _read_json(p)
    except (OSError, ValueError, RecursionError) as e:
        return None, f"{p} cannot be read ({e})"
    try:
        if not isinstance(report, dict):
            check_report(report, p)
        if not str(report.get("schema_version", "")).startswith("2."):
            return None, f"{p} has report schema {report.get('schema_version')!r}, not 2.x"
        project = report.get("project")
        stored = project.get("digest") if isinstance(project, dict) else None
        if not stored or stored != spec_digest(project_file):
            return None, f"{p} is stale: the spec files changed since it was verified"
        check_report(report, p)
    except ReportError as e:
        if strict:
            raise
        return None, str(e)
    return report, ""


@dataclass
class ReportTransition:
    """What execution needs of a verified transition: its grid times and switch-in clocks."""

    source: str
    target: str
    cls: int
    t_A_list: list
    best_t_B: list
    windows: list
    weights: dict = field(default_factory=dict)
    row_margins: list = field(default_factory=list)
    row_peaks: list = field(default_factory=list)
    row_from_roa: list = field(default_factory=list)
    row_keeps: list = field(default_factory=list)

    @cached_property
    def t_A(self):
        """The t_A grid as a numpy array."""
        import numpy as np

        return np.asarray(self.t_A_list, float)

    def switch_clock(self, t_A: float) -> float | None:
        """The verified t_B for a grid time t_A, None where no transition starts."""
        import numpy as np

        i = int(np.argmin(np.abs(self.t_A - t_A)))
        return self.best_t_B[i] if abs(self.t_A[i] - t_A) < 1e-9 else None


def _per_row(t: dict, key: str, read) -> list:
    """Per t_A of a report's transition: read(grids, i, j) of its cells' `key` grids at the cell of its best
    t_B (column j), None where it has none or the cells do not say; [] without such grids."""
    c, best, t_B = t.get("cells"), t.get("best_t_B") or [], t.get("t_B") or []
    grids = c.get(key) if isinstance(c, dict) else None
    if not isinstance(grids, list) or not t_B:
        return []
    out = []
    for i, t_b in enumerate(best):
        try:
            out.append(None if t_b is None else read(grids, i, min(range(len(t_B)), key=lambda k: abs(t_B[k] - t_b))))
        except (IndexError, KeyError, TypeError, ValueError):
            out.append(None)
    return out


def _row_peaks(t: dict) -> list:
    """Per t_A of a report's transition: the peak |u| of each input in the cell of its best t_B."""
    return _per_row(t, "peak_input", lambda grids, i, j: [g[i][j] for g in grids])


def _row_keeps(t: dict, target_h: list) -> list:
    """Per t_A of a report's transition: the least value of each safety function family in the cell of
    its best t_B ({family: value}); the grids are by h_families, else by the target's safety functions."""
    names = t.get("h_families") or target_h

    def read(grids, i, j):
        if not isinstance(names, list) or len(grids) != len(names):
            raise ValueError("the cells' families do not match")
        least: dict = {}
        for name, g in zip(names, grids):
            if g[i][j] is not None:
                fam = str(name).split("[", 1)[0]  # the family (graph.transition.family)
                least[fam] = min(least.get(fam, math.inf), float(g[i][j]))
        return least

    return _per_row(t, "min_margins", read)


class ReportGraph:
    """The motion primitive graph of a report: G holds every verified edge (attribute `class`),
    planner_graph() the ones the planner may take; edge(a, b) as MotionPrimitiveGraph.edge.
    A report whose graph cannot be rebuilt raises ReportError (source: where it was read)."""

    def __init__(self, report: dict, source="report"):
        check_graph(report, source)
        self.report = report
        self.G = nx.DiGraph()
        for p in report.get("primitives", []):
            self.G.add_node(p["name"], **{"class": p["class"], "period": p.get("period"), "domain": p.get("domain"),
                                          "next": p.get("next")})
        trs = {(t["from"], t["to"]): t for t in report.get("transitions", [])}
        h_of = {p["name"]: list(p.get("safety_functions") or []) for p in report.get("primitives", [])}
        self.transitions: dict[tuple[str, str], ReportTransition] = {}
        for e in report.get("edges", []):
            t = trs.get((e["from"], e["to"]), {})
            self.G.add_edge(e["from"], e["to"], **{"class": e["class"], "usable": e.get("usable", True),
                                                   **{k: e[k] for k in WEIGHTS if e.get(k) is not None}})
            self.transitions[(e["from"], e["to"])] = ReportTransition(
                e["from"], e["to"], e["class"], list(t.get("t_A", [])), list(t.get("best_t_B", [])),
                [tuple(w) for w in t.get("windows", [])], {k: e[k] for k in WEIGHTS if e.get(k) is not None},
                list(t.get("row_margins") or []), _row_peaks(t), list((t.get("from_roa") or {}).get("rows") or []),
                _row_keeps(t, h_of.get(e["to"], [])))

    @property
    def nodes(self) -> list[str]:
        return list(self.G.nodes)

    def edge(self, a: str, b: str) -> ReportTransition | None:
        return self.transitions.get((a, b))

    def planner_graph(self) -> nx.DiGraph:
        G = nx.DiGraph()
        G.add_nodes_from(self.G.nodes(data=True))
        G.add_edges_from((a, b, d) for a, b, d in self.G.edges(data=True) if d.get("usable", True))
        return G
