"""`mpgspec verify`: every project through mpgspec.api.verify, its reports written as a unit, the
result as text, JSON or GitHub annotations with a step summary."""
from __future__ import annotations

import contextlib
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from .. import api
from ..cores import usable_cores
from ..errors import UsageError
from ..oracle.cache import VERIFY_ENV
from ..report.ci import project_seconds
from ..report.findings import disagreements, nominal_only_path, path_text, warning_count
from ..streams import stdout_to_stderr
from .output import MARK, _annotation, _rel, _json_doc, _line, _num, _print_errors, _progress, append_step_summary

JOBS_PER_CORE = 4
MACHINE_FORMATS = ("json", "junit", "sarif")
"""Formats whose stdout is one document: every other line of the command goes to stderr."""

if TYPE_CHECKING:
    from ..pipeline.results import VerifyResult


def _step_summary(res) -> None:
    """A Markdown table of the run appended to $GITHUB_STEP_SUMMARY (when set)."""
    if not os.environ.get("GITHUB_STEP_SUMMARY"):
        return

    def cell(v) -> str:
        return str(v).replace("|", "\\|").replace("\n", " ")

    rows = ["| project | result | primitives | edges | oracle calls | assertions | warnings | report |",
            "|---|---|---|---|---|---|---|---|"]
    for p in res.projects:
        if p.report is None:
            why = "; ".join(e.get("message", "") for e in p.errors)[:300]
            rows.append(f"| {cell(p.name or p.path)} | ERROR | {cell(why)} | | | | | |")
            continue
        r = p.report
        a = r.get("assertions", [])
        warns = warning_count(r)
        failed = [x for x in a if x["status"] != "pass"]
        rows.append("| " + " | ".join(cell(v) for v in (
            p.name or p.path, MARK.get(p.status, p.status.upper()), len(r.get("primitives", [])), len(r.get("edges", [])),
            (r.get("timing") or {}).get("oracle_calls", "–"),
            f"{len(a) - len(failed)}/{len(a)} pass" + (f" (failed: {'; '.join(x['description'] for x in failed)})"
                                                        if failed else ""), warns,
            _rel(p.files["html"]) if p.files.get("html") else "not written")) + " |")
        for e in p.errors:  # e.g. the reports could not be written
            rows.append(f"| {cell(p.name or p.path)} | ERROR | {cell(e.get('message', ''))} | | | | | |")
    append_step_summary("### mpgspec verify\n\n" + "\n".join(rows) + "\n\n")


def _inconclusive(r: dict) -> str:
    v = r.get("verdicts") or {}
    return f", {v['inconclusive']} inconclusive" if v.get("inconclusive") else ""


def _cached(t: dict) -> str:
    out = f", {int(t['cache_hits'])} from the cache" if t.get("cache_hits") else ""
    if t.get("cache_verified"):
        out += f", {int(t['cache_verified'])} of them run again ({int(t.get('cache_mismatch', 0))} disagreed)"
    if t.get("cache_rejected"):
        out += f", {int(t['cache_rejected'])} stored results failed their integrity check and were recomputed"
    return out


def _proved(report: dict) -> str:
    """How the oracle calls were answered: simulated, or how many verdicts were proved."""
    n = int((report.get("verdicts") or {}).get("certified") or 0)
    return f"{n} certified" if n else "simulated"


