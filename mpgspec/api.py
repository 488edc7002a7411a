"""Python API: everything the CLI does, callable from a notebook.

    result = mpgspec.api.verify(["specs/"], out_dir="reports")
    result.exit_code, result.projects[0].report
"""
from __future__ import annotations

import time
from functools import partial
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .certify.roa import RANK, apply_radii, size_regions
from .check.assertions import AssertionResult, evaluate_assertions
from .check.assumptions import check_primitive
from .compile.primitive import CompiledPrimitive, compile_primitive
from .compile.system import compile_system
from .errors import EXIT_CHECK_FAILED, EXIT_OK, EXIT_USAGE, MpgError, SpecError, SpecErrors, UsageError  # noqa: F401
from .execute.sequence import simulate_sequence
from .graph.build import build_graph
from .oracle.oracle import CapabilityError, needs, require_capabilities
from .oracle.registry import get_backend
from .graph.transition import MotionPrimitiveGraph
from .plan.planner import lookup_table, shortest_plan
from .report.build import build_report, edge_traces, failure_traces
from .settings import OracleSettings
from .spec.loader import ProjectSpec, discover, load_project

Progress = Callable[[str, str, int, int], None]


@dataclass
class ProjectResult:
    """Outcome of one project: 'pass', 'fail' or 'error', with its report and written files."""

    path: Path
    name: str = ""
    status: str = "error"
    report: dict | None = None
    errors: list[dict] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    graph: MotionPrimitiveGraph | None = None


@dataclass
class VerifyResult:
    projects: list[ProjectResult]

    @property
    def exit_code(self) -> int:
        st = {p.status for p in self.projects}
        return EXIT_USAGE if "error" in st else EXIT_CHECK_FAILED if "fail" in st else EXIT_OK


def settings_for(spec: ProjectSpec, overrides: dict | None = None) -> OracleSettings:
    """Oracle settings of a project: its accuracy preset, then explicit overrides."""
    o = spec.project.oracle
    s = OracleSettings.with_accuracy(o.accuracy, horizon=o.horizon, dt=o.dt, method=o.method,
                                     h_tolerance=o.h_tolerance)
    s = s.replace(**(overrides or {}))
    get_backend(s.method)  # an unknown method is a usage error, not evidence
    return s


def compile_project(spec: ProjectSpec) -> dict[str, CompiledPrimitive]:
    """System and every primitive of a project as CasADi Functions, keyed by node name."""
    sys = compile_system(spec)
    return {inst.name: compile_primitive(inst, sys) for inst in spec.primitives}


def compile_path(path: str | Path, radii: dict[str, float] | None = None) -> dict[str, CompiledPrimitive]:
    """Load and compile a project file with the given E radii (a picklable factory for workers)."""
    spec = load_project(path)
    prims = compile_project(spec)
    apply_radii(prims, radii or {})
    return prims


def build(spec: ProjectSpec, settings: OracleSettings, progress: Progress | None = None, workers: int = 1):
    """Compile and run Algorithm 1; returns (primitives, graph, oracles, timing)."""
    t0 = time.perf_counter()
    prims = compile_project(spec)
    _check_capabilities(spec, settings, prims)
    t1 = time.perf_counter()
    if progress:
        progress(spec.name, "regions of attraction", 0, len(prims))
    roa = size_regions(spec, prims)
    t2 = time.perf_counter()
    oracles: dict = {}
    cb = (lambda what, i, n: progress(spec.name, what, i, n)) if progress else None
    radii = {n: r.radius for n, r in roa.items()}
    g = build_graph(prims, settings, spec.project.oracle.grid.t_A, spec.project.oracle.grid.t_B, cb, oracles,
                    workers=workers, factory=partial(compile_path, spec.path, radii))
    t3 = time.perf_counter()
    calls = sum(len(tr.t_A) * len(tr.t_B) for tr in g.transitions.values())
    timing = {"compile_s": t1 - t0, "roa_s": t2 - t1, "graph_s": t3 - t2, "oracle_calls": calls,
              "oracle_calls_per_s": calls / max(t3 - t2, 1e-9)}
    return prims, g, oracles, timing, roa


