"""Reuse what `verify` wrote: the report of a project while it matches the spec files, else a
rebuild of its graph (through the oracle cache).

Light at import (json, networkx and the YAML reader) so that a plan from a report is quick; the
build stages are imported only when a graph must be rebuilt."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from ..errors import MpgError, UsageError
from ..report.read import report_status
from ..spec.yamlpos import parse_yaml

Notify = Callable[[str], None]
"""notify(message): told why a report is not reused (the command line prints it on stderr)."""


def load_one(path):
    """The one project at path (file or folder), loaded but not compiled."""
    from ..spec.loader import discover, load_project

    files = discover(path)
    if len(files) != 1:
        raise UsageError(f"{path}: expected one project, found {len(files)}")
    return load_project(files[0])


def quick_report(project, out, rebuild: bool) -> dict | None:
    """The report `verify` wrote for the project at `project` when it matches the spec files, found
    without loading the spec (its name is read from project.yaml); None otherwise. A current report
    that its checks refuse (edited, written with another key, malformed) raises ReportError."""
    if rebuild:
        return None
    f = Path(project)
    f = f / "project.yaml" if f.is_dir() else f
    try:
        data = parse_yaml(f.read_text(encoding="utf-8"), str(f))[0] if f.is_file() else None
    except (OSError, ValueError, MpgError):
        return None
    name = data.get("project") if isinstance(data, dict) else None
    if not isinstance(name, str) or not name.strip() or Path(name).name != name or name.startswith("."):
        return None
    return report_status(Path(out) / name / "report.json", f, strict=True)[0]


def verified(spec, out, rebuild: bool, notify: Notify | None = None, strict: bool = True) -> dict | None:
    """The project's report from `verify` when it matches the spec files, else None (telling
    notify why). strict: a current report that its checks refuse raises ReportError (plan and
    simulate stop on it); otherwise it is only not used."""
    if rebuild:
        return None
    report, why = report_status(Path(out) / spec.name / "report.json", spec.path, strict)
    if report is None and notify is not None:
        notify(f"mpgspec: {why}; rebuilding the graph (run `mpgspec verify` to store it)")
    return report


def cached_executor(jobs: int = 1):
    """`jobs` processes (one: this process), oracle results from and into the cache."""
    from ..oracle.executors import make_executor

    return make_executor(jobs, None, cache=True)


def rebuild(spec, executor=None):
    """Compile the project and run Algorithm 1 with its own settings (through executor, else a
    cached one): (CompiledProject, VerifiedGraph)."""
    from .settings import settings_for
    from .stages import build

    return build(spec, settings_for(spec), executor=executor or cached_executor())


def compiled(spec, cache: bool = True):
    """The project's closed loops with E sized (the graph is read from a report); with cache, the
    sizing of E is kept in (and taken from) the oracle cache."""
    from .settings import settings_for
    from .stages import compile_stage

    memo = getattr(cached_executor(), "memo", None) if cache else None
    return compile_stage(spec, settings_for(spec), memo=memo)