def _human(res: VerifyResult, fmt: str):
    def out(text: str):
        print(_line(text, fmt))

    for p in res.projects:
        if p.report is None:
            out(f"{MARK['error']} {p.path}")
            _print_errors(p.errors, fmt)
            continue
        r = p.report
        t = r["timing"]
        total = project_seconds(t)
        out(f"{MARK[p.status]} {p.name}: {len(r['primitives'])} primitives, {len(r['edges'])} edges, "
            f"{t['oracle_calls']} oracle calls ({_proved(r)}) in {_num(t['graph_s'], '.2f')} s"
            f"{_inconclusive(r)}{_cached(t)}; {_num(total, '.1f')} s for the project")
        methods = {(tr["from"], tr["to"]): tr["method"] for tr in r.get("transitions", [])}
        for e in r["edges"]:
            out(f"    {e['from']} -> {e['to']}  class {e['class']}  duration {_num(e.get('duration') or 0)} s"
                f"  {methods.get((e['from'], e['to']), 'simulated')}")
        for a in r["assertions"]:
            if fmt == "github" and a["status"] != "pass":
                print(_annotation("error", f"{a['description']}: {a['message']}", a.get("location"),
                                  "mpgspec assertion", file=p.path))
            else:
                out(f"  {MARK[a['status']]:5} {a['description']}: {a['message']}")
        for c in r.get("assumptions", []):
            if c["status"] == "pass":
                continue
            text = f"assumption {c['name']} of {c['primitive']}: {c['message']}"
            if fmt == "github":
                kind = {"warn": "warning", "info": "notice"}.get(c["status"], "error")
                print(_annotation(kind, text, c.get("location"),
                                  "mpgspec assumption", file=p.path))
            else:
                out(f"  {c['status'].upper():5} {text}")
        for d in disagreements(r):
            text = f"cross-check of the {d['mode']} run: {d['text']}"
            if fmt == "github":
                print(_annotation("warning", text, None, "mpgspec cross-check", file=p.path))
            else:
                out(f"  {'WARN':5} {text}")
        if (bad := nominal_only_path(r)) is not None:
            if fmt == "github":
                print(_annotation("warning", path_text(bad), None, "mpgspec robust", file=p.path))
            else:
                out(f"  {'WARN':5} {path_text(bad)}")
        for k, path in p.files.items():
            out(f"  wrote {k}: {path}")
        _print_errors(p.errors, fmt)


def _against_baseline(res: VerifyResult, folder: str, fmt: str, allow_paths) -> int:
    """--baseline DIR: each verified project against DIR/<project>/report.json (mpgspec diff); an
    edge the baseline had and this run lost fails (exit 1) unless the project's baseline.may_lose
    names it. A project without a baseline report is noted, not failed. The spec is the one the run
    compiled, or (a project verified in another process) read again with the run's allow_paths."""
    from ..report.diff import diff_reports, load_for_diff
    from ..report.files import ReportWriteError, project_folder
    from ..spec.loader import load_project

    failed = 0
    for p in res.projects:
        if p.report is None:
            continue
        try:
            path = project_folder(folder, p.name)[1] / "report.json"
        except ReportWriteError as e:  # a name that is not a folder inside DIR
            print(_line(f"  NOTE  baseline: {e}; {p.name} not compared", fmt))
            continue
        if not path.is_file():
            print(_line(f"  NOTE  baseline: no {path}; {p.name} not compared", fmt))
            continue
        old, note = load_for_diff(path)
        if note:
            print(_line(f"  NOTE  baseline: {note}", fmt))
        spec = p.compiled.spec if p.compiled is not None else load_project(p.path, allow_paths)
        base = spec.project.baseline
        allowed = {(e.from_, e.to) for e in (base.may_lose if base else [])}
        where = spec.locate(("baseline", "may_lose")) if base else None
        for e in diff_reports(old, p.report)["edges_lost"]:
            text = f"baseline: edge {e['from']} -> {e['to']} (class {e['class']}) of {path} is lost"
            if (e["from"], e["to"]) in allowed:
                print(_line(f"  INFO  {text}, as baseline.may_lose allows", fmt))
                continue
            failed += 1
            if fmt == "github":
                at = {"file": where.file, "line": where.line, "column": where.column} if where else None
                print(_annotation("error", text, at, "mpgspec baseline", file=p.path))
            else:
                print(_line(f"  FAIL  {text} (name it in baseline.may_lose if that is intended)", fmt))
    return failed


def _check_jobs(jobs: int) -> None:
    cores = os.cpu_count() or 1
    if not 1 <= jobs <= JOBS_PER_CORE * cores:
        raise UsageError(f"--jobs must be between 1 and {JOBS_PER_CORE * cores} "
                             f"({JOBS_PER_CORE} per core, {cores} cores), not {jobs}")


SCHEDULER = re.compile(r"(tcp|tls|ws|wss|ucx|inproc)://([A-Za-z0-9._\-]+|\[[0-9A-Fa-f:.]+\])(:[0-9]{1,5})?")
"""A Dask scheduler address: protocol://host[:port] (an IPv6 host in brackets)."""


