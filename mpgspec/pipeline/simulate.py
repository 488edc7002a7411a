"""The project's goal sequence run naive and through the graph (replayed in MuJoCo on request), or
under seeded draws of its uncertainty; the graph is read from the verified report when it matches
the spec files, else rebuilt."""
from __future__ import annotations

from ..errors import UsageError
from .reuse import Notify, cached_executor, compiled, load_one, rebuild, verified


def _with_sequence(project):
    spec = load_one(project)
    if spec.project.sequence is None:
        raise UsageError(f"{spec.path}: the project has no 'sequence'")
    return spec


def expected(spec) -> dict[str, bool]:
    """mode -> the simulation_safe expectation of the project (safe when not asserted)."""
    out = {}
    for a in spec.project.assertions:
        mode = getattr(a, "simulation_safe", None)
        if isinstance(mode, str):
            out[mode] = bool(getattr(a, "expect", True))
    return out


def simulate_project(project, modes=("naive", "graph"), out="reports", rebuild_: bool = False,
                     crosscheck: bool = False, notify: Notify | None = None, runs=None, seed=None) -> dict:
    """runs: mode -> SequenceRun; expected: mode -> whether the project expects it safe; crosscheck:
    mode -> the MuJoCo replay (None unless asked). A number of runs or a seed is refused: they
    belong to simulate_uncertain."""
    from ..execute.sequence import simulate_sequence

    spec = _with_sequence(project)
    xcs = None
    if crosscheck:
        from ..execute.crosscheck.settings import settings_of

        xcs = settings_of(spec, force=True)
    report = verified(spec, out, rebuild_, notify)
    if runs is not None or seed is not None:
        raise UsageError("--runs and --seed apply to --uncertain runs only")
    if report is not None:
        from ..report.read import ReportGraph

        cp = compiled(spec)
        g, table = ReportGraph(report), report["lookup_table"]["next"]
    else:
        from ..plan.planner import lookup_table

        cp, vg = rebuild(spec)
        g, table = vg.graph, lookup_table(vg.graph, spec.project.sequence.weight)
    done = {m: simulate_sequence(cp.prims, g, table, spec.project.sequence, cp.settings, m) for m in modes}
    xc = None
    if xcs is not None:
        from ..execute.crosscheck import crosscheck_runs
        from ..execute.crosscheck.executor import ExecutorPlan

        plan = ExecutorPlan.of(g, table, spec.project.sequence, cp.prims) if "graph" in done else None
        xc = crosscheck_runs(cp.prims, done, spec.project.sequence.duration, xcs.replace(runs=modes),
                             cp.settings.h_tolerance, plan=plan).runs
    return {"runs": done, "expected": expected(spec), "crosscheck": xc}


def simulate_uncertain(project, runs: int | None = None, seed: int | None = None, out="reports",
                       rebuild_: bool = False, crosscheck: bool = False, notify: Notify | None = None) -> dict:
    """The goal sequence under seeded draws of the project's uncertainty: the fraction of runs that
    stay safe naive, through the nominal graph and through the robust graph (sequence_under_uncertainty's
    statistics, with the uncertainty, runs and seed used)."""
    from ..plan.planner import lookup_table
    from ..robust.sequence import sequence_under_uncertainty

    spec = _with_sequence(project)
    if crosscheck:
        raise UsageError("--crosscheck replays the nominal runs; it does not apply to --uncertain")
    report = verified(spec, out, rebuild_, notify)
    unc = spec.project.uncertainty
    if unc is None:
        raise UsageError(f"{spec.path}: the project declares no `uncertainty` to sample")
    runs = unc.runs if runs is None else runs
    seed = unc.seed if seed is None else seed
    if not 1 <= runs <= 100000:
        raise UsageError(f"--runs must be between 1 and 100000; got {runs}")
    from ..oracle.executors import usable_cores

    executor = cached_executor(usable_cores())  # the modes (and a rebuild) on every usable core
    if report is not None and report.get("robust"):
        from ..report.read import ReportGraph
        from ..robust.plan import report_lookup_table, robust_report_graph

        cp = compiled(spec)
        rg = robust_report_graph(report)
        graphs = {"graph": (ReportGraph(report), report["lookup_table"]["next"]),
                  "robust_graph": (rg, report_lookup_table(rg, spec.project.sequence.weight))}
    else:
        from ..robust.graph import robust_stage

        cp, vg = rebuild(spec, executor)
        rob = robust_stage(cp, vg, memo=getattr(executor, "memo", None), executor=executor)
        w = spec.project.sequence.weight
        graphs = {"graph": (vg.graph, lookup_table(vg.graph, w)), "robust_graph": (rob.graph, lookup_table(rob.graph, w))}
    stats = sequence_under_uncertainty(spec, cp.prims, cp.settings, graphs, runs, seed, executor)
    return {"stats": stats, "uncertainty": unc, "runs": runs, "seed": seed}
