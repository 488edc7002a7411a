"""What a verify returns: one ProjectResult per project (status, report, the planner's graph, plan()
and simulate()) and the VerifyResult of a run; load_report reads one back from report.json."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import EXIT_CHECK_FAILED, EXIT_OK, EXIT_USAGE, UsageError, unknown_primitive
from ..plan.planner import hops, lookup_table, plan_graph, shortest_path
from ..report.findings import warning_count
from ..report.read import ReportGraph, load_report as read

if TYPE_CHECKING:
    from ..graph.transition import MotionPrimitiveGraph
    from .stages import CompiledProject

@dataclass
class ProjectResult:
    """Outcome of one project: 'pass', 'fail' or 'error', with its report and written files.

    graph: the networkx DiGraph the planner searches (edges it may take; attributes `class`,
    `duration`, `peak_input`, `hops`); mpg: the full MotionPrimitiveGraph with every oracle grid
    (None for a result read back by load_report); pages: further report files rendered with the
    report (file key -> text, e.g. the 3D playback), written beside it."""

    path: Path
    name: str = ""
    status: str = "error"
    report: dict | None = None
    errors: list[dict] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    mpg: MotionPrimitiveGraph | None = None
    compiled: CompiledProject | None = field(default=None, repr=False)
    pages: dict[str, str] = field(default_factory=dict, repr=False)

    @property
    def warnings(self) -> int:
        """Assumption checks that warn and cross-check disagreements (mpgspec.report.findings)."""
        return warning_count(self.report)

    @property
    def graph(self):
        """The planner's graph: the edges plans and the lookup table may use, edge class as `class`."""
        if self.mpg is not None:
            G = plan_graph(self.mpg).copy()
            for _, _, d in G.edges(data=True):
                d["class"] = d.pop("cls", d.get("class"))
            for _, d in G.nodes(data=True):
                if "cls" in d:
                    d["class"] = d.pop("cls")
            return G
        if self.report is not None:
            return ReportGraph(self.report).planner_graph()
        return None

    def plan(self, source: str, goal: str, weight: str = "duration", robust: bool = False) -> dict:
        """The shortest safe sequence from source to goal: path, cost and each hop with its class and
        the t_A windows to wait for (Class 2); path None (and `why`) when the goal cannot be reached.
        robust: only the edges that withstood the project's uncertainty (its report's robust graph)."""
        if robust:
            if self.report is None or not self.report.get("robust"):
                raise UsageError(f"{self.path}: no robust graph (the project declares no `uncertainty`, or it "
                                 "was not verified)")
            from ..robust.plan import robust_report_graph

            g = robust_report_graph(self.report)
            G, edge = g.planner_graph(), g.edge
        else:
            G = self.graph
            if G is None:
                raise UsageError(f"{self.path}: no verified graph "
                                 f"({'; '.join(e.get('message', '') for e in self.errors)})")
            edge = self.mpg.edge if self.mpg is not None else ReportGraph(self.report).edge
        for n in (source, goal):
            if n not in G:
                raise unknown_primitive(n, G.nodes)
        path, cost = shortest_path(G, source, goal, weight)
        doc = {"from": source, "to": goal, "weight": weight, "path": path, "cost": cost, "hops": hops(edge, path)}
        if path is None:
            from .plan import unreachable

            doc["why"] = unreachable(G, source, goal, weight, robust)
        return doc

    def __repr__(self) -> str:
        """One line: name, status and counts (the report itself is the `report` attribute)."""
        r = self.report or {}
        failed = sum(a.get("status") == "fail" for a in r.get("assertions", []))
        parts = [f"{len(r.get('primitives', []))} primitives", f"{len(r.get('edges', []))} edges",
                 f"{len(r.get('assertions', []))} assertions ({failed} failed)"] if r else []
        parts += [f"{len(self.errors)} errors"] if self.errors else []
        return f"ProjectResult({self.name or self.path!s}: {self.status}{'; ' if parts else ''}{', '.join(parts)})"

    def simulate(self, mode: str = "graph"):
        """Run the project's goal sequence ('naive' or 'graph'); returns the SequenceRun (its
        to_dict() is what the report stores)."""
        if mode not in ("naive", "graph"):
            raise UsageError(f"mode must be 'naive' or 'graph', not {mode!r}")
        from ..execute.sequence import simulate_sequence
        from .reuse import compiled

        cp = self.compiled
        if cp is None:
            from ..spec.loader import load_project

            cp = self.compiled = compiled(load_project(self.path), cache=False)
        if cp.spec.project.sequence is None:
            raise UsageError(f"{cp.spec.path}: the project has no 'sequence'")
        if self.mpg is not None:
            seq = cp.spec.project.sequence
            g, table = self.mpg, lookup_table(self.mpg, seq.weight)
        else:
            g, table = ReportGraph(self.report), self.report["lookup_table"]["next"]
        return simulate_sequence(cp.prims, g, table, cp.spec.project.sequence, cp.settings, mode)

    def _repr_html_(self) -> str:
        from html import escape

        if self.report is None:
            errs = "".join(f"<li>{escape(str(e.get('text', e.get('message', ''))))}</li>" for e in self.errors)
            return f"<div><b>{escape(str(self.path))}</b>: ERROR<ul>{errs}</ul></div>"
        r = self.report
        warns = warning_count(r)
        head = (f"<b>{escape(self.name)}</b>: <b>{escape(self.status.upper())}</b>"
                f"{f' with {warns} warning' + ('s' if warns != 1 else '') if warns else ''} · "
                f"{len(r['primitives'])} primitives · {len(r['edges'])} edges · "
                f"{r.get('timing', {}).get('oracle_calls', '?')} oracle calls")
        rows = "".join(f"<tr><td>{escape(e['from'])}</td><td>{escape(e['to'])}</td><td>{e['class']}</td>"
                       f"<td>{'' if e.get('duration') is None else format(e['duration'], '.3g')}</td>"
                       f"<td>{'yes' if e.get('usable', True) else 'no'}</td></tr>" for e in r["edges"])
        bad = "".join(f"<li>{escape(a['status'].upper())} {escape(a['description'])}: {escape(a['message'])}</li>"
                      for a in r["assertions"] if a["status"] != "pass")
        bad += "".join(f"<li>WARN {escape(w)}</li>" for w in _warning_texts(r))
        files = f"<div>report: {escape(self.files['html'])}</div>" if self.files.get("html") else ""
        from ..report.svg import graph_svg, graphviz_svg

        picture = graphviz_svg(r) or graph_svg(r)
        return (f"<div>{head}{f'<ul>{bad}</ul>' if bad else ''}<div style=\"max-width: 720px\">{picture}</div>"
                f"<details><summary>{len(r['edges'])} edges</summary><table><tr><th>from</th><th>to</th>"
                f"<th>class</th><th>duration (s)</th><th>planner</th></tr>{rows}</table></details>{files}</div>")


