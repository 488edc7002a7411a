"""Python API: everything the CLI does, callable from a notebook.

    from mpgspec import api
    res = api.verify("specs/pendulum")            # nothing written unless out_dir is given
    p = res["pendulum"]                           # or res.projects[0]
    p.status, p.report                            # 'pass' and the report dict (as report.json)
    p.plan("Hang", "Balance")                     # the planner's shortest sequence, hop by hop
    p.simulate("graph")                           # the goal sequence through the graph
    p.graph                                       # networkx graph the planner searches
    api.load_report("reports/pendulum")           # the same from what `mpgspec verify` wrote
"""
from __future__ import annotations

import time

import numpy as np
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .certify.roa import RANK, size_regions
from .check.assertions import AssertionResult, evaluate_assertions
from .check.assumptions import AssumptionCheck, check_primitive
from .check.crosscheck import agreement_assertions
from .compile.primitive import CompiledPrimitive, compile_primitive
from .compile.system import compile_system
from .errors import EXIT_CHECK_FAILED, EXIT_OK, EXIT_USAGE, MpgError, SpecError, SpecErrors, UsageError  # noqa: F401
from .execute.crosscheck import CrossCheckResult, crosscheck_runs
from .execute.crosscheck.settings import settings_of as crosscheck_settings
from .execute.sequence import simulate_sequence
from .graph.build import build_graph
from .graph.traces import edge_traces, failure_traces
from .graph.transition import MotionPrimitiveGraph
from .oracle.executors import Executor, InProcess
from .oracle.oracle import CapabilityError, require_capabilities
from .oracle.registry import get_backend
from .plan.planner import lookup_table, shortest_plan
from .report.build import build_report
from .robust.check import check_uncertainty, check_uncertainty_compiled
from .robust.graph import RobustResult, robust_stage
from .settings import OracleSettings
from .spec.loader import ProjectSpec, discover, load_project

__all__ = ["verify", "load_report", "ProjectResult", "VerifyResult", "run_project", "compile_stage", "graph_stage",
           "check_stage", "build", "settings_for", "compile_project", "load_project", "discover",
           "CompiledProject", "VerifiedGraph", "Checks", "EXIT_OK", "EXIT_CHECK_FAILED", "EXIT_USAGE"]

Progress = Callable[[str, str, int, int], None]


