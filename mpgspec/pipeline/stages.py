"""The stages of a build, each with its typed result: compile (closed loops as CasADi Functions, E
sized), graph (Algorithm 1 and the traces the report shows), checks (plans, sequence runs,
assertions, cross-check, robust graph, Definition-1 assumptions and the verdict)."""
from __future__ import annotations

import dataclasses
import difflib
import time
from dataclasses import dataclass

from ..certify.roa import size_regions
from ..check.assertions import AssertionResult, evaluate_assertions, roa_requirements
from ..check.crosscheck import agreement_assertions
from ..check.severity import assumptions_stage
from ..compile.primitive import CompiledPrimitive, compile_primitive
from ..compile.system import compile_system
from ..errors import SpecError
from ..execute.crosscheck import CrossCheckResult, runs_stage, variants_stage
from ..execute.crosscheck.executor import ExecutorPlan
from ..execute.crosscheck.settings import settings_of as crosscheck_settings, variants_of
from ..execute.sequence import SequenceRun, simulate_sequence
from ..graph.build import build_graph
from ..graph.certified import certify_windows
from ..graph.traces import traces_stage
from ..graph.transition import MotionPrimitiveGraph, family
from ..oracle.executors import Executor, InProcess
from ..oracle.joint import Map, concurrently, run, together
from ..oracle.looplib import build_all as build_loop_libraries
from ..oracle.oracle import CapabilityError, require_capabilities
from ..oracle.registry import get_backend
from ..oracle.tasks import Failed
from ..plan.planner import lookup_table, shortest_plan
from ..progress import Progress, of_project
from ..spec.uncertainty_refs import check_uncertainty, check_uncertainty_compiled
from ..robust.from_roa import check_from_roa, from_roa_samples
from ..robust.graph import RobustResult, prefetch_robust, robust_steps
from ..settings import OracleSettings
from ..spec.loader import ProjectSpec
from ..spec.project import asserted_edges

def compile_project(spec: ProjectSpec) -> dict[str, CompiledPrimitive]:
    """System and every primitive of a project as CasADi Functions, keyed by node name."""
    sys = compile_system(spec)
    return {inst.name: compile_primitive(inst, sys) for inst in spec.primitives}


def _check_keep(spec: ProjectSpec, prims: dict[str, CompiledPrimitive]) -> None:
    """A located SpecError for a family in sequence.keep that no primitive's safe set has."""
    seq = spec.project.sequence
    known = sorted({family(h) for p in prims.values() for h in p.h_names})
    for k in (seq.keep or {}) if seq is not None else {}:
        if k not in known:
            near = difflib.get_close_matches(k, known, n=1)
            raise SpecError("unknown safety function family", location=spec.locate(("sequence", "keep", k)),
                            key=f"sequence.keep.{k[:60]}", expected=("one of " + ", ".join(known))[:300],
                            found=repr(k[:60]), hint=f"did you mean {near[0]!r}?" if near else "", code="MPG304")


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
                  memo=None, executor: Executor | None = None) -> CompiledProject:
    """Closed loops of every primitive, refused early when the backend cannot run them; E sized
    (memo: mpgspec.oracle.cache.Memo, to reuse the sizing of unchanged primitives) on the
    executor's workers (in this process when omitted)."""
    t0 = time.perf_counter()
    check_uncertainty(spec)
    xcs = crosscheck_settings(spec)  # a cross-check that cannot run is a spec error before anything is built
    if xcs is not None:
        variants_of(spec, xcs)
    if progress:
        progress(spec.name, "compile (closed loops as CasADi functions)", 0, len(spec.primitives))
    prims = compile_project(spec)
    check_uncertainty_compiled(spec, prims)
    _check_keep(spec, prims)
    _check_capabilities(spec, settings, prims)
    for p in prims.values():  # a control period must be a whole number of oracle steps
        if p.sampled is not None:
            p.sampled.steps(settings.dt)
    t1 = time.perf_counter()
    if progress:
        progress(spec.name, "regions of attraction", 0, len(prims))
    cb = of_project(progress, spec.name)
    roa = size_regions(spec, prims, memo, executor, cb)
    return CompiledProject(spec, settings, prims, roa,
                           {"compile_s": t1 - t0, "roa_s": time.perf_counter() - t1})