def _check_dask(args) -> None:
    """--dask is 'local' or a scheduler address, --scheduler an address; anything else (a shell
    fragment, an empty value, both options at once) is a usage error before any work starts."""
    if args.dask is not None and args.scheduler is not None:
        raise UsageError("give --dask or --scheduler, not both")
    for opt, value in (("--dask", args.dask), ("--scheduler", args.scheduler)):
        if value is None or (opt == "--dask" and value == "local"):
            continue
        if not SCHEDULER.fullmatch(value):
            raise UsageError(f"{opt} must be {'local or ' if opt == '--dask' else ''}a scheduler address such as "
                             f"tcp://host:8786, not {value[:80]!r}")


def _set_verify_cache(fraction) -> None:
    """--verify-cache F: the share of stored results every executor of this run (and of the
    processes it starts) runs again (oracle/cache.py, through MPGSPEC_VERIFY_CACHE)."""
    if fraction is None:
        return
    if not 0.0 <= fraction <= 1.0:
        raise UsageError(f"--verify-cache must be a fraction between 0 and 1, not {fraction:g}")
    os.environ[VERIFY_ENV] = repr(float(fraction))


def _verify(args, overrides: dict, show) -> VerifyResult:
    """Every project of args.paths verified and (unless --no-write) written: side by side, one
    process per project, when there are several, more than one job and no Dask; else here."""
    try:
        files = [f for p in args.paths for f in api.discover(p)]
    except UsageError:  # api.verify reports it
        files = []
    if len(files) > 1 and args.jobs > 1 and not (args.dask or args.scheduler):
        from ..pipeline.side_by_side import verify_side_by_side

        return verify_side_by_side(files, None if args.no_write else Path(args.out), overrides, show, args.jobs,
                                   not args.no_cache, args.jobs, args.allow_path or None)
    executor = api.executor(args.jobs, args.dask or args.scheduler, cache=not args.no_cache)
    res = api.verify(args.paths, out_dir=None, overrides=overrides, progress=show, executor=executor,
                     allow_paths=args.allow_path or None)
    if not args.no_write:
        api.write_reports(res, args.out, show)
    return res


def cmd_verify(args) -> int:
    overrides = {}
    if args.method:
        overrides["method"] = args.method
    from ..progress import summary

    if args.jobs is None:
        args.jobs = usable_cores()
    _check_jobs(args.jobs)
    _check_dask(args)
    _set_verify_cache(getattr(args, "verify_cache", None))
    t0 = time.perf_counter()
    show = None if args.quiet else _progress(sys.stderr, args.format)
    try:
        with stdout_to_stderr():  # solver logs and prints of the pipeline go to stderr
            res = _verify(args, overrides, show)
    finally:
        if show is not None:
            show.close()
    args.exit_code = res.exit_code
    strict = getattr(args, "strict", False)
    machine = args.format in MACHINE_FORMATS
    if args.format == "json":
        print(_json_doc(res))
    elif args.format == "junit":
        from ..report.ci import junit

        print(junit(res.projects, strict), end="")
    elif args.format == "sarif":
        from ..report.ci import sarif

        print(json.dumps(sarif(res.projects, strict, res.exit_code), separators=(",", ":")))
    else:
        _human(res, args.format)
        if len(res.projects) > 1 or not args.quiet:
            print(_line(summary(res.projects, time.perf_counter() - t0), args.format))
    if args.format == "github":
        _step_summary(res)
    with stdout_to_stderr() if machine else contextlib.nullcontext():  # stdout holds the document alone
        lost = _against_baseline(res, args.baseline, args.format, args.allow_path or None) \
            if getattr(args, "baseline", None) else 0
        warned = sum(warning_count(p.report) for p in res.projects if p.report is not None)
        strict_failed = strict and warned > 0
        if strict_failed:
            print(_line(f"FAIL --strict: {warned} warning{'s' if warned != 1 else ''}", args.format))
    mismatch = sum(int(((p.report or {}).get("timing") or {}).get("cache_mismatch", 0)) for p in res.projects)
    if mismatch:
        print(f"mpgspec: {mismatch} stored oracle results disagreed with a fresh run (--verify-cache): the result "
              "cache cannot be trusted; clear it with `mpgspec cache clear`", file=sys.stderr)
        return max(res.exit_code, 1)
    return max(res.exit_code, 1) if lost or strict_failed else res.exit_code