@dataclass
class ProjectResult:
    """Outcome of one project: 'pass', 'fail' or 'error', with its report and written files.

    graph: the networkx DiGraph the planner searches (edges it may take; attributes `class`,
    `duration`, `peak_input`, `hops`); mpg: the full MotionPrimitiveGraph with every oracle grid
    (None for a result read back by load_report)."""

    path: Path
    name: str = ""
    status: str = "error"
    report: dict | None = None
    errors: list[dict] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    mpg: MotionPrimitiveGraph | None = None
    compiled: "CompiledProject | None" = field(default=None, repr=False)

    @property
    def graph(self):
        """The planner's graph: the edges plans and the lookup table may use, edge class as `class`."""
        if self.mpg is not None:
            from .plan.planner import plan_graph

            G = plan_graph(self.mpg).copy()
            for _, _, d in G.edges(data=True):
                d["class"] = d.pop("cls", d.get("class"))
            for _, d in G.nodes(data=True):
                if "cls" in d:
                    d["class"] = d.pop("cls")
            return G
        if self.report is not None:
            from .report.read import ReportGraph

            return ReportGraph(self.report).planner_graph()
        return None

    def plan(self, source: str, goal: str, weight: str = "duration") -> dict:
        """The shortest safe sequence from source to goal: path, cost and each hop with its class and
        the t_A windows to wait for (Class 2); path None when the goal cannot be reached."""
        from .report.read import ReportGraph, hops, shortest_path

        G = self.graph
        if G is None:
            raise UsageError(f"{self.path}: no verified graph ({'; '.join(e.get('message', '') for e in self.errors)})")
        for n in (source, goal):
            if n not in G:
                raise UsageError(f"unknown primitive {n!r}; expected one of {', '.join(G.nodes)}")
        path, cost = shortest_path(G, source, goal, weight)
        edge = self.mpg.edge if self.mpg is not None else ReportGraph(self.report).edge
        return {"from": source, "to": goal, "weight": weight, "path": path, "cost": cost, "hops": hops(edge, path)}

    def simulate(self, mode: str = "graph"):
        """Run the project's goal sequence ('naive' or 'graph'); returns the SequenceRun (its
        to_dict() is what the report stores)."""
        if mode not in ("naive", "graph"):
            raise UsageError(f"mode must be 'naive' or 'graph', not {mode!r}")
        cp = self.compiled
        if cp is None:
            spec = load_project(self.path)
            cp = compile_stage(spec, settings_for(spec))
            self.compiled = cp
        if cp.spec.project.sequence is None:
            raise UsageError(f"{cp.spec.path}: the project has no 'sequence'")
        if self.mpg is not None:
            g, table = self.mpg, lookup_table(self.mpg, "duration")
        else:
            from .report.read import ReportGraph

            g, table = ReportGraph(self.report), self.report["lookup_table"]["next"]
        return simulate_sequence(cp.prims, g, table, cp.spec.project.sequence, cp.settings, mode)

    def _repr_html_(self) -> str:
        from html import escape

        if self.report is None:
            errs = "".join(f"<li>{escape(str(e.get('text', e.get('message', ''))))}</li>" for e in self.errors)
            return f"<div><b>{escape(str(self.path))}</b>: ERROR<ul>{errs}</ul></div>"
        r = self.report
        warns = sum(c["status"] == "warn" for c in r.get("assumptions", []))
        head = (f"<b>{escape(self.name)}</b>: <b>{escape(self.status.upper())}</b>"
                f"{f' with {warns} warning' + ('s' if warns != 1 else '') if warns else ''} · "
                f"{len(r['primitives'])} primitives · {len(r['edges'])} edges · "
                f"{r.get('timing', {}).get('oracle_calls', '?')} oracle calls")
        rows = "".join(f"<tr><td>{escape(e['from'])}</td><td>{escape(e['to'])}</td><td>{e['class']}</td>"
                       f"<td>{'' if e.get('duration') is None else format(e['duration'], '.3g')}</td>"
                       f"<td>{'yes' if e.get('usable', True) else 'no'}</td></tr>" for e in r["edges"])
        bad = "".join(f"<li>{escape(a['status'].upper())} {escape(a['description'])}: {escape(a['message'])}</li>"
                      for a in r["assertions"] if a["status"] != "pass")
        files = f"<div>report: {escape(self.files['html'])}</div>" if self.files.get("html") else ""
        return (f"<div>{head}{f'<ul>{bad}</ul>' if bad else ''}<table><tr><th>from</th><th>to</th><th>class</th>"
                f"<th>duration (s)</th><th>planner</th></tr>{rows}</table>{files}</div>")


@dataclass
class VerifyResult:
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

    def _repr_html_(self) -> str:
        return "".join(p._repr_html_() for p in self.projects)


def load_report(path) -> ProjectResult:
    """A verified project read back from its report.json (or the folder holding it): report, status,
    the planner's graph, plan(); simulate() compiles the project from the spec path in the report."""
    from .report.read import load_report as read

    p = Path(path)
    report = read(p)
    name = report.get("project", {}).get("name", "")
    html = (p if p.is_dir() else p.parent) / "report.html"
    return ProjectResult(Path(report.get("project", {}).get("path", "")), name, report.get("status", "error"), report,
                         files={"json": str(p / "report.json" if p.is_dir() else p),
                                **({"html": str(html)} if html.is_file() else {})})


def settings_for(spec: ProjectSpec, overrides: dict | None = None) -> OracleSettings:
    """Oracle settings of a project: its accuracy preset, then explicit overrides."""
    o = spec.project.oracle
    s = OracleSettings.with_accuracy(o.accuracy, horizon=o.horizon, dt=o.dt, method=o.method,
                                     h_tolerance=o.h_tolerance, error=o.error)
    s = s.replace(**(overrides or {}))
    try:
        get_backend(s.method)  # an unknown method is a spec error, not evidence
    except UsageError:
        if "method" in (overrides or {}):  # named on the command line, not in the spec
            raise
        import difflib

        from .oracle.registry import backends

        names = sorted(backends())
        near = difflib.get_close_matches(s.method, names, n=1)
        raise SpecError("unknown oracle method", location=spec.locate(("oracle", "method")), key="oracle.method",
                        expected="one of " + ", ".join(names), found=repr(s.method),
                        hint=f"did you mean {near[0]!r}?" if near else "", code="MPG104") from None
    _check_budget(spec, s)
    return s