def graph_stage(cp: CompiledProject, progress: Progress | None = None,
                executor: Executor | None = None) -> VerifiedGraph:
    """Algorithm 1 through the executor, then the traces of every edge and of the closest failures
    (one map on the executor)."""
    spec, prims, settings = cp.spec, cp.prims, cp.settings
    executor = executor or InProcess()
    cb = of_project(progress, spec.name)
    before = dict(getattr(executor, "stats", {}))
    t0 = time.perf_counter()
    if settings.jit:  # the large closed loops' libraries, side by side, before anything forks
        build_loop_libraries(prims.values())
    prefetch_robust(spec, prims, settings, getattr(executor, "memo", None))  # gcc beside the oracle
    if progress:
        progress(spec.name, "oracle (JIT-compiling the rollouts unless cached)", 0, 0)
    recheck = asserted_edges(spec.project.assertions) if getattr(executor, "verify", 0) > 0 else frozenset()
    g = build_graph(prims, settings, spec.project.oracle.grid.t_A, spec.project.oracle.grid.t_B, cb, executor,
                    recheck)
    if settings.method == "validated":  # proofs between the grid points of t_A
        if progress:
            progress(spec.name, "certified windows (validated integration over t_A intervals)", 0, 0)
        certify_windows(g, prims, settings, executor, cb)
    samples = from_roa_samples(spec)
    t_roa = time.perf_counter()
    counts = sorted({n for n in samples.values() if n})
    if counts:
        if progress:
            many = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
            progress(spec.name, f"switches from E_A's boundary ({many} samples a row)", 0, 0)
        seq = spec.project.sequence
        from_roa_calls = check_from_roa(g, prims, settings, samples, executor, cb, seq.switch if seq else "first",
                                        seq.reserve if seq else None, seq.keep if seq else None)
    t1 = time.perf_counter()
    names = list(prims)
    pairs = [(a, b) for a in names for b in names if a != b]
    if progress:
        progress(spec.name, "traces of the edges and failed pairs", 0, 0)
    memo = getattr(executor, "memo", None)
    edges, failures = run(traces_stage(g, prims, settings, pairs, memo), executor, cb)
    calls = sum(len(tr.t_A) * len(tr.t_B) for tr in g.transitions.values())
    timing = {"graph_s": t1 - t0, **({"from_roa_s": t1 - t_roa, "from_roa_calls": from_roa_calls} if counts else {}),
              "oracle_calls": calls, "oracle_calls_per_s": calls / max(t1 - t0, 1e-9),
              "traces_s": time.perf_counter() - t1,
              **{k: v - before.get(k, 0) for k, v in getattr(executor, "stats", {}).items()}}  # this project's
    return VerifiedGraph(g, edges, failures, timing)


def check_stage(cp: CompiledProject, vg: VerifiedGraph, progress: Progress | None = None, memo=None,
                executor: Executor | None = None) -> Checks:
    """Plans, the goal sequence naive and through the graph, assertions and assumptions. The
    sequence's runs go first (the cross-check replays them); then the cross-check, the robust stage
    and the primitives' Definition 1 checks, independent of each other, run side by side through
    the executor (mpgspec.oracle.joint: their maps merged, so one stage's last item never leaves the
    other cores idle), each computed as it would be alone (in this process when the executor is
    omitted). Their timings overlap: each is the time from the start of the checks until that
    stage was done; checks_s is the whole."""
    spec, prims, g = cp.spec, cp.prims, vg.graph
    executor = executor or InProcess()
    cb = of_project(progress, spec.name)
    t0 = time.perf_counter()
    names = list(prims)
    plans = [shortest_plan(g, a, b, "duration") for a in names for b in names if a != b]
    weight = spec.project.sequence.weight if spec.project.sequence is not None else "duration"
    switch = spec.project.sequence.switch if spec.project.sequence is not None else "first"
    table = {"weight": weight, "switch": switch, "next": lookup_table(g, weight)}
    if spec.project.sequence is not None and spec.project.sequence.reserve is not None:
        table["reserve"] = float(spec.project.sequence.reserve)
    if spec.project.sequence is not None and spec.project.sequence.keep:
        table["keep"] = {k: float(v) for k, v in spec.project.sequence.keep.items()}
    runs = {}
    if spec.project.sequence is not None:
        if progress:
            progress(spec.name, "sequence", 0, 2)
        runs = run(_sequence_runs(cp, g, table["next"], memo), executor, cb)
    checks = evaluate_assertions(spec.project.assertions, g, runs)
    checks += roa_requirements(spec, cp.roa, start=len(checks))
    timing: dict = {"plan_execute_s": time.perf_counter() - t0}

    def timed(name: str, stage):
        out = yield from stage
        timing[name] = time.perf_counter() - t0
        return out

    xcs = crosscheck_settings(spec) if runs else None
    parts = {"robust": timed("robust_s", robust_steps(cp, vg, progress, memo, executor.workers)),
             "assumptions": timed("assumptions_s", assumptions_stage(prims, spec.project.assumptions, memo, cp.roa))}
    if xcs is not None:
        parts["crosscheck"] = timed("crosscheck_s", _crosscheck(cp, g, table, runs, xcs, progress, memo))
    done = together(parts, executor, cb)
    xc, robust, assumed = done.get("crosscheck"), done["robust"], done["assumptions"]
    if xc is not None and xcs.require_agreement:
        checks += agreement_assertions(xc, start=len(checks))
    if robust is not None:
        for a in robust.assertions:
            a.index = len(checks)
            checks.append(a)
    st = [c.status for c in checks] + [a.status for a in assumed]
    status = "error" if "error" in st else "fail" if "fail" in st else "pass"
    timing["checks_s"] = time.perf_counter() - t0
    return Checks(plans, table, runs, checks, assumed, status, timing, robust, xc)