def _warning_texts(r: dict) -> list[str]:
    """The report's warnings as the command line words them (findings)."""
    from ..report.findings import disagreements, nominal_only_path, path_text

    out = [f"assumption {c['name']} of {c['primitive']}: {c['message']}" for c in r.get("assumptions", [])
           if c.get("status") == "warn"]
    out += [f"cross-check of the {d['mode']} run: {d['text']}" for d in disagreements(r)]
    bad = nominal_only_path(r)
    return out + ([path_text(bad)] if bad is not None else [])


@dataclass
class VerifyResult:
    """Outcome of a run over several projects; exit_code as the command line's."""

    projects: list[ProjectResult]

    @property
    def exit_code(self) -> int:
        st = {p.status for p in self.projects}
        return EXIT_USAGE if "error" in st else EXIT_CHECK_FAILED if "fail" in st else EXIT_OK

    def __getitem__(self, key: int | str) -> ProjectResult:
        """A project by position or by name."""
        if isinstance(key, str):
            for p in self.projects:
                if p.name == key:
                    return p
            raise KeyError(key)
        return self.projects[key]

    def __repr__(self) -> str:
        return f"VerifyResult(exit_code={self.exit_code}, [{', '.join(map(repr, self.projects))}])"

    def _repr_html_(self) -> str:
        return "".join(p._repr_html_() for p in self.projects)


def _spec_path(spec: Path, folder: Path) -> Path:
    """The project file a report names (a path relative to where verify ran, as written): as it
    stands when it exists from here, else below the nearest folder above the report's that holds it
    (reports/<project>/ beside specs/), so a loaded report simulates from any working folder."""
    if spec.is_absolute() or spec.exists():
        return spec
    for up in folder.resolve().parents:
        if (up / spec).is_file():
            return up / spec
    return spec


def load_report(path) -> ProjectResult:
    """A verified project read back from its report.json (or the folder holding it): report, status,
    the planner's graph, plan(); simulate() compiles the project from the spec path in the report.
    A report that was edited, written with another key or is malformed raises ReportError (exit 2)."""
    p = Path(path)
    report = read(p)
    name = report.get("project", {}).get("name", "")
    folder = p if p.is_dir() else p.parent
    html = folder / "report.html"
    spec = _spec_path(Path(report.get("project", {}).get("path", "")), folder)
    return ProjectResult(spec, name, report.get("status", "error"), report,
                         files={"json": str(p / "report.json" if p.is_dir() else p),
                                **({"html": str(html)} if html.is_file() else {})})


def write_reports(res: VerifyResult, out_dir, progress=None) -> None:
    """Each project's report set into out_dir/<project>/ as a unit; a failure to write makes the
    project an error (exit 2) with the reason, never a PASS."""
    from ..report.files import ReportWriteError, write_project_reports

    for p in res.projects:
        if p.report is None:
            continue
        if progress is not None:
            progress(p.name, "report (JSON, HTML, graph files)", 0, 1)
        try:
            p.files = write_project_reports(p.report, out_dir, p.report["project"]["name"], pages=p.pages)
        except ReportWriteError as e:
            why = str(e)
        except Exception as e:  # noqa: BLE001 - a bug in a writer: this project's error, not the run's end
            why = f"internal error while writing reports: {type(e).__name__}: {e}"
        else:
            continue
        p.status, p.files = "error", {}
        p.errors.append({"code": "MPG400", "file": str(p.path), "message": why, "text": f"{p.path}: MPG400 {why}"})
    if any(p.files for p in res.projects):
        from ..report.index import write_index

        write_index(out_dir)