MAX_STEPS = 1_000_000
"""Most RK4 steps one oracle rollout may take (horizon / dt at the finest preset)."""
MAX_GRID = 10_000
"""Most clock samples of one grid axis."""
MAX_CALLS = 1_000_000
"""Most oracle calls Algorithm 1 may make for one project (sum over ordered pairs of t_A x t_B)."""


def _check_budget(spec: ProjectSpec, s: OracleSettings) -> None:
    """Refuse, located, oracle settings that could not finish: too many steps or too many calls."""
    o = spec.project.oracle
    if not (np.isfinite(s.horizon) and np.isfinite(s.dt) and s.dt > 0):
        raise SpecError("the oracle's horizon and step must be finite", location=spec.locate(("oracle",)),
                        key="oracle.horizon / oracle.dt", expected="finite numbers, dt > 0",
                        found=f"horizon {s.horizon:g}, dt {s.dt:g}", code="MPG104")
    steps = s.horizon / s.dt
    if steps > MAX_STEPS:
        raise SpecError("horizon / dt needs too many steps", location=spec.locate(("oracle", "dt")), key="oracle.dt",
                        expected=f"at most {MAX_STEPS:,} steps per rollout (accuracy presets divide dt further)",
                        found=f"{steps:,.0f} steps ({s.horizon:g} s / {s.dt:g} s)", code="MPG104")
    for key in ("t_A", "t_B"):
        n = getattr(o.grid, key)
        if n > MAX_GRID:
            raise SpecError("grid too fine", location=spec.locate(("oracle", "grid", key)), key=f"oracle.grid.{key}",
                            expected=f"at most {MAX_GRID:,} clock samples", found=f"{n:,}", code="MPG104")
    sizes = []
    for inst in spec.primitives:
        g = inst.spec.grid
        n_a = (g.t_A if g else o.grid.t_A) if inst.spec.class_.value != "fixed" else 1
        n_b = (g.t_B if g else o.grid.t_B) if inst.spec.class_.value != "fixed" else 1
        sizes.append((n_a, n_b))
    calls = sum(a * b for i, (a, _) in enumerate(sizes) for j, (_, b) in enumerate(sizes) if i != j)
    if calls > MAX_CALLS:
        raise SpecError("the oracle grids need too many oracle calls", location=spec.locate(("oracle", "grid")),
                        key="oracle.grid", expected=f"at most {MAX_CALLS:,} calls (sum over pairs of t_A x t_B)",
                        found=f"{calls:,} calls", code="MPG104")


def compile_project(spec: ProjectSpec) -> dict[str, CompiledPrimitive]:
    """System and every primitive of a project as CasADi Functions, keyed by node name."""
    sys = compile_system(spec)
    return {inst.name: compile_primitive(inst, sys) for inst in spec.primitives}


@dataclass
class CompiledProject:
    """Compile stage: the project's closed loops with their regions of attraction sized."""

    spec: ProjectSpec
    settings: OracleSettings
    prims: dict[str, CompiledPrimitive]
    roa: dict
    timing: dict


@dataclass
class VerifiedGraph:
    """Graph stage: Algorithm 1's graph with its evidence, and the rollouts the report shows."""

    graph: MotionPrimitiveGraph
    edge_traces: list[dict]
    failure_traces: list[dict]
    timing: dict


@dataclass
class Checks:
    """Check stage: plans, sequence runs, assertions and Definition-1 assumptions, with the verdict."""

    plans: list
    table: dict
    runs: dict
    assertions: list[AssertionResult]
    assumptions: list
    status: str
    timing: dict
    robust: RobustResult | None = None  # the robust graph when the project declares `uncertainty`
    crosscheck: CrossCheckResult | None = None  # the runs replayed in MuJoCo when the project asks