def _crosscheck(cp: CompiledProject, g: MotionPrimitiveGraph, table: dict, runs: dict, xcs, progress, memo):
    """The cross-check as a stage: the sequence's runs replayed, the executor on the simulator's
    state and the variants, side by side."""
    spec, prims, settings = cp.spec, cp.prims, cp.settings
    if progress:
        progress(spec.name, f"cross-check ({xcs.simulator})", 0, len(xcs.runs))
    plan = ExecutorPlan.of(g, table["next"], spec.project.sequence, prims) if "graph" in runs else None
    duration = spec.project.sequence.duration
    variants = variants_of(spec, xcs) if "graph" in runs else []
    both = yield from concurrently({
        "runs": runs_stage(prims, runs, duration, xcs, settings.h_tolerance, memo=memo, plan=plan),
        "variants": variants_stage(prims, runs.get("graph"), duration, variants, plan, settings.h_tolerance, memo)})
    xc = both["runs"]
    xc.variants = both["variants"]
    return xc


SEQUENCE_RECORD = 4
"""Layout of the memoised goal-sequence run (part of its key)."""


def _sequence_runs(cp: CompiledProject, g: MotionPrimitiveGraph, table: dict, memo=None):
    """mode -> the goal sequence's run, naive and through the graph, as a stage: each kept in the memo
    by what decides it (the closed loops, the project's oracle block and settings, which decide the graph,
    its table and the shares of E_A each switch was checked from, the sequence and the mode); the others
    one map, a mode per item."""
    spec, prims, settings = cp.spec, cp.prims, cp.settings
    modes = ("naive", "graph")
    keys = {mode: memo.key("sequence", SEQUENCE_RECORD, mode, *(p.digest() for p in prims.values()),
                           spec.project.oracle.model_dump_json(), sorted(from_roa_samples(spec).items()),
                           spec.project.sequence.model_dump_json(),
                           sorted(dataclasses.asdict(settings).items())) for mode in modes} if memo is not None else {}
    known = {mode: memo.get(keys[mode]) for mode in keys}
    runs = {mode: SequenceRun(**known[mode]) for mode in modes if known.get(mode) is not None}
    todo = [mode for mode in modes if mode not in runs]
    if todo:
        done = yield Map(_simulated, todo, "sequence", (prims, g, table, spec.project.sequence, settings))
        for mode, got in zip(todo, done):
            if isinstance(got, Failed):
                raise RuntimeError(f"the {mode} run of the sequence failed: {got.error}")
            runs[mode] = got
            if memo is not None:
                memo.put(keys[mode], got.to_dict())
    return {mode: runs[mode] for mode in modes}


def _simulated(shared: tuple, mode: str) -> SequenceRun:
    """One mode of the goal sequence (a map item): shared = (prims, graph, table, sequence, settings)."""
    prims, g, table, seq, settings = shared
    return simulate_sequence(prims, g, table, seq, settings, mode)


def build(spec: ProjectSpec, settings: OracleSettings, progress: Progress | None = None,
          executor: Executor | None = None) -> tuple[CompiledProject, VerifiedGraph]:
    """Compile and run Algorithm 1; a caching executor also lends its memo to the sizing of E."""
    cp = compile_stage(spec, settings, progress, getattr(executor, "memo", None), executor)
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
