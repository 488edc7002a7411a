"""Command line: a thin layer over mpgspec.api.

    mpgspec verify PATH [--out reports] [--format human|json|github]
    mpgspec plan PROJECT --from A --to B [--weight duration|peak_input|hops]
    mpgspec simulate PROJECT [--mode naive|graph|both] [--uncertain --runs N --seed S]
    mpgspec schema [--kind project|primitive|system|report]

plan and simulate reuse what verify wrote (reports/<project>/report.json) while it matches the
spec files, and rebuild otherwise.

Exit codes: 0 all checks pass, 1 a check failed, 2 a spec or usage error.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import time
from pathlib import Path

from . import __version__
from .streams import stdout_to_stderr
from .errors import (EXIT_CHECK_FAILED, EXIT_OK, EXIT_USAGE, MpgError, SpecError, SpecErrors, UsageError,
                     gh_command, gh_plain)
from .spec.yamlpos import format_context

MARK = {"pass": "PASS", "fail": "FAIL", "error": "ERROR", "warn": "WARN"}


class _Api:
    """mpgspec.api, imported on first use: plan from a verified report needs none of it."""

    def __getattr__(self, name):
        from . import api as module

        return getattr(module, name)


api = _Api()
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
    """Phases with elapsed time: live on a terminal (human format), plain lines otherwise."""
    from .progress import Display

    return Display(stream, live=None if fmt == "human" else False, line=lambda text: _line(text, fmt))


def _print_errors(errors: list[dict], fmt: str):
    for e in errors:
        if fmt == "github":
            print(_annotation("error", e.get("text", e.get("message")), e, e.get("code", "") or None))
            continue
        print(e.get("text", e.get("message")), file=sys.stderr)
        if e.get("line"):
            try:
                print(format_context(e["file"], e["line"], column=e.get("column", 0)), file=sys.stderr)
            except OSError:
                pass


def _rel(path) -> str:
    """A path relative to the working folder when it lies below it (how GitHub names files)."""
    try:
        return os.path.relpath(path) if not os.path.relpath(path).startswith("..") else str(path)
    except (ValueError, OSError):
        return str(path)


def _annotation(kind: str, message, where: dict | None, title: str | None = None, file=None) -> str:
    """A GitHub workflow command; file, line and col only where they are known (never line=0)."""
    where = where or {}
    f = where.get("file") or file
    line = where.get("line") or None
    return gh_command(kind, message, file=_rel(f) if f else None, line=line,
                      col=(where.get("column") or None) if line else None, title=title)


def _step_summary(res) -> None:
    """A Markdown table of the run appended to $GITHUB_STEP_SUMMARY (when set)."""
    path = os.environ.get("GITHUB_STEP_SUMMARY")
    if not path:
        return

    def cell(v) -> str:
        return str(v).replace("|", "\\|").replace("\n", " ")

    rows = ["| project | result | primitives | edges | oracle calls | assertions | warnings |",
            "|---|---|---|---|---|---|---|"]
    for p in res.projects:
        if p.report is None:
            why = "; ".join(e.get("message", "") for e in p.errors)[:300]
            rows.append(f"| {cell(p.name or p.path)} | ERROR | {cell(why)} | | | | |")
            continue
        r = p.report
        a = r.get("assertions", [])
        warns = sum(c["status"] == "warn" for c in r.get("assumptions", []))
        failed = [x for x in a if x["status"] != "pass"]
        rows.append("| " + " | ".join(cell(v) for v in (
            p.name or p.path, MARK.get(p.status, p.status.upper()), len(r.get("primitives", [])), len(r.get("edges", [])),
            (r.get("timing") or {}).get("oracle_calls", "–"),
            f"{len(a) - len(failed)}/{len(a)} pass" + (f" (failed: {'; '.join(x['description'] for x in failed)})"
                                                        if failed else ""), warns)) + " |")
        for e in p.errors:  # e.g. the reports could not be written
            rows.append(f"| {cell(p.name or p.path)} | ERROR | {cell(e.get('message', ''))} | | | | |")
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write("### mpgspec verify\n\n" + "\n".join(rows) + "\n\n")
    except OSError as e:
        print(f"mpgspec: cannot write the step summary {path}: {e}", file=sys.stderr)


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
        total = sum(v for k, v in t.items() if k.endswith("_s") and not k.endswith("per_s")
                    and isinstance(v, (int, float)))
        out(f"{MARK[p.status]} {p.name}: {len(r['primitives'])} primitives, {len(r['edges'])} edges, "
            f"{t['oracle_calls']} oracle calls (simulated) in {_num(t['graph_s'], '.2f')} s"
            f"{_inconclusive(r)}{_cached(t)}; {_num(total, '.1f')} s for the project")
        for e in r["edges"]:
            out(f"    {e['from']} -> {e['to']}  class {e['class']}  duration {_num(e.get('duration') or 0)} s")
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
                print(_annotation("warning" if c["status"] == "warn" else "error", text, c.get("location"),
                                  "mpgspec assumption", file=p.path))
            else:
                out(f"  {c['status'].upper():5} {text}")
        for k, path in p.files.items():
            out(f"  wrote {k}: {path}")
        _print_errors(p.errors, fmt)


def _check_jobs(jobs: int) -> None:
    cores = os.cpu_count() or 1
    if not 1 <= jobs <= JOBS_PER_CORE * cores:
        raise UsageError(f"--jobs must be between 1 and {JOBS_PER_CORE * cores} "
                             f"({JOBS_PER_CORE} per core, {cores} cores), not {jobs}")


def _write(res: api.VerifyResult, out_dir: str, progress=None) -> None:
    """Each project's report set into out_dir/<project>/ as a unit; a failure to write makes the
    project an error (exit 2) with the reason, never a PASS."""
    from .report.files import ReportWriteError, write_project_reports

    for p in res.projects:
        if p.report is None:
            continue
        if progress is not None:
            progress(p.name, "report (JSON, HTML, graph files)", 0, 1)
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
         "assertions": p.report["assertions"] if p.report else [], "report": p.report} for p in res.projects]}
    if errors:
        doc["errors"] = list(errors)
    return json.dumps(finite_json(doc), indent=1, allow_nan=False, default=str)


def cmd_verify(args) -> int:
    overrides = {}
    if args.method:
        overrides["method"] = args.method
    from .oracle.executors import make_executor

    from .progress import summary

    _check_jobs(args.jobs)
    t0 = time.perf_counter()
    show = None if args.quiet else _progress(sys.stderr, args.format)
    try:
        with stdout_to_stderr():  # solver logs and prints of the pipeline go to stderr
            executor = make_executor(args.jobs, args.dask or args.scheduler, cache=not args.no_cache)
            res = api.verify(args.paths, out_dir=None, overrides=overrides, progress=show, executor=executor,
                             allow_paths=args.allow_path or None)
            if not args.no_write:
                _write(res, args.out, show)
    finally:
        if show is not None:
            show.close()
    args.exit_code = res.exit_code
    if args.format == "json":
        print(_json_doc(res))
    else:
        _human(res, args.format)
        if len(res.projects) > 1 or not args.quiet:
            print(_line(summary(res.projects, time.perf_counter() - t0), args.format))
    if args.format == "github":
        _step_summary(res)
    return res.exit_code


def cmd_cache(args) -> int:
    from .oracle import cache

    d = cache.clear() if args.action == "clear" else cache.info()
    verb = "removed" if args.action == "clear" else "holds"
    print(f"{d['folder']} {verb}: {d['oracle_results']} oracle results ({d['results_bytes'] / 1e6:.1f} MB), "
          f"{d['compiled_chunks']} compiled chunks ({d['compiled_bytes'] / 1e6:.1f} MB)")
    return EXIT_OK


def _load_one(path):
    """The one project at path (file or folder), loaded but not compiled."""
    from .spec.loader import discover, load_project

    files = discover(path)
    if len(files) != 1:
        raise UsageError(f"{path}: expected one project, found {len(files)}")
    return load_project(files[0])


def _quick_report(project: str, out: str, rebuild: bool) -> dict | None:
    """The report `verify` wrote for the project at `project` when it matches the spec files, found
    without loading the spec (its name is read from project.yaml); None otherwise."""
    if rebuild:
        return None
    from .report.read import report_status
    from .spec.yamlpos import parse_yaml

    f = Path(project)
    f = f / "project.yaml" if f.is_dir() else f
    try:
        data = parse_yaml(f.read_text(encoding="utf-8"), str(f))[0] if f.is_file() else None
    except (OSError, ValueError, MpgError):
        return None
    name = data.get("project") if isinstance(data, dict) else None
    if not isinstance(name, str) or not name.strip() or Path(name).name != name or name.startswith("."):
        return None
    return report_status(Path(out) / name / "report.json", f)[0]


def _verified(spec, out: str, rebuild: bool, quiet: bool = False):
    """The project's report from `verify` when it matches the spec files, else None (saying why
    on stderr, unless quiet)."""
    from .report.read import report_status

    if rebuild:
        return None
    report, why = report_status(Path(out) / spec.name / "report.json", spec.path)
    if report is None and not quiet:
        print(f"mpgspec: {why}; rebuilding the graph (run `mpgspec verify` to store it)", file=sys.stderr)
    return report


def _build(spec):
    settings = api.settings_for(spec)
    executor = _cached_executor()
    cp, vg = api.build(spec, settings, executor=executor)
    return settings, cp.prims, vg.graph


def _build_robust(spec):
    """The robust graph of a project that declares `uncertainty`."""
    if spec.project.uncertainty is None:
        raise UsageError(f"{spec.name} declares no `uncertainty`: there is no robust graph to plan on")
    settings = api.settings_for(spec)
    cp, vg = api.build(spec, settings, executor=_cached_executor())
    return api.robust_stage(cp, vg).graph


def _cached_executor():
    from .oracle.executors import make_executor

    return make_executor(1, None, cache=True)


def _window_text(ws) -> str:
    return ", ".join(f"[{_num(a, '.4g')}, {_num(b, '.4g')}]" for a, b in ws)


def cmd_plan(args) -> int:
    from .report.read import ReportGraph, hops, shortest_path

    report = _quick_report(args.project, args.out, args.rebuild)
    spec = None if report is not None else _load_one(args.project)
    name = report["project"]["name"] if report is not None else spec.name
    names = [p["name"] for p in report["primitives"]] if report is not None else [p.name for p in spec.primitives]
    for n in (args.source, args.goal):
        if n not in names:
            raise UsageError(f"unknown primitive {n!r}; expected one of {', '.join(names)}")
    if report is None:
        report = _verified(spec, args.out, args.rebuild, quiet=args.format == "json")
    if report is not None:
        if args.robust:
            from .robust.plan import robust_report_graph

            g = robust_report_graph(report)
        else:
            g = ReportGraph(report)
        path, cost = shortest_path(g.planner_graph(), args.source, args.goal, args.weight)
        edge, source = g.edge, str(Path(args.out) / name / "report.json")
    else:
        from .plan.planner import shortest_plan

        with stdout_to_stderr():
            if args.robust:
                graph = _build_robust(spec)
            else:
                _, _, graph = _build(spec)
        plan = shortest_plan(graph, args.source, args.goal, args.weight)
        path, cost, edge, source = plan.path, plan.cost, graph.edge, "rebuilt"
    steps = hops(edge, path)
    found = path is not None
    args.exit_code = EXIT_OK if found else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps({"from": args.source, "to": args.goal, "weight": args.weight, "path": path, "cost": cost,
                          "hops": steps, "source": source}, indent=1))
    elif found:
        print(" -> ".join(path) + f"   ({args.weight} {cost:.4g})")
        for h in steps:
            wait = (f"wait until t_A of {h['from']} is in {_window_text(h['windows'])} s" if h["class"] == 2
                    else "switch at any t_A")
            print(f"  {h['from']} -> {h['to']}: class {h['class']}, {_num(h['duration'], '.3g')} s; {wait}")
    else:
        print(f"no safe transition sequence from {args.source} to {args.goal}")
    return args.exit_code


def _expected(spec) -> dict[str, bool]:
    """mode -> the simulation_safe expectation of the project (safe when not asserted)."""
    out = {}
    for a in spec.project.assertions:
        mode = getattr(a, "simulation_safe", None)
        if isinstance(mode, str):
            out[mode] = bool(getattr(a, "expect", True))
    return out


def _simulate_uncertain(args, spec, report) -> int:
    """The goal sequence under seeded draws of the project's uncertainty: the fraction of runs that
    stay safe naive, through the nominal graph and through the robust graph. Exit 0 when every
    robust-graph run stays safe."""
    from .plan.planner import lookup_table
    from .robust.sequence import sequence_under_uncertainty

    unc = spec.project.uncertainty
    if unc is None:
        raise UsageError(f"{spec.path}: the project declares no `uncertainty` to sample")
    runs = unc.runs if args.runs is None else args.runs
    seed = unc.seed if args.seed is None else args.seed
    if not 1 <= runs <= 100000:
        raise UsageError(f"--runs must be between 1 and 100000; got {runs}")
    with stdout_to_stderr():
        settings = api.settings_for(spec)
        if report is not None and report.get("robust"):
            from .report.read import ReportGraph
            from .robust.plan import report_lookup_table, robust_report_graph

            cp = api.compile_stage(spec, settings, memo=getattr(_cached_executor(), "memo", None))
            rg = robust_report_graph(report)
            graphs = {"graph": (ReportGraph(report), report["lookup_table"]["next"]),
                      "robust_graph": (rg, report_lookup_table(rg))}
        else:
            executor = _cached_executor()
            cp, vg = api.build(spec, settings, executor=executor)
            rob = api.robust_stage(cp, vg, memo=getattr(executor, "memo", None))
            graphs = {"graph": (vg.graph, lookup_table(vg.graph)), "robust_graph": (rob.graph, lookup_table(rob.graph))}
        stats = sequence_under_uncertainty(spec, cp.prims, settings, graphs, runs, seed)
    modes = stats["modes"]
    args.exit_code = EXIT_OK if modes["robust_graph"]["safe_runs"] == runs else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps({**stats, "modes": {m: {k: v for k, v in r.items() if k != "final"} for m, r in modes.items()},
                          "uncertainty": {"parameters": {n: list(r.range) for n, r in unc.parameters.items()},
                                          "initial_state": dict(unc.initial_state),
                                          "disturbance": unc.disturbance.model_dump() if unc.disturbance else None}},
                         indent=1))
        return args.exit_code
    print(f"{runs} seeded runs (seed {seed}) of the goal sequence: parameters, start error and a disturbance held "
          f"{stats['disturbance_hold_s']:g} s drawn uniformly from the project's uncertainty")
    for m, r in modes.items():
        first = r["first_violation"][0] if r["first_violation"] else None
        why = "" if first is None else (f"; first unsafe at t = {first['t']:.3f} s in {first['primitive']}"
                                        + (f" ({first['h']} = {first['value']:.4g})" if first.get("h") else "")
                                        + (f" ({first['error']})" if first.get("error") else "")
                                        + (f" (unverified hand-over to {first['unverified_hand_over']})"
                                           if first.get("unverified_hand_over") else ""))
        print(f"  {m.replace('_', ' '):13} {r['safe_runs']:>5} / {r['runs']} safe ({100 * r['safe_fraction']:.1f} %), "
              f"{r.get('reached_goal', 0)} safe in the last goal{why}")
    return args.exit_code


def cmd_simulate(args) -> int:
    from .execute.sequence import simulate_sequence

    spec = _load_one(args.project)
    if spec.project.sequence is None:
        raise UsageError(f"{spec.path}: the project has no 'sequence'")
    xcs = None
    if args.crosscheck:
        from .execute.crosscheck.settings import settings_of

        if args.uncertain:
            raise UsageError("--crosscheck replays the nominal runs; it does not apply to --uncertain")
        xcs = settings_of(spec, force=True)
    report = _verified(spec, args.out, args.rebuild, quiet=args.format == "json")
    if args.uncertain:
        return _simulate_uncertain(args, spec, report)
    if args.runs is not None or args.seed is not None:
        raise UsageError("--runs and --seed apply to --uncertain runs only")
    with stdout_to_stderr():
        if report is not None:
            from .report.read import ReportGraph

            settings = api.settings_for(spec)
            cp = api.compile_stage(spec, settings, memo=getattr(_cached_executor(), "memo", None))
            prims, g, table = cp.prims, ReportGraph(report), report["lookup_table"]["next"]
        else:
            from .plan.planner import lookup_table

            settings, prims, g = _build(spec)
            table = lookup_table(g)
        modes = ("naive", "graph") if args.mode == "both" else (args.mode,)
        runs = {m: simulate_sequence(prims, g, table, spec.project.sequence, settings, m) for m in modes}
        if xcs is not None:
            from .execute.crosscheck import crosscheck_runs

            xc = crosscheck_runs(prims, runs, spec.project.sequence.duration, xcs.replace(runs=modes),
                                 settings.h_tolerance).runs
    expect = _expected(spec)
    ok = {m: r.safe == expect.get(m, True) for m, r in runs.items()}
    args.exit_code = EXIT_OK if all(ok.values()) and (xcs is None or all(x["agree"] for x in xc.values())) \
        else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps({m: {**{k: v for k, v in r.to_dict().items() if k in (
            "mode", "safe", "switches", "violations", "final_primitive", "failed")},
            "expected_safe": expect.get(m, True), "as_expected": ok[m],
            **({"crosscheck": {k: v for k, v in xc[m].items() if k != "series"}} if xcs is not None else {})}
            for m, r in runs.items()}, indent=1, default=float))
    else:
        for m, r in runs.items():
            note = "as expected" if ok[m] else f"NOT as expected: the project expects it to be " \
                                                f"{'safe' if expect.get(m, True) else 'unsafe'}"
            print(f"{m}: {'safe' if r.safe else 'UNSAFE'}; ends in {r.final_primitive} ({note})")
            for sw in r.switches:
                print(f"    t = {sw['t']:7.3f} s  -> {sw['to']} (clock {sw['clock']:.3f}; {sw['reason']})")
            if r.violations:
                v = r.violations[0]
                print(f"    first violation: {v['h']} of {v['primitive']} at t = {v['t']:.3f} s ({v['value']:.3g})")
            if xcs is not None:
                print("    " + _crosscheck_line(xc[m]))
    return args.exit_code


def _crosscheck_line(x: dict) -> str:
    """One replayed run: the simulator's verdict, agreement and the largest divergences."""
    fv, dv = x["mujoco"]["first_violation"], x["divergence"]
    verdict = "safe" if x["mujoco"]["safe"] else "UNSAFE" + (
        f" (first: {fv['h']} of {fv['primitive']} at t = {fv['t']:.3f} s)" if fv else f" ({x['mujoco']['failed']})")
    com = f"{1000 * dv['com']['max']:.3g} mm" if dv["com"] else "-"
    joint = f"{dv['joint']['max']:.3g} rad" if dv["joint"] else "-"
    return (f"MuJoCo: {verdict}; {'agrees' if x['agree'] else 'DISAGREES'}; largest divergence: CoM {com}, "
            f"joints {joint}")