def _check_capabilities(spec: ProjectSpec, settings: OracleSettings, prims: dict[str, CompiledPrimitive]) -> None:
    """A backend that cannot run a primitive is the project's error, located at oracle.method."""
    backend = get_backend(settings.method)
    for p in prims.values():
        try:
            require_capabilities(backend, p)
        except CapabilityError as err:
            raise SpecError(str(err), location=spec.locate(("oracle", "method")), key="oracle.method",
                            expected="a backend with the capabilities " + ", ".join(sorted(needs(p))),
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


def check_assumptions(prims: dict[str, CompiledPrimitive], severity: dict) -> list:
    """Definition-1 checks of every primitive; a failure counts as the project's severity says."""
    out = []
    for p in prims.values():
        for c in check_primitive(p):
            sev = severity.get(c.name, "fail")
            if sev == "off":
                continue
            if c.status == "fail" and sev == "warn":
                c.status, c.message = "warn", c.message + " (reported as a warning by the project)"
            out.append(c)
    return out


def run_project(path: Path, out_dir: Path | None, overrides: dict | None = None,
                progress: Progress | None = None, formats: tuple[str, ...] = ("json", "html", "dot", "graphml"),
                workers: int = 1) -> ProjectResult:
    """Verify one project file and write its reports under out_dir/<project>/."""
    res = ProjectResult(Path(path))
    try:
        spec = load_project(path)
        res.name = spec.name
        settings = settings_for(spec, overrides)
        prims, g, oracles, timing, roa = build(spec, settings, progress, workers)
    except SpecErrors as e:
        res.errors = [x.to_dict() | {"text": x.format()} for x in e.errors]
        return res
    except (SpecError, MpgError) as e:
        res.errors = [e.to_dict() | {"text": e.format()} if isinstance(e, SpecError) else
                      {"code": e.code, "message": str(e), "text": f"{path}: {e.code} {e}"}]
        return res
    res.graph = g
    try:
        return _finish_project(res, spec, settings, prims, g, oracles, timing, roa, out_dir, formats, progress)
    except Exception as err:  # a bug after the graph was built: this project's error, not the end of the run
        res.errors = [{"code": "MPG900", "message": f"internal error: {type(err).__name__}: {err}",
                       "text": f"{path}: MPG900 internal error: {type(err).__name__}: {err}"}]
        return res


def _finish_project(res: ProjectResult, spec, settings, prims, g, oracles, timing, roa, out_dir, formats,
                    progress: Progress | None):
    """Plans, sequences, checks and reports of a project whose graph is built."""
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
    checks += roa_requirements(spec, roa, start=len(checks))
    timing["plan_execute_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    assumed = check_assumptions(prims, spec.project.assumptions)
    timing["assumptions_s"] = time.perf_counter() - t0
    st = [c.status for c in checks] + [a.status for a in assumed]
    status = "error" if "error" in st else "fail" if "fail" in st else "pass"
    pairs = [(a, b) for a in names for b in names if a != b]
    failures = failure_traces(g, prims, settings, oracles, pairs)
    edge_series = edge_traces(g, prims, settings, oracles)
    report = build_report(spec=spec, prims=prims, graph=g, settings=settings, plans=plans, table=table,
                          assertions=checks, runs=runs, failures=failures, timing=timing, status=status,
                          assumptions=assumed, roa=roa, edge_series=edge_series)
    res.status, res.report = status, report
    if out_dir is not None:
        from .report.files import write_reports

        res.files = write_reports(report, g, Path(out_dir) / spec.name, formats)
    return res


def verify(paths, out_dir: str | Path | None = "reports", overrides: dict | None = None,
           progress: Progress | None = None, workers: int = 1) -> VerifyResult:
    """Verify every project found under `paths`; reports go to out_dir (None: write nothing)."""
    files: list[Path] = []
    for p in [paths] if isinstance(paths, (str, Path)) else paths:
        files.extend(discover(p))
    return VerifyResult([run_project(f, Path(out_dir) if out_dir else None, overrides, progress, workers=workers)
                         for f in files])
