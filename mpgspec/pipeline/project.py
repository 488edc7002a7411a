"""One project through the whole pipeline: load, settings, build, checks, report (and its files)."""
from __future__ import annotations

from pathlib import Path

from ..errors import MpgError, SpecError, SpecErrors
from ..oracle.executors import Executor
from ..progress import Progress
from ..report.build import build_report
from ..spec.loader import ProjectSpec, load_project
from .results import ProjectResult
from .settings import settings_for
from .stages import Checks, CompiledProject, VerifiedGraph, build, check_stage

FORMATS = ("json", "html", "dot", "graphml")


def run_project(path: Path, out_dir: Path | None, overrides: dict | None = None,
                progress: Progress | None = None, formats: tuple[str, ...] = FORMATS,
                executor: Executor | None = None, allow_paths=None, check=check_stage) -> ProjectResult:
    """Verify one project file and write its reports under out_dir/<project>/.

    allow_paths: folders outside the project folder that files named by the spec may lie in;
    check: the check stage (check_stage unless the caller wraps it)."""
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
        ch = check(cp, vg, progress, getattr(executor, "memo", None), executor=executor)
        return _finish_project(res, cp, vg, ch, out_dir, formats)
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
    from ..spec.digest import spec_digest

    try:
        return spec_digest(path)
    except OSError:
        return None


def _where(loc) -> dict | None:
    if loc is None or not getattr(loc, "line", 0):
        return None
    return {"file": str(loc.file), "line": int(loc.line), "column": int(loc.column or 0)}


def _locate_checks(spec: ProjectSpec, ch: Checks, report: dict) -> None:
    """The spec position of each assertion and assumption check (for CI annotations), as `location`."""
    n = len(spec.project.assertions)

    def prim(name, *key):
        try:
            return spec.primitive(name).locate(key)
        except (KeyError, LookupError, TypeError, ValueError):
            return None

    for a, entry in zip(ch.assertions, report["assertions"]):
        loc = None
        try:
            if a.index < n:
                loc = spec.locate(("assertions", a.index))
            elif a.kind == "roa_level":
                loc = prim(a.primitive, "roa")
            elif a.kind == "crosscheck":
                loc = spec.locate(("crosscheck", "require_agreement"))
        except (KeyError, LookupError, TypeError, ValueError):
            loc = None
        if (w := _where(loc)) is not None:
            entry["location"] = w
    for c in report.get("assumptions", []):
        on_roa = c["name"] in ("roa_in_safe_set", "roa_invariant", "roa_size")
        w = _where(prim(c["primitive"], "roa") if on_roa else prim(c["primitive"]))
        if w is not None:
            c["location"] = w


def _finish_project(res: ProjectResult, cp: CompiledProject, vg: VerifiedGraph, ch: Checks, out_dir,
                    formats) -> ProjectResult:
    """The report of a project whose graph is built and checked, written when out_dir is given."""
    report = build_report(cp, vg, ch, digest=_digest(cp.spec.path))
    _locate_checks(cp.spec, ch, report)
    res.status, res.report, res.compiled = ch.status, report, cp
    res.pages = _playback(cp, ch, report)
    if out_dir is not None:
        from ..report.files import write_reports

        res.files = write_reports(report, vg.graph, Path(out_dir) / cp.spec.name, formats, res.pages)
    return res


def _playback(cp: CompiledProject, ch: Checks, report: dict) -> dict[str, str]:
    """{'playback': playback.html} when the project's sequence ran a robot with a floating base (the
    report's sequence entry then names the page); {} otherwise."""
    from ..report.playback import playback_data, render_playback

    seq = cp.spec.project.sequence
    if not ch.runs or seq is None:
        return {}
    xc = ch.crosscheck
    data = playback_data(cp.spec.name, next(iter(cp.prims.values())).system, ch.runs,
                         xc.playback() if xc is not None else None, report.get("crosscheck"), float(seq.duration))
    if data is None:
        return {}
    report["sequence"]["playback"] = "playback.html"
    return {"playback": render_playback(data)}