def cmd_schema(args) -> int:
    if args.kind == "report":
        from .report.schema import schema_path

        print(schema_path().read_text(encoding="utf-8"), end="")
    else:
        from .spec.schema import spec_schema

        print(json.dumps(spec_schema(args.kind), indent=1, ensure_ascii=False))
    return EXIT_OK


def cmd_gait(args) -> int:
    """Generate (or with --check, compare) the gait tables of a gait file."""
    from .compile.system import compile_system
    from .robots.quadruped.gait.library import GaitTable, compare, generate, load_gait_file, write
    from .spec.loader import load_project

    path = Path(args.file)
    say = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
    tables = generate(path, progress=say)
    gf = load_gait_file(path)
    names = compile_system(load_project(path.parent / gf.project)).state_names
    bad = [t.node for t in tables if isinstance(t, GaitTable) and (t.orbit.status != "converged"
                                                                   or not t.orbit.spectral_radius < 1)]
    if args.check:
        problems = compare(tables, names)
        for p_ in problems:
            print(f"stale: {p_}")
        if not problems:
            print(f"{len(tables)} gait tables match their regeneration")
        return EXIT_CHECK_FAILED if problems or bad else EXIT_OK
    write(tables, names)
    for t in tables:
        print(f"wrote {t.path}")
    for n in bad:
        print(f"{n}: no stable orbit (see the table's header)")
    return EXIT_CHECK_FAILED if bad else EXIT_OK


