"""Python API: everything the CLI does, callable from a notebook.

    from mpgspec import api
    res = api.verify("specs/pendulum")            # nothing written unless out_dir is given
    p = res["pendulum"]                           # or res.projects[0]
    p.status, p.report                            # 'pass' and the report dict (as report.json)
    p.plan("Hang", "Balance")                     # the planner's shortest sequence, hop by hop
    p.simulate("graph")                           # the goal sequence through the graph
    p.graph                                       # networkx graph the planner searches
    api.load_report("reports/pendulum")           # the same from what `mpgspec verify` wrote
    api.write_reports(res, "reports")             # each project's report set, written as a unit
    api.plan("specs/pendulum", "Hang", "Balance") # from the verified report while it is current
    api.gait("specs/a1/gaits.yaml", check=True)   # the gait tables against their regeneration

The stages themselves (compile_stage, graph_stage, check_stage, build) live in mpgspec.pipeline;
they are imported on first use, so that planning from a verified report stays quick.
"""
from __future__ import annotations

import importlib
from pathlib import Path

from .errors import EXIT_CHECK_FAILED, EXIT_OK, EXIT_USAGE, MpgError, SpecError, SpecErrors, UsageError  # noqa: F401
from .pipeline.results import ProjectResult, VerifyResult, load_report, write_reports
from .pipeline.reuse import Notify
from .progress import Progress

__all__ = ["verify", "load_report", "ProjectResult", "VerifyResult", "run_project", "compile_stage", "graph_stage",
           "check_stage", "build", "settings_for", "compile_project", "load_project", "discover",
           "CompiledProject", "VerifiedGraph", "Checks", "plan", "simulate", "simulate_uncertain", "write_reports",
           "cache", "schema", "executor", "gait", "GaitRun",
           "EXIT_OK", "EXIT_CHECK_FAILED", "EXIT_USAGE"]

_LAZY = {
    **dict.fromkeys(("compile_stage", "graph_stage", "check_stage", "build", "compile_project", "CompiledProject",
                     "VerifiedGraph", "Checks"), "mpgspec.pipeline.stages"),
    "settings_for": "mpgspec.pipeline.settings",
    **dict.fromkeys(("cache", "schema", "executor", "gait", "GaitRun"), "mpgspec.pipeline.tools"),
    "robust_stage": "mpgspec.robust.graph",
    **dict.fromkeys(("load_project", "discover", "ProjectSpec"), "mpgspec.spec.loader"),
}
FORMATS = ("json", "html", "dot", "graphml")


def __getattr__(name: str):
    """The build's stages and spec loading, imported when first named (PEP 562)."""
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value
    return value


def _stage(name: str):
    """A stage as this module holds it now: a notebook (or a test) may replace api.check_stage."""
    return globals()[name] if name in globals() else __getattr__(name)


def run_project(path: Path, out_dir: Path | None, overrides: dict | None = None, progress: Progress | None = None,
                formats: tuple[str, ...] = FORMATS, executor=None, allow_paths=None) -> ProjectResult:
    """Verify one project file and write its reports under out_dir/<project>/.

    allow_paths: folders outside the project folder that files named by the spec may lie in.
    """
    from .pipeline.project import run_project as run

    return run(path, out_dir, overrides, progress, formats, executor, allow_paths, check=_stage("check_stage"))


def verify(paths, out_dir: str | Path | None = None, overrides: dict | None = None,
           progress: Progress | None = None, executor=None, allow_paths=None, cache: bool = True) -> VerifyResult:
    """Verify every project found under `paths`; reports go to out_dir (None: write nothing).

    progress(project, phase, done, total): told as each stage starts.
    executor: where oracle calls run (mpgspec.oracle.executors: InProcess, ProcessPool,
    DaskExecutor; make_executor(jobs, dask) picks one); in this process when omitted, reusing and
    storing oracle results in the result cache as `mpgspec verify` does (cache=False: run every call).
    allow_paths: folders outside each project folder that files named by specs may lie in
    (paths a spec names must otherwise resolve inside its project folder).
    """
    discover = _stage("discover")
    files: list[Path] = []
    for p in [paths] if isinstance(paths, (str, Path)) else paths:
        files.extend(discover(p))
    if executor is None:
        from .pipeline.tools import executor as make

        executor = make(1, None, cache=cache)
    res = VerifyResult([run_project(f, Path(out_dir) if out_dir else None, overrides, progress, executor=executor,
                                    allow_paths=allow_paths)
                        for f in files])
    if out_dir and any(p.files for p in res.projects):
        from .report.index import write_index

        write_index(out_dir)
    return res


def plan(project, source: str, goal: str, weight: str = "duration", out: str | Path = "reports",
         rebuild: bool = False, robust: bool = False, notify: Notify | None = None) -> dict:
    """The shortest safe sequence from source to goal in the project at `project` (a project.yaml
    or its folder): read from out/<project>/report.json while it matches the spec files, else
    rebuilt (notify is told why). robust: only the edges that withstood the project's uncertainty.
    Returns from, to, weight, path (None when unreachable), cost, hops and source."""
    from .pipeline.plan import plan_project

    return plan_project(project, source, goal, weight, out, rebuild, robust, notify)


def simulate(project, modes=("naive", "graph"), out: str | Path = "reports", rebuild: bool = False,
             crosscheck: bool = False, notify: Notify | None = None, runs=None, seed=None) -> dict:
    """The project's goal sequence in each mode ('naive', 'graph'): runs (mode -> SequenceRun),
    expected (mode -> whether the project expects it safe) and crosscheck (the MuJoCo replays
    when asked, else None). The graph is read from the verified report while it is current."""
    from .pipeline.simulate import simulate_project

    return simulate_project(project, tuple(modes), out, rebuild, crosscheck, notify, runs, seed)


def simulate_uncertain(project, runs: int | None = None, seed: int | None = None, out: str | Path = "reports",
                       rebuild: bool = False, crosscheck: bool = False, notify: Notify | None = None) -> dict:
    """The goal sequence under seeded draws of the project's `uncertainty`, naive, through the
    nominal and through the robust graph: stats (safe fractions per mode), uncertainty, runs, seed."""
    from .pipeline.simulate import simulate_uncertain as run

    return run(project, runs, seed, out, rebuild, crosscheck, notify)