def compile_stage(spec: ProjectSpec, settings: OracleSettings, progress: Progress | None = None,
                  memo=None) -> CompiledProject:
    """Closed loops of every primitive, refused early when the backend cannot run them; E sized
    (memo: mpgspec.oracle.cache.Memo, to reuse the sizing of unchanged primitives)."""
    t0 = time.perf_counter()
    check_uncertainty(spec)
    crosscheck_settings(spec)  # a cross-check that cannot run is a spec error before anything is built
    if progress:
        progress(spec.name, "compile (closed loops as CasADi functions)", 0, len(spec.primitives))
    prims = compile_project(spec)
    check_uncertainty_compiled(spec, prims)
    _check_capabilities(spec, settings, prims)
    for p in prims.values():  # a control period must be a whole number of oracle steps
        if p.sampled is not None:
            p.sampled.steps(settings.dt)
    t1 = time.perf_counter()
    if progress:
        progress(spec.name, "regions of attraction", 0, len(prims))
    roa = size_regions(spec, prims, memo)
    return CompiledProject(spec, settings, prims, roa,
                           {"compile_s": t1 - t0, "roa_s": time.perf_counter() - t1})


def graph_stage(cp: CompiledProject, progress: Progress | None = None,
                executor: Executor | None = None) -> VerifiedGraph:
    """Algorithm 1 through the executor, then the traces of every edge and of the closest failures."""
    spec, prims, settings = cp.spec, cp.prims, cp.settings
    executor = executor or InProcess()
    cb = (lambda what, i, n: progress(spec.name, what, i, n)) if progress else None
    before = dict(getattr(executor, "stats", {}))
    t0 = time.perf_counter()
    if progress:
        progress(spec.name, "oracle (JIT-compiling the rollouts unless cached)", 0, 0)
    g = build_graph(prims, settings, spec.project.oracle.grid.t_A, spec.project.oracle.grid.t_B, cb, executor)
    t1 = time.perf_counter()
    names = list(prims)
    pairs = [(a, b) for a in names for b in names if a != b]
    if progress:
        progress(spec.name, "traces of the edges and failed pairs", 0, 0)
    edges, failures = edge_traces(g, prims, settings), failure_traces(g, prims, settings, pairs)
    calls = sum(len(tr.t_A) * len(tr.t_B) for tr in g.transitions.values())
    timing = {"graph_s": t1 - t0, "oracle_calls": calls, "oracle_calls_per_s": calls / max(t1 - t0, 1e-9),
              "traces_s": time.perf_counter() - t1,
              **{k: v - before.get(k, 0) for k, v in getattr(executor, "stats", {}).items()}}  # this project's
    return VerifiedGraph(g, edges, failures, timing)


def check_stage(cp: CompiledProject, vg: VerifiedGraph, progress: Progress | None = None, memo=None) -> Checks:
    """Plans, the goal sequence naive and through the graph, assertions and assumptions."""
    spec, prims, settings, g = cp.spec, cp.prims, cp.settings, vg.graph
    t0 = time.perf_counter()
    names = list(prims)
    plans = [shortest_plan(g, a, b, "duration") for a in names for b in names if a != b]
    table = {"weight": "duration", "next": lookup_table(g, "duration")}
    runs = {}
    if spec.project.sequence is not None:
        if progress:
            progress(spec.name, "sequence", 0, 2)
        for mode in ("naive", "graph"):
            runs[mode] = simulate_sequence(prims, g, table["next"], spec.project.sequence, settings, mode)
    checks = evaluate_assertions(spec.project.assertions, g, runs)
    checks += roa_requirements(spec, cp.roa, start=len(checks))
    t_x = time.perf_counter()
    xcs, xc = crosscheck_settings(spec), None
    if xcs is not None and runs:
        if progress:
            progress(spec.name, f"cross-check ({xcs.simulator})", 0, len(xcs.runs))
        xc = crosscheck_runs(prims, runs, spec.project.sequence.duration, xcs, settings.h_tolerance, memo=memo)
        if xcs.require_agreement:
            checks += agreement_assertions(xc, start=len(checks))
    t1 = time.perf_counter()
    robust = robust_stage(cp, vg, progress, memo)
    if robust is not None:
        for a in robust.assertions:
            a.index = len(checks)
            checks.append(a)
    t2 = time.perf_counter()
    if progress:
        progress(spec.name, "assumptions (Definition 1)", 0, len(prims))
    assumed = check_assumptions(prims, spec.project.assumptions, memo)
    st = [c.status for c in checks] + [a.status for a in assumed]
    status = "error" if "error" in st else "fail" if "fail" in st else "pass"
    return Checks(plans, table, runs, checks, assumed, status,
                  {"plan_execute_s": t_x - t0, **({"crosscheck_s": t1 - t_x} if xc is not None else {}),
                   "robust_s": t2 - t1, "assumptions_s": time.perf_counter() - t2}, robust, xc)


