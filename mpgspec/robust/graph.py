"""The robust graph: each nominal edge's switch cells re-run under the project's uncertainty.

For every nominal transition A -> B (among `nodes`, when given), up to `cells` t_A rows that have
a verified t_B are taken (the t_B the plan would switch in at), spread over the rows the graph executor
switches through (the sequence's rule, reserve and keep, the checks from E_A's boundary) when it takes any,
so that a robust cell is a switch the executor makes. Each such cell is run for a set of
scenarios: the corners of the box of uncertain parameters and start errors (at most `corners` of
them, seeded), its centre, `samples` seeded random points, each with the disturbance at 0, +bound
and -bound; then `search` rounds of an adversarial bang-bang disturbance from the worst scenario
(the sign of the gradient, through CasADi, of the binding h sample before entry and of the RoA
margin at entry; where the law gives no gradient, a rigid body or a sampled ID-QP, a coordinate
search that reverses one piece of one axis per candidate and keeps the worst).
With `start_in_roa`, every scenario also starts from seeded samples of the boundary of the source's
region of attraction E_A (starts.py), and the search continues from the worst start.
A cell is robust-safe when every scenario from every start is safe; the robust transition keeps
only those cells and is classified like the nominal one. This is falsification: a robust edge withstood every
scenario tried, it is not proven to withstand the whole set.
The targets are checked independently through the executor's map (in this process, a process pool
or Dask), each from the same seeded scenarios, so the result does not depend on where they ran.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ..check.assertions import AssertionResult, evaluate_assertions
from ..graph.transition import (MotionPrimitiveGraph, Transition, TransitionClass, executor_clocks,
                                input_bounds)
from ..plan.planner import lookup_table
from ..spec.models import PrimitiveClass
from ..spec.uncertainty_refs import latency_steps, rigid_nominal
from ..progress import of_project
from .from_roa import from_roa_samples
from ..oracle.executors import InProcess
from ..oracle.joint import Map, concurrently, run
from ..oracle.tasks import Failed
from .cells import TargetJob, cell_rows, failed_target, job_cost, run_target
from .library import prefetch
from .rigid import RigidRobustRollout, uses_library
from .rollout import RobustRollout, plant
from .scenarios import Scenarios, scenarios, searched
from .sequence import uncertain_stage

LABEL = "empirical"
RECORD = 13
"""Layout of the memoised robust record and the rule that made it (part of its key): 10 runs a cell's scenarios in
waves; 11 runs a target's own flow past its first wave only when an edge into it depends on it; 13 takes the
cells among the rows the graph executor switches through."""
SAMPLED = "empirical (sampled)"
NOTE = ("falsification, not proof: a robust edge withstood every scenario tried (parameter-box corners, seeded "
        "samples and an adversarial disturbance search); no certificate backs it")


@dataclass
class RobustResult:
    """The robust graph, what each nominal edge withstood, and the robust assertions."""

    graph: MotionPrimitiveGraph
    edges: list[dict]
    assertions: list[AssertionResult]
    scenarios: dict
    timing: dict = field(default_factory=dict)
    sequence: dict | None = None  # safe fraction of the goal sequence per mode under sampled uncertainty
    nodes: list[dict] = field(default_factory=list)  # each target's own flow under the scenarios

    def to_dict(self) -> dict:
        survive = [e for e in self.edges if e["survives"]]
        return {"level": LABEL, "note": NOTE, "scenarios": self.scenarios,
                "summary": {"nominal_edges": len(self.edges), "robust_edges": len(survive),
                            "nominal_only": [f"{e['from']} -> {e['to']}" for e in self.edges if not e["survives"]]},
                "edges": self.edges, "nodes": self.nodes, "assertions": [a.to_dict() for a in self.assertions],
                "sequence": self.sequence,
                "timing": self.timing}


def robust_stage(cp, vg, progress=None, memo=None, executor=None) -> RobustResult | None:
    """Build the robust graph of a compiled project and its nominal graph; None without `uncertainty`.

    memo (optional, mpgspec.oracle.cache.Memo) keeps the cell verdicts and sequence statistics by the
    content hash of the closed loops, the system, the uncertainty, the sequence and the settings.
    executor (mpgspec.oracle.executors; in this process when omitted) runs the targets' checks.
    """
    executor = executor or InProcess()
    stage = robust_steps(cp, vg, progress, memo, executor.workers)
    return run(stage, executor, of_project(progress, cp.spec.name))


def robust_steps(cp, vg, progress=None, memo=None, workers: int = 1):
    """robust_stage as a stage (mpgspec.oracle.joint): the targets' checks one map, beside them the
    uncertain sequences naive and through the nominal graph, then through the robust graph (each
    spread over `workers` items; each mode's runs depend on the seed and its graph only)."""
    spec, prims, settings, g = cp.spec, cp.prims, cp.settings, vg.graph
    unc = spec.project.uncertainty
    if unc is None:
        return None
    t0 = time.perf_counter()
    key = _key(spec, prims, settings, memo)
    known = memo.get(key) if memo is not None else None
    if known is not None:
        edges = known["edges"]
        rg = _robust_graph(g, edges, unc.nodes)
        return RobustResult(rg, edges, _assertions(unc, rg), known["scenarios"],
                            {"robust_s": time.perf_counter() - t0, "robust_cache_hit": 1.0}, known["sequence"],
                            known["nodes"])
    sys = next(iter(prims.values())).system
    sc, jobs = target_jobs(spec, prims, settings, g)
    among = set(unc.nodes) if unc.nodes is not None else set(prims)
    runs = spec.project.sequence is not None and unc.runs > 0
    w = spec.project.sequence.weight if runs else None
    targets = targets_stage(jobs, prims, unc)
    if runs:  # the naive and nominal-graph runs need no robust verdict: they run beside the targets' checks
        first = yield from concurrently({"targets": targets, "nominal": uncertain_stage(
            spec, prims, settings, {"graph": (g, lookup_table(g, w))}, unc.runs, unc.seed, workers)})
        edges, nodes, n_roll, build_s = first["targets"]
    else:
        edges, nodes, n_roll, build_s = yield from targets
    rg = _robust_graph(g, edges, unc.nodes)
    scen = _scenario_record(unc, sc, among, edges, nodes, sys)
    t1 = time.perf_counter()
    seq = None
    if runs:
        if progress:
            progress(spec.name, "sequence under uncertainty (through the robust graph)", 2, 3)
        late = yield from uncertain_stage(spec, prims, settings, {"robust_graph": (rg, lookup_table(rg, w))},
                                          unc.runs, unc.seed, workers, naive=False)
        seq = {**late, "modes": {**first["nominal"]["modes"], **late["modes"]}}
    timing = {"robust_s": time.perf_counter() - t0, "robust_build_s": build_s, "robust_rollouts": n_roll,
              "robust_sequence_s": time.perf_counter() - t1}
    edges.sort(key=lambda e: (e["from"], e["to"]))
    if memo is not None:
        memo.put(key, {"edges": edges, "nodes": nodes, "scenarios": scen, "sequence": seq, "rollouts": n_roll})
    return RobustResult(rg, edges, _assertions(unc, rg), scen, timing, seq, nodes)


def _key(spec, prims: dict, settings, memo) -> str | None:
    """The memo key of the robust record: the closed loops, the system, the uncertainty, the sequence,
    the project's oracle block (its grid and `from_roa` decide the nominal graph the uncertain runs follow)
    and the settings."""
    if memo is None:
        return None
    seq_spec = spec.project.sequence
    return memo.key("robust", RECORD, *(p.digest() for p in prims.values()), spec.system.model_dump_json(),
                    spec.project.uncertainty.model_dump_json(), seq_spec.model_dump_json() if seq_spec else None,
                    spec.project.oracle.model_dump_json(), sorted(from_roa_samples(spec).items()),
                    sorted(dataclasses.asdict(settings).items()))


def prefetch_robust(spec, prims: dict, settings, memo=None) -> None:
    """Start compiling the robot's library in the background when the robust stage will need it
    (uncertainty, a rigid body with a masked plant, no stored record): its gcc then runs beside
    the stages before."""
    if spec.project.uncertainty is None or not prims:
        return
    prim = next((p for p in prims.values() if uses_library(p, settings)), None)
    if prim is None or (memo is not None and memo.has(_key(spec, prims, settings, memo))):
        return
    prefetch(prim.system, reverse=searched(spec.project.uncertainty))


@dataclass(frozen=True)
class RolloutFactory:
    """rollout(B, horizon): B's robust rollout on the perturbed plant, picklable so that a worker
    process builds it (the rigid body's uncertain plant with a push on its base, or the analytic
    plant P with input disturbances on the inputs dist_idx)."""

    settings: object
    K: int
    names: tuple = ()
    rigid: bool = False
    frame: str | None = None
    push: bool = False
    duration: float | None = None
    P: object = None
    dist_idx: tuple = ()
    gradient: bool = True  # the push gradient is built (the adversarial search runs)
    latency: int = 0  # oracle steps between the state a law reads and its input reaching the plant (rigid bodies)

    def __call__(self, B, horizon):
        if self.rigid:
            return RigidRobustRollout(B, list(self.names), self.frame, self.push, self.K, self.settings, horizon,
                                      self.duration, self.gradient, self.latency)
        return RobustRollout(B, self.P, list(self.dist_idx), self.K, self.settings, horizon, gradient=self.gradient)


def _setup(spec, sys, unc, settings) -> tuple[Scenarios, RolloutFactory]:
    """The scenarios of every cell, and the factory of each target's robust rollout."""
    names = list(unc.parameters)
    dist = unc.disturbance
    force = dist.force if dist is not None else None
    K = dist.segments if dist is not None else 1
    if sys.is_rigid_body:
        nominal_values = rigid_nominal(sys)
        frame = force.frame if force is not None else sys.base_frames()[0]
        dist_names = [f"force_{a}" for a in "xyz"] if force is not None else []
        bound = np.asarray(force.bound, float) if force is not None else np.zeros(0)
        rollout = RolloutFactory(settings, K, tuple(names), True, frame, force is not None,
                                 force.duration if force is not None else None, gradient=searched(unc),
                                 latency=latency_steps(spec, settings.dt))
    else:
        nominal_values = dict(sys.parameters)
        dist_idx = [sys.input_names.index(u) for u in dist.inputs] if dist is not None else []
        dist_names = list(dist.inputs) if dist is not None else []
        bound = (np.broadcast_to(np.asarray(dist.bound, float), (len(dist_idx),)).copy() if dist is not None
                 else np.zeros(0))
        rollout = RolloutFactory(settings, K, P=plant(spec, names), dist_idx=tuple(dist_idx), gradient=searched(unc))
    rng = np.random.default_rng(unc.seed)
    TH, ERR, SG, KIND = scenarios(unc, sys, rng, nominal_values)
    return Scenarios(names, TH, ERR, SG, KIND, bound, K, dist_names, list(sys.state_names)), rollout


def targets_stage(jobs: list[TargetJob], prims: dict, unc):
    """(edge records, own-flow records, rollouts run, seconds building rollouts) of the target jobs as a
    stage (mpgspec.oracle.joint): the targets one map, the costliest first; a job that raised gets the
    records of failed_target, with its error as the evidence."""
    done = yield Map(run_target, jobs, "robust graph", prims, cost=[job_cost(job) for job in jobs])
    edges, nodes, n_roll, build_s = [], [], 0, 0.0
    for job, res in zip(jobs, done):
        if isinstance(res, Failed):
            e, node = failed_target(prims, job.target, job.items, unc, res.error)
            n, s = 0, 0.0
        else:
            e, node, n, s = res
        edges += e
        nodes.append(node)
        n_roll, build_s = n_roll + n, build_s + s
    return edges, nodes, n_roll, build_s


def target_jobs(spec, prims: dict, settings, g: MotionPrimitiveGraph) -> tuple[Scenarios, list[TargetJob]]:
    """The scenarios every cell runs, and one job per target of a nominal edge among the uncertainty's
    nodes: the target and its in-edges."""
    unc, sys = spec.project.uncertainty, next(iter(prims.values())).system
    sc, rollout = _setup(spec, sys, unc, settings)
    among = set(unc.nodes) if unc.nodes is not None else set(prims)
    return sc, [TargetJob(b, items, unc, settings, sc, rollout)
                for b, items in _by_target(spec, prims, g, among).items()]


def _by_target(spec, prims: dict, g: MotionPrimitiveGraph, among: set) -> dict[str, list]:
    """Target -> [(source, transition, t_A rows)] of the nominal edges among `among`: the rows are the
    cells to check, among those the graph executor switches through under the sequence's rule and
    reserve and keep (executor_clocks) where it takes any."""
    seq = spec.project.sequence
    rule, reserve, keep = (seq.switch, seq.reserve, seq.keep) if seq is not None else ("first", None, None)
    by_target: dict[str, list] = {}
    for (a, b), tr in g.transitions.items():
        if tr.cls is not TransitionClass.NONE and a in among and b in among:
            taken = executor_clocks(tr, prims[a].cls is PrimitiveClass.TRANSIENT, rule, reserve,
                                    input_bounds(prims[b].system), keep)
            by_target.setdefault(b, []).append((a, tr, cell_rows(tr, spec.project.uncertainty.cells, taken)))
    return by_target


def _scenario_record(unc, sc: Scenarios, among: set, edges: list[dict], nodes: list[dict], sys) -> dict:
    """The report's account of the scenarios every cell ran."""
    dist, roa_starts = unc.disturbance, unc.start_in_roa
    force = dist.force if dist is not None else None
    bound = sc.bound
    scen = {"per_cell": sc.S, "corners": sc.KIND.count("corner"), "samples": unc.samples,
            "search_rounds": unc.search, "disturbance_segments": sc.K, "latency": float(unc.latency),
            "parameters": {n: list(unc.parameters[n].range) for n in sc.names},
            "initial_state": dict(unc.initial_state),
            "disturbance": None if dist is None else {"inputs": list(dist.inputs), "bound": bound.tolist()}
            if force is None else {"force": {"frame": force.frame, "bound": bound.tolist(),
                                             "duration": force.duration}},
            "nodes": sorted(among),
            "seed": unc.seed, "cells_per_edge": unc.cells, "start_in_roa": None,
            "stopped": sum(sum(e["cells"]["stopped"]) for e in edges),
            "own_flow_not_run": sum(n.get("not_run", 0) for n in nodes)}
    if roa_starts is not None:
        scen["start_in_roa"] = {"level": SAMPLED, "samples": roa_starts.samples, "seed": roa_starts.seed,
                                "drawn": sum(e["start_in_roa"]["drawn"] for e in edges),
                                "kept": sum(e["start_in_roa"]["kept"] for e in edges),
                                "projected": bool(sys.is_rigid_body)}
    return scen


def _assertions(unc, rg: MotionPrimitiveGraph) -> list[AssertionResult]:
    checks = evaluate_assertions(unc.assertions, rg, {})
    for c in checks:
        c.kind = f"robust {c.kind}"
        c.description = f"robust: {c.description}"
    return checks


def _robust_graph(g: MotionPrimitiveGraph, edges: list[dict], nodes: list[str] | None = None) -> MotionPrimitiveGraph:
    """The nominal graph (on `nodes` only, when given) with each edge's transition cut to its robust
    cells, keeping each row's margin and its check from E_A's boundary (where and within what share of
    r_A the executor may switch, as robust_report_graph reads them from a report); fills each edge
    record's robust class, windows and weights."""
    keep = set(g.G.nodes) if nodes is None else set(nodes)
    trs = {k: tr for k, tr in g.transitions.items() if k[0] in keep and k[1] in keep}
    for e in edges:
        tr = g.transitions[(e["from"], e["to"])]
        ok = {(i, int(np.argmin(np.abs(tr.t_B - tr.best_t_B[i]))))
              for i, safe in zip(e["cells"]["row"], e["cells"]["robust_safe"]) if safe}
        ev = [[x if (i, j) in ok else dataclasses.replace(x, verdict=0, status="unsafe") for j, x in enumerate(row)]
              for i, row in enumerate(tr.evidence)]
        rt = Transition(tr.source, tr.target, tr.t_A, tr.t_B, ev, row_margins=list(tr.row_margins),
                        row_from_roa=list(tr.row_from_roa), from_roa_worst=tr.from_roa_worst)
        rt.classify()  # the rows' margins and checks from E_A's boundary stay: the executor's rule reads them
        trs[(e["from"], e["to"])] = rt
        e.update(robust_class=int(rt.cls), survives=rt.cls is not TransitionClass.NONE, cells_robust=len(ok),
                 robust_windows=[list(w) for w in rt.windows], robust_weights=dict(rt.weights))
    return MotionPrimitiveGraph({n: dict(g.G.nodes[n]) for n in g.G.nodes if n in keep}, trs)