def _sub(sub, name: str, help: str, examples: str):
    return sub.add_parser(name, help=help, description=help[0].upper() + help[1:] + ".",
                          epilog="examples:\n" + examples, formatter_class=argparse.RawDescriptionHelpFormatter)


def _verified_results_args(p, used: str) -> None:
    """--out and --rebuild of the commands that read what `verify` wrote."""
    p.add_argument("--out", default="reports", metavar="DIR",
                   help=f"where `verify` wrote its reports; {used} used while the specs match (default: reports)")
    p.add_argument("--rebuild", action="store_true", help="build the graph again instead of reading the report")


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="mpgspec", description="Verify safe transitions between motion primitives.",
        epilog="exit codes: 0 every assertion holds, 1 an assertion failed, 2 a spec or usage error\n"
               "run `mpgspec COMMAND --help` for a command's options and examples",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"mpgspec {__version__}")
    sub = ap.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    v = _sub(sub, "verify", "build the motion primitive graph, check assertions, write reports",
             "  mpgspec verify specs/                      every project below specs/\n"
             "  mpgspec verify specs/pendulum -j 2         oracle calls in 2 processes\n"
             "  mpgspec verify specs/ --format github      annotations and a step summary in GitHub Actions\n"
             "  mpgspec verify specs/cart --format json --no-write > result.json")
    v.add_argument("paths", nargs="+", metavar="PATH", help="a project.yaml, a project folder, or a folder of projects")
    v.add_argument("--out", default="reports", metavar="DIR",
                   help="report folder; each project gets DIR/<project>/ (default: reports)")
    v.add_argument("--no-write", action="store_true", help="write no report files")
    v.add_argument("--format", choices=("human", "json", "github"), default="human",
                   help="human: text (default); json: the whole result on stdout; github: workflow annotations "
                        "at the spec lines, plus a table in $GITHUB_STEP_SUMMARY when it is set")
    v.add_argument("--method", metavar="NAME", help="oracle backend, e.g. rk4 or scipy (default: the project's)")
    v.add_argument("-j", "--jobs", type=int, default=1, metavar="N",
                   help="local worker processes for oracle calls (default 1)")
    v.add_argument("--dask", metavar="local|ADDRESS",
                   help="run oracle calls on Dask: 'local' starts a LocalCluster of max(jobs, 2) workers, "
                        "or the address of a running scheduler (needs the 'dask' extra)")
    v.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler (same as --dask ADDRESS)")
    v.add_argument("--allow-path", action="append", metavar="DIR", default=[],
                   help="a folder outside the project that specs may name files in (repeatable)")
    v.add_argument("--no-cache", action="store_true",
                   help="run every oracle call, ignoring and not storing results in the cache")
    v.add_argument("-q", "--quiet", action="store_true", help="no progress display")
    v.set_defaults(fn=cmd_verify)
    p = _sub(sub, "plan", "shortest safe transition sequence between two primitives",
             "  mpgspec plan specs/pendulum --from Hang --to Balance\n"
             "  mpgspec plan specs/pendulum --from SwingUp --to Hang --weight hops --format json")
    p.add_argument("project", metavar="PROJECT", help="a project.yaml or its folder")
    p.add_argument("--from", dest="source", required=True, metavar="A", help="the primitive to start from")
    p.add_argument("--to", dest="goal", required=True, metavar="B", help="the primitive to reach")
    p.add_argument("--weight", choices=("duration", "peak_input", "hops"), default="duration",
                   help="what the plan minimises: summed transition duration (default), peak input, or hops")
    p.add_argument("--format", choices=("human", "json"), default="human",
                   help="human: the path and each hop with its class and waiting window; json: the same as JSON")
    _verified_results_args(p, "its graph is")
    p.add_argument("--robust", action="store_true",
                   help="use only the edges that withstood the project's `uncertainty` (the robust graph)")
    p.set_defaults(fn=cmd_plan)
    s = _sub(sub, "simulate", "run the project's goal sequence naive and through the graph",
             "  mpgspec simulate specs/pendulum              both runs; exit 0 when each is as the project expects\n"
             "  mpgspec simulate specs/pendulum --mode graph --format json\n"
             "  mpgspec simulate specs/pendulum --uncertain --runs 64 --seed 1")
    s.add_argument("project", metavar="PROJECT", help="a project.yaml or its folder")
    s.add_argument("--mode", choices=("naive", "graph", "both"), default="both",
                   help="naive: switch to each goal at once; graph: follow the lookup table and wait for "
                        "verified windows; both (default)")
    s.add_argument("--format", choices=("human", "json"), default="human",
                   help="human: switches and the first violation of each run; json: the runs as JSON")
    s.add_argument("--uncertain", action="store_true",
                   help="run the sequence under seeded draws of the project's `uncertainty` (parameters, start "
                        "error, disturbance) naive, through the nominal and through the robust graph, and give "
                        "the fraction of runs that stay safe in each; exit 0 when every robust-graph run is safe")
    s.add_argument("--runs", type=int, metavar="N", help="with --uncertain: how many draws (default: uncertainty.runs)")
    s.add_argument("--seed", type=int, metavar="S", help="with --uncertain: the seed (default: uncertainty.seed)")
    s.add_argument("--crosscheck", action="store_true",
                   help="also replay the runs in MuJoCo (the project's `crosscheck` settings, else defaults; the "
                        "xcheck extra) and compare verdicts and trajectories; exit 1 when a verdict differs")
    _verified_results_args(s, "its graph and lookup table are")
    s.set_defaults(fn=cmd_simulate)
    k = _sub(sub, "cache", "show or clear stored oracle results and compiled chunks",
             "  mpgspec cache info\n  mpgspec cache clear")
    k.add_argument("action", choices=("info", "clear"), help="info: what is stored; clear: remove it all")
    k.set_defaults(fn=cmd_cache)
    c = _sub(sub, "schema", "print a JSON Schema: of project, primitive or system spec files, or of report.json",
             "  mpgspec schema > project.schema.json\n"
             "  mpgspec schema --kind primitive > primitive.schema.json\n"
             "  then, first line of a spec file: # yaml-language-server: $schema=project.schema.json")
    c.add_argument("--kind", choices=("project", "primitive", "system", "report"), default="project",
                   help="project.yaml (default), a primitive file, a system file, or report.json")
    c.set_defaults(fn=cmd_schema)
    g = _sub(sub, "gait", "generate the gait tables of trot primitives: each node's orbit, command and multipliers",
             "  mpgspec gait specs/a1/gaits.yaml            write specs/a1/gaits/*.csv\n"
             "  mpgspec gait specs/a1/gaits.yaml --check    exit 1 when the tables on disk are stale")
    g.add_argument("file", metavar="GAITS", help="a gait file (project, primitive, dt)")
    g.add_argument("--check", action="store_true", help="regenerate in memory and compare with the tables on disk")
    g.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    g.set_defaults(fn=cmd_gait)
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