def build(spec: ProjectSpec, settings: OracleSettings, progress: Progress | None = None,
          executor: Executor | None = None) -> tuple[CompiledProject, VerifiedGraph]:
    """Compile and run Algorithm 1; a caching executor also lends its memo to the sizing of E."""
    cp = compile_stage(spec, settings, progress, getattr(executor, "memo", None))
    return cp, graph_stage(cp, progress, executor)


def _check_capabilities(spec: ProjectSpec, settings: OracleSettings, prims: dict[str, CompiledPrimitive]) -> None:
    """A backend that cannot run a primitive is the project's error, located at oracle.method."""
    backend = get_backend(settings.method)
    for p in prims.values():
        try:
            require_capabilities(backend, p)
        except CapabilityError as err:
            raise SpecError(str(err), location=spec.locate(("oracle", "method")), key="oracle.method",
                            expected="a backend with the capabilities " + ", ".join(sorted(p.needs)),
                            found=repr(settings.method), code="MPG120") from None


def roa_requirements(spec: ProjectSpec, roa: dict, start: int) -> list[AssertionResult]:
    """`roa.require` of each primitive as an assertion on the level of evidence of its radius."""
    out = []
    for inst in spec.primitives:
        need = inst.spec.roa.require
        if need is None:
            continue
        rec = roa[inst.name]
        ok = RANK[rec.level] >= RANK[need]
        out.append(AssertionResult(start + len(out), "roa_level", f"E of {inst.name} is {need}",
                                   "pass" if ok else "fail", f"{rec.level} by {rec.method}, r = {rec.radius:.4g}"))
    return out


def check_assumptions(prims: dict[str, CompiledPrimitive], severity: dict, memo=None) -> list:
    """Definition-1 checks of every primitive; a failure counts as the project's severity says.

    memo (optional) keeps the checks of each primitive by its content hash."""
    out = []
    for p in prims.values():
        key = memo.key("assumptions", p.digest()) if memo else None
        known = memo.get(key) if memo else None
        checks = [AssumptionCheck(**c) for c in known] if known is not None else check_primitive(p)
        if memo and known is None:
            memo.put(key, [c.to_dict() for c in checks])
        for c in checks:
            sev = severity.get(c.name, "fail")
            if sev == "off":
                continue
            if c.status == "fail" and sev == "warn":
                c.status, c.message = "warn", c.message + " (reported as a warning by the project)"
            out.append(c)
    return out


def run_project(path: Path, out_dir: Path | None, overrides: dict | None = None,
                progress: Progress | None = None, formats: tuple[str, ...] = ("json", "html", "dot", "graphml"),
                executor: Executor | None = None, allow_paths=None) -> ProjectResult:
    """Verify one project file and write its reports under out_dir/<project>/.

    allow_paths: folders outside the project folder that files named by the spec may lie in.
    """
    res = ProjectResult(Path(path))
    try:
        if progress:
            progress(Path(path).parent.name or str(path), "load", 0, 1)
        spec = load_project(path, allow_paths=allow_paths)
        res.name = spec.name
        settings = settings_for(spec, overrides)
        cp, vg = build(spec, settings, progress, executor)
    except SpecErrors as e:
        res.errors = [x.to_dict() | {"text": x.format()} for x in e.errors]
        return res
    except (SpecError, MpgError) as e:
        res.errors = [e.to_dict() | {"text": e.format()} if isinstance(e, SpecError) else
                      {"code": e.code, "message": str(e), "text": f"{path}: {e.code} {e}"}]
        return res
    res.mpg = vg.graph
    try:
        return _finish_project(res, cp, vg, out_dir, formats, progress, executor)
    except MpgError as err:  # e.g. the reports could not be written: this project's error
        res.status = "error"
        res.errors = [{"code": err.code, "message": str(err), "text": f"{path}: {err.code} {err}"}]
        return res
    except Exception as err:  # a bug after the graph was built: this project's error, not the end of the run
        res.status = "error"
        res.errors = [{"code": "MPG900", "message": f"internal error: {type(err).__name__}: {err}",
                       "text": f"{path}: MPG900 internal error: {type(err).__name__}: {err}"}]
        return res


