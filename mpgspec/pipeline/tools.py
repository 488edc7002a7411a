"""The side commands behind `mpgspec cache`, `schema` and `gait`, and the choice of executor."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


def cache(action: str = "info") -> dict:
    """What the oracle cache holds ('info'), or what clearing it removed ('clear')."""
    from ..oracle import cache as store

    return store.clear() if action == "clear" else store.info()


def schema(kind: str = "project") -> str:
    """The JSON Schema of a spec file kind, or of report.json (kind 'report'), as text."""
    if kind == "report":
        from ..report.schema import schema_path

        return schema_path().read_text(encoding="utf-8")
    import json

    from ..spec.schema import spec_schema

    return json.dumps(spec_schema(kind), indent=1, ensure_ascii=False) + "\n"


def executor(jobs: int = 1, dask=None, cache: bool = True):
    """Where oracle calls run: in this process, in `jobs` processes, or on a Dask cluster."""
    from ..oracle.executors import make_executor

    return make_executor(jobs, dask, cache=cache)


@dataclass
class GaitRun:
    """The gait tables of one gait file: regenerated, compared with the files on disk or written."""

    tables: list
    unstable: list[str]  # nodes without a converged, stable orbit (with the reason when none was found)
    stale: list[str] = field(default_factory=list)  # with check: what differs from the files on disk
    written: list[Path] = field(default_factory=list)


def gait(path, check: bool = False, progress=None, allow_paths=None) -> GaitRun:
    """Find every node's orbit; with check compare the tables with the files on disk, else write them.

    allow_paths: folders outside the gait file's folder that its project and the files the project
    names may lie in (as for verify)."""
    from ..compile.system import compile_system
    from ..robots.quadruped.gait.library import GaitTable, compare, gait_project, generate, write

    path = Path(path)
    tables = generate(path, progress=progress or (lambda m: None), allow_paths=allow_paths)
    names = compile_system(gait_project(path, allow_paths)[2]).state_names
    bad = [f"{t.node}: {t.failure}" if t.failure else t.node for t in tables
           if isinstance(t, GaitTable) and (t.orbit.status != "converged" or not t.orbit.spectral_radius < 1)]
    if check:
        return GaitRun(tables, bad, stale=compare(tables, names))
    return GaitRun(tables, bad, written=write(tables, names))
