"""Command line: a thin layer over mpgspec.api.

    mpgspec verify PATH [--out reports] [--format human|json|github]
    mpgspec plan PROJECT --from A --to B [--weight duration|peak_input|hops]
    mpgspec simulate PROJECT [--mode naive|graph|both]
    mpgspec schema [--kind project|report]

Exit codes: 0 all checks pass, 1 a check failed, 2 a spec or usage error.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys

from . import __version__, api
from .streams import stdout_to_stderr
from .errors import (EXIT_CHECK_FAILED, EXIT_OK, EXIT_USAGE, MpgError, SpecError, SpecErrors, gh_command,
                     gh_plain)
from .spec.yamlpos import format_context

MARK = {"pass": "PASS", "fail": "FAIL", "error": "ERROR", "warn": "WARN"}
JOBS_PER_CORE = 4


class Terminated(SystemExit):
    """SIGTERM (or SIGHUP) arrived: raised in the main thread so that every finally-block runs (report
    temporaries removed, worker processes terminated); exits with 128 + the signal number."""


def _on_signal(signum, frame):
    raise Terminated(128 + signum)


@contextlib.contextmanager
def _signal_handlers():
    """SIGTERM/SIGHUP raise Terminated while the command runs (Ctrl-C already raises KeyboardInterrupt)."""
    saved = {}
    for s in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if s is None:
            continue
        try:
            saved[s] = signal.signal(s, _on_signal)
        except (ValueError, OSError):  # not the main thread: leave signals alone
            pass
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


def _line(text: str, fmt: str) -> str:
    """A plain output line; with --format github, one that cannot start a workflow command."""
    return gh_plain(text) if fmt == "github" else text


def _progress(stream, fmt: str = "human"):
    def cb(project: str, what: str, i: int, n: int):
        print(_line(f"[{project}] {what} ({i}/{n})", fmt), file=stream, flush=True)
    return cb


def _print_errors(errors: list[dict], fmt: str):
    for e in errors:
        if fmt == "github":
            print(gh_command("error", e.get("text", e.get("message")), file=e.get("file", ""),
                             line=e.get("line", 0), col=e.get("column", 0), title=e.get("code", "")))
            continue
        print(e.get("text", e.get("message")), file=sys.stderr)
        if e.get("line"):
            try:
                print(format_context(e["file"], e["line"], column=e.get("column", 0)), file=sys.stderr)
            except OSError:
                pass


def _inconclusive(r: dict) -> str:
    v = r.get("verdicts") or {}
    return f", {v['inconclusive']} inconclusive" if v.get("inconclusive") else ""


def _cached(t: dict) -> str:
    return f", {int(t['cache_hits'])} from the cache" if t.get("cache_hits") else ""


def _num(v, spec: str = ".3g") -> str:
    try:
        return format(float(v), spec)
    except (TypeError, ValueError):
        return "?"


def _human(res: api.VerifyResult, fmt: str):
    def out(text: str):
        print(_line(text, fmt))

    for p in res.projects:
        if p.report is None:
            out(f"{MARK['error']} {p.path}")
            _print_errors(p.errors, fmt)
            continue
        r = p.report
        t = r["timing"]
        out(f"{MARK[p.status]} {p.name}: {len(r['primitives'])} primitives, {len(r['edges'])} edges, "
            f"{t['oracle_calls']} oracle calls (simulated) in {_num(t['graph_s'], '.2f')} s"
            f"{_inconclusive(r)}{_cached(t)}")
        for e in r["edges"]:
            out(f"    {e['from']} -> {e['to']}  class {e['class']}  duration {_num(e.get('duration') or 0)} s")
        for a in r["assertions"]:
            if fmt == "github" and a["status"] != "pass":
                print(gh_command("error", f"{a['description']}: {a['message']}", file=p.path,
                                 title="mpgspec assertion"))
            else:
                out(f"  {MARK[a['status']]:5} {a['description']}: {a['message']}")
        for c in r.get("assumptions", []):
            if c["status"] != "pass":
                out(f"  {c['status'].upper():5} assumption {c['name']} of {c['primitive']}: {c['message']}")
        for k, path in p.files.items():
            out(f"  wrote {k}: {path}")
        _print_errors(p.errors, fmt)


def _check_jobs(jobs: int) -> None:
    cores = os.cpu_count() or 1
    if not 1 <= jobs <= JOBS_PER_CORE * cores:
        raise api.UsageError(f"--jobs must be between 1 and {JOBS_PER_CORE * cores} "
                             f"({JOBS_PER_CORE} per core, {cores} cores), not {jobs}")


def _write(res: api.VerifyResult, out_dir: str) -> None:
    """Each project's report set into out_dir/<project>/ as a unit; a failure to write makes the
    project an error (exit 2) with the reason, never a PASS."""
    from .report.files import ReportWriteError, write_project_reports

    for p in res.projects:
        if p.report is None:
            continue
        try:
            p.files = write_project_reports(p.report, out_dir, p.report["project"]["name"])
        except ReportWriteError as e:
            why = str(e)
        except Exception as e:  # noqa: BLE001 - a bug in a writer: this project's error, not the run's end
            why = f"internal error while writing reports: {type(e).__name__}: {e}"
        else:
            continue
        p.status, p.files = "error", {}
        p.errors.append({"code": "MPG400", "file": str(p.path), "message": why, "text": f"{p.path}: MPG400 {why}"})


def _json_doc(res: api.VerifyResult | None, errors=(), code: int = EXIT_USAGE) -> str:
    from .report.build import finite_json

    doc = {"exit_code": res.exit_code if res is not None else code, "projects": [] if res is None else [
        {"path": str(p.path), "name": p.name, "status": p.status, "errors": p.errors, "files": p.files,
         "assertions": p.report["assertions"] if p.report else []} for p in res.projects]}
    if errors:
        doc["errors"] = list(errors)
    return json.dumps(finite_json(doc), indent=1, allow_nan=False, default=str)


def cmd_verify(args) -> int:
    overrides = {}
    if args.method:
        overrides["method"] = args.method
    from .oracle.executors import make_executor

    _check_jobs(args.jobs)
    with stdout_to_stderr():  # solver logs and prints of the pipeline go to stderr
        executor = make_executor(args.jobs, args.dask or args.scheduler, cache=not args.no_cache)
        res = api.verify(args.paths, out_dir=None, overrides=overrides,
                         progress=None if args.quiet else _progress(sys.stderr, args.format), executor=executor,
                         allow_paths=args.allow_path or None)
        if not args.no_write:
            _write(res, args.out)
    args.exit_code = res.exit_code
    if args.format == "json":
        print(_json_doc(res))
    else:
        _human(res, args.format)
    return res.exit_code


def cmd_cache(args) -> int:
    from .oracle import cache

    d = cache.clear() if args.action == "clear" else cache.info()
    verb = "removed" if args.action == "clear" else "holds"
    print(f"{d['folder']} {verb}: {d['oracle_results']} oracle results ({d['results_bytes'] / 1e6:.1f} MB), "
          f"{d['compiled_chunks']} compiled chunks ({d['compiled_bytes'] / 1e6:.1f} MB)")
    return EXIT_OK


def _one_project(path):
    files = api.discover(path)
    if len(files) != 1:
        raise api.UsageError(f"{path}: expected one project, found {len(files)}")
    spec = api.load_project(files[0])
    settings = api.settings_for(spec)
    cp, vg = api.build(spec, settings)
    return spec, settings, cp.prims, vg.graph


def cmd_plan(args) -> int:
    from .plan.planner import shortest_plan

    spec, _, prims, g = _one_project(args.project)
    for n in (args.source, args.goal):
        if n not in prims:
            raise api.UsageError(f"unknown primitive {n!r}; expected one of {', '.join(prims)}")
    plan = shortest_plan(g, args.source, args.goal, args.weight)
    args.exit_code = EXIT_OK if plan.found else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps(plan.to_dict(), indent=1))
    elif plan.found:
        print(" -> ".join(plan.path) + f"   ({args.weight} {plan.cost:.4g})")
    else:
        print(f"no safe transition sequence from {args.source} to {args.goal}")
    return EXIT_OK if plan.found else EXIT_CHECK_FAILED


def cmd_simulate(args) -> int:
    from .execute.sequence import simulate_sequence
    from .plan.planner import lookup_table

    spec, settings, prims, g = _one_project(args.project)
    if spec.project.sequence is None:
        raise api.UsageError(f"{spec.path}: the project has no 'sequence'")
    table = lookup_table(g)
    modes = ("naive", "graph") if args.mode == "both" else (args.mode,)
    runs = {m: simulate_sequence(prims, g, table, spec.project.sequence, settings, m) for m in modes}
    args.exit_code = EXIT_OK if all(r.safe for r in runs.values()) else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps({m: {k: v for k, v in r.to_dict().items() if k in ("mode", "safe", "switches", "violations",
                                                                             "final_primitive", "failed")}
                          for m, r in runs.items()}, indent=1))
    else:
        for m, r in runs.items():
            print(f"{m}: {'safe' if r.safe else 'UNSAFE'}; ends in {r.final_primitive}")
            for s in r.switches:
                print(f"    t = {s['t']:7.3f} s  -> {s['to']} (clock {s['clock']:.3f}; {s['reason']})")
            if r.violations:
                v = r.violations[0]
                print(f"    first violation: {v['h']} of {v['primitive']} at t = {v['t']:.3f} s ({v['value']:.3g})")
    return EXIT_OK if all(r.safe for r in runs.values()) else EXIT_CHECK_FAILED


def cmd_schema(args) -> int:
    if args.kind == "report":
        from importlib.resources import files

        print(files("mpgspec.report").joinpath("schema/report-v1.json").read_text())
    else:
        from .spec.models import Project

        print(json.dumps(Project.model_json_schema(by_alias=True), indent=1))
    return EXIT_OK


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="mpgspec", description="Verify safe transitions between motion primitives.")
    ap.add_argument("--version", action="version", version=f"mpgspec {__version__}")
    sub = ap.add_subparsers(dest="cmd", required=True)
    v = sub.add_parser("verify", help="build the motion primitive graph, check assertions, write reports")
    v.add_argument("paths", nargs="+", help="a project.yaml, a project folder, or a folder of projects")
    v.add_argument("--out", default="reports", help="report folder (default: reports)")
    v.add_argument("--no-write", action="store_true", help="write no report files")
    v.add_argument("--format", choices=("human", "json", "github"), default="human")
    v.add_argument("--method", help="oracle backend (default: the project's, usually rk4)")
    v.add_argument("-j", "--jobs", type=int, default=1, help="local worker processes for oracle calls (default 1)")
    v.add_argument("--dask", metavar="local|ADDRESS",
                   help="run oracle calls on Dask: 'local' starts a LocalCluster of max(jobs, 2) workers, "
                        "or the address of a running scheduler (needs the 'dask' extra)")
    v.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler (same as --dask ADDRESS)")
    v.add_argument("--allow-path", action="append", metavar="DIR", default=[],
                   help="a folder outside the project that specs may name files in (repeatable)")
    v.add_argument("--no-cache", action="store_true",
                   help="run every oracle call, ignoring and not storing results in the cache")
    v.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    v.set_defaults(fn=cmd_verify)
    p = sub.add_parser("plan", help="shortest safe transition sequence between two primitives")
    p.add_argument("project")
    p.add_argument("--from", dest="source", required=True)
    p.add_argument("--to", dest="goal", required=True)
    p.add_argument("--weight", choices=("duration", "peak_input", "hops"), default="duration")
    p.add_argument("--format", choices=("human", "json"), default="human")
    p.set_defaults(fn=cmd_plan)
    s = sub.add_parser("simulate", help="run the project's goal sequence naive and through the graph")
    s.add_argument("project")
    s.add_argument("--mode", choices=("naive", "graph", "both"), default="both")
    s.add_argument("--format", choices=("human", "json"), default="human")
    s.set_defaults(fn=cmd_simulate)
    k = sub.add_parser("cache", help="show or clear stored oracle results and compiled chunks")
    k.add_argument("action", choices=("info", "clear"))
    k.set_defaults(fn=cmd_cache)
    c = sub.add_parser("schema", help="print the JSON Schema of project specs (or of reports)")
    c.add_argument("--kind", choices=("project", "report"), default="project")
    c.set_defaults(fn=cmd_schema)
    return ap


def _silence_stdout() -> None:
    """The reader of stdout went away: point fd 1 at /dev/null so that nothing more (not even the
    interpreter's last flush) fails."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):
        pass


def _fail(args, errors: list[dict], plain: str | None = None, code: int = EXIT_USAGE) -> int:
    """Report an error that ended the command; exit code 2 (or code). With verify --format json the
    error is the JSON document on stdout as well."""
    args.exit_code = code
    fmt = getattr(args, "format", "human")
    if getattr(args, "cmd", None) == "verify" and fmt == "json":
        print(_json_doc(None, errors, code))
    if plain is not None:
        print(gh_command("error", plain) if fmt == "github" else plain, file=sys.stderr)
    else:
        _print_errors(errors, fmt)
    return code


def _run(args) -> int:
    try:
        return args.fn(args)
    except SpecErrors as e:
        return _fail(args, [x.to_dict() | {"text": x.format()} for x in e.errors])
    except SpecError as e:
        return _fail(args, [e.to_dict() | {"text": e.format()}])
    except MpgError as e:
        return _fail(args, [{"code": e.code, "message": str(e)}], f"mpgspec: {e.code} {e}")
    except BrokenPipeError:
        raise
    except KeyboardInterrupt:
        return _fail(args, [{"code": "MPG002", "message": "interrupted"}], "mpgspec: interrupted")
    except Terminated as e:
        return _fail(args, [{"code": "MPG002", "message": "terminated by a signal"}], "mpgspec: terminated", e.code)
    except Exception as e:  # a bug, not the user's mistake: say so, keep the details
        import traceback

        rc = _fail(args, [{"code": "MPG900", "message": f"internal error: {type(e).__name__}: {e}"}],
                   f"mpgspec: internal error: {type(e).__name__}: {e}")
        if os.environ.get("MPGSPEC_DEBUG"):
            traceback.print_exc()
        else:
            print("set MPGSPEC_DEBUG=1 for the traceback", file=sys.stderr)
        return rc


def main(argv=None) -> int:
    args = argparse.Namespace()
    try:
        with _signal_handlers():
            try:
                args = parser().parse_args(argv)
            except SystemExit as e:
                return EXIT_USAGE if e.code not in (0, None) else EXIT_OK
            rc = _run(args)
            sys.stdout.flush()  # here, so that a closed pipe is seen while the exit code is known
            return rc
    except BrokenPipeError:  # the reader went away (e.g. `| head`): stop quietly, keep the exit code
        _silence_stdout()
        return getattr(args, "exit_code", EXIT_OK)
    except Terminated as e:  # a signal while an error was being reported
        return e.code


if __name__ == "__main__":
    sys.exit(main())