def _digest(path) -> str | None:
    from .spec.digest import spec_digest

    try:
        return spec_digest(path)
    except OSError:
        return None


def _where(loc) -> dict | None:
    if loc is None or not getattr(loc, "line", 0):
        return None
    return {"file": str(loc.file), "line": int(loc.line), "column": int(loc.column or 0)}


def _locate_checks(spec: ProjectSpec, report: dict) -> None:
    """The spec position of each assertion and assumption check (for CI annotations), as `location`."""
    n = len(spec.project.assertions)

    def prim(name, *key):
        try:
            return spec.primitive(name).locate(key)
        except (KeyError, LookupError, TypeError, ValueError):
            return None

    for a in report["assertions"]:
        loc = None
        try:
            if a["index"] < n:
                loc = spec.locate(("assertions", a["index"]))
            elif a["kind"] == "roa_level":
                loc = prim(a["description"].removeprefix("E of ").rsplit(" is ", 1)[0], "roa")
            elif a["kind"] == "crosscheck":
                loc = spec.locate(("crosscheck", "require_agreement"))
        except (KeyError, LookupError, TypeError, ValueError):
            loc = None
        if (w := _where(loc)) is not None:
            a["location"] = w
    for c in report.get("assumptions", []):
        w = _where(prim(c["primitive"], "roa") if c["name"] == "roa_in_safe_set" else prim(c["primitive"]))
        if w is not None:
            c["location"] = w


def _finish_project(res: ProjectResult, cp: CompiledProject, vg: VerifiedGraph, out_dir, formats,
                    progress: Progress | None, executor: Executor | None = None):
    """Checks and reports of a project whose graph is built."""
    ch = check_stage(cp, vg, progress, getattr(executor, "memo", None))
    timing = {**cp.timing, **vg.timing, **ch.timing}
    report = build_report(spec=cp.spec, prims=cp.prims, graph=vg.graph, settings=cp.settings, plans=ch.plans,
                          table=ch.table, assertions=ch.assertions, runs=ch.runs, failures=vg.failure_traces,
                          timing=timing, status=ch.status, assumptions=ch.assumptions, roa=cp.roa,
                          edge_series=vg.edge_traces, digest=_digest(cp.spec.path),
                          robust=ch.robust.to_dict() if ch.robust is not None else None,
                          crosscheck=ch.crosscheck.to_dict() if ch.crosscheck is not None else None)
    _locate_checks(cp.spec, report)
    res.status, res.report, res.compiled = ch.status, report, cp
    if out_dir is not None:
        from .report.files import write_reports

        res.files = write_reports(report, vg.graph, Path(out_dir) / cp.spec.name, formats)
    return res


def verify(paths, out_dir: str | Path | None = None, overrides: dict | None = None,
           progress: Progress | None = None, executor: Executor | None = None,
           allow_paths=None) -> VerifyResult:
    """Verify every project found under `paths`; reports go to out_dir (None: write nothing).

    executor: where oracle calls run (mpgspec.oracle.executors: InProcess, ProcessPool,
    DaskExecutor; make_executor(jobs, dask) picks one); in this process when omitted.
    allow_paths: folders outside each project folder that files named by specs may lie in
    (paths a spec names must otherwise resolve inside its project folder).
    """
    files: list[Path] = []
    for p in [paths] if isinstance(paths, (str, Path)) else paths:
        files.extend(discover(p))
    return VerifyResult([run_project(f, Path(out_dir) if out_dir else None, overrides, progress, executor=executor,
                                     allow_paths=allow_paths)
                         for f in files])
