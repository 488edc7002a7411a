"""The command line's arguments: one function per command, each with its help and examples."""
from __future__ import annotations

import argparse

from .. import __version__
from ..cores import usable_cores
from .diff import cmd_diff
from .explain import cmd_explain
from .plan import cmd_plan
from .simulate import cmd_simulate
from .tools import cmd_cache, cmd_gait, cmd_schema
from .verify import cmd_verify


def _sub(sub, name: str, help: str, examples: str):
    return sub.add_parser(name, help=help, description=help[0].upper() + help[1:] + ".",
                          epilog="examples:\n" + examples, formatter_class=argparse.RawDescriptionHelpFormatter)


def _verified_results_args(p, used: str) -> None:
    """--out and --rebuild of the commands that read what `verify` wrote."""
    p.add_argument("--out", default="reports", metavar="DIR",
                   help=f"where `verify` wrote its reports; {used} used while the specs match (default: reports)")
    p.add_argument("--rebuild", action="store_true", help="build the graph again instead of reading the report")


def _verify_args(sub) -> None:
    """`mpgspec verify PATH...`: what to verify, where reports go, how oracle calls run."""
    v = _sub(sub, "verify", "build the motion primitive graph, check assertions, write reports",
             "  mpgspec verify specs/                      every project below specs/\n"
             "  mpgspec verify specs/pendulum -j 1         everything in this process\n"
             "  mpgspec verify specs/ --format github      annotations and a step summary in GitHub Actions\n"
             "  mpgspec verify specs/cart --format json --no-write > result.json\n"
             "  mpgspec verify specs/ --format junit > mpgspec.xml   test results for Jenkins, GitLab\n"
             "  mpgspec verify specs/ --format sarif > mpgspec.sarif  findings for code scanning\n"
             "  mpgspec verify specs/ --baseline main-reports/  exit 1 when an edge main had is lost")
    v.add_argument("paths", nargs="+", metavar="PATH", help="a project.yaml, a project folder, or a folder of projects")
    v.add_argument("--out", default="reports", metavar="DIR",
                   help="report folder; each project gets DIR/<project>/ (default: reports)")
    v.add_argument("--no-write", action="store_true", help="write no report files")
    v.add_argument("--format", choices=("human", "json", "github", "junit", "sarif"), default="human",
                   help="human: text (default); json: the whole result on stdout; github: workflow annotations "
                        "at the spec lines, plus a table in $GITHUB_STEP_SUMMARY when it is set; junit: JUnit XML "
                        "on stdout (a test case per assertion, assumption check and cross-checked run); sarif: "
                        "SARIF 2.1.0 on stdout (a result per finding at its spec line)")
    v.add_argument("--method", metavar="NAME", help="oracle backend, e.g. rk4 or scipy (default: the project's)")
    v.add_argument("-j", "--jobs", type=int, default=None, metavar="N",
                   help="local worker processes for oracle calls and the robust stage's targets and uncertain "
                        f"runs (default: the number of usable cores, here {usable_cores()}; 1: in this process)")
    v.add_argument("--dask", metavar="local|ADDRESS",
                   help="run oracle calls on Dask: 'local' starts a LocalCluster of max(jobs, 2) workers, "
                        "or the address of a running scheduler (needs the 'dask' extra)")
    v.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler (same as --dask ADDRESS)")
    v.add_argument("--allow-path", action="append", metavar="DIR", default=[],
                   help="a folder outside the project that specs may name files in (repeatable)")
    v.add_argument("--no-cache", action="store_true",
                   help="run every oracle call, ignoring and not storing results in the cache")
    v.add_argument("--verify-cache", type=float, default=None, metavar="F",
                   help="also run a fraction F (0-1) of the stored oracle results again, and every stored call of "
                        "the edges assertions name, and fail (exit 1) when one disagrees with what was stored")
    v.add_argument("--strict", action="store_true",
                   help="exit 1 on a warning too (a WARN assumption check, a cross-check disagreement); INFO notes "
                        "(expected, such as a transient's missing stability test) never fail")
    v.add_argument("--baseline", metavar="DIR",
                   help="reports of an earlier verify (e.g. the main branch's, a CI artifact): exit 1 when an edge "
                        "DIR/<project>/report.json had is lost, unless the project's baseline.may_lose names it")
    v.add_argument("-q", "--quiet", action="store_true", help="no progress display")
    v.set_defaults(fn=cmd_verify)


def _plan_args(sub) -> None:
    """`mpgspec plan PROJECT --from A --to B`."""
    p = _sub(sub, "plan", "shortest safe transition sequence between two primitives",
             "  mpgspec plan specs/pendulum --from Hang --to Balance\n"
             "  mpgspec plan specs/pendulum --from SwingUp --to Hang --weight hops --format json")
    p.add_argument("project", metavar="PROJECT", help="a project.yaml or its folder")
    p.add_argument("--from", dest="source", required=True, metavar="A", help="the primitive to start from")
    p.add_argument("--to", dest="goal", required=True, metavar="B", help="the primitive to reach")
    p.add_argument("--weight", choices=("duration", "peak_input", "hops", "margin"), default="duration",
                   help="what the plan minimises: summed transition duration (default), peak input, hops, or "
                        "margin (the sum of 1 / each edge's least normalised safety margin: thin edges avoided)")
    p.add_argument("--format", choices=("human", "json"), default="human",
                   help="human: the path and each hop with its class and waiting window; json: the same as JSON")
    _verified_results_args(p, "its graph is")
    p.add_argument("--robust", action="store_true",
                   help="use only the edges that withstood the project's `uncertainty` (the robust graph)")
    p.set_defaults(fn=cmd_plan)


def _simulate_args(sub) -> None:
    """`mpgspec simulate PROJECT`: nominal, uncertain or cross-checked runs."""
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


def _tool_args(sub) -> None:
    """`mpgspec cache` and `mpgspec schema`."""
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


def _gait_args(sub) -> None:
    """`mpgspec gait GAITS`."""
    g = _sub(sub, "gait", "generate the gait tables of trot primitives: each node's orbit, command and multipliers",
             "  mpgspec gait specs/a1/gaits.yaml            write specs/a1/gaits/*.csv\n"
             "  mpgspec gait specs/a1/gaits.yaml --check    exit 1 when the tables on disk are stale")
    g.add_argument("file", metavar="GAITS", help="a gait file (project, primitive, dt)")
    g.add_argument("--check", action="store_true", help="regenerate in memory and compare with the tables on disk")
    g.add_argument("--allow-path", action="append", metavar="DIR", default=[],
                   help="a folder outside the gait file's folder that its project and the files the project "
                        "names may lie in (repeatable)")
    g.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    g.set_defaults(fn=cmd_gait)


def _diff_args(sub) -> None:
    """`mpgspec diff OLD NEW`."""
    d = _sub(sub, "diff", "what changed between two verified reports: edges, classes, windows, robust edges, "
                          "inconclusive cells, assertions; exit 1 on a regression",
             "  mpgspec diff baseline/pendulum reports/pendulum\n"
             "  mpgspec diff old/report.json new/report.json --format markdown >> $GITHUB_STEP_SUMMARY\n"
             "  mpgspec diff baseline/a1 reports/a1 --format github")
    d.add_argument("old", metavar="OLD", help="the earlier report: a report.json or the folder holding it")
    d.add_argument("new", metavar="NEW", help="the later report: a report.json or the folder holding it")
    d.add_argument("--format", choices=("human", "json", "markdown", "github"), default="human",
                   help="human: one line per change (default); json: one compact object; markdown: a table; "
                        "github: workflow annotations, and the table in $GITHUB_STEP_SUMMARY when it is set")
    d.set_defaults(fn=cmd_diff)


def _explain_args(sub) -> None:
    """`mpgspec explain [CODE]`."""
    e = _sub(sub, "explain", "what an error code (MPGnnn) means and how to fix it; without a code, all codes",
             "  mpgspec explain MPG204\n  mpgspec explain 104\n  mpgspec explain")
    e.add_argument("code", nargs="?", metavar="CODE", help="an error code such as MPG204 (or 204)")
    e.set_defaults(fn=cmd_explain)


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="mpgspec", description="Verify safe transitions between motion primitives.",
        epilog="exit codes: 0 every assertion holds, 1 an assertion failed, 2 a spec or usage error\n"
               "run `mpgspec COMMAND --help` for a command's options and examples",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"mpgspec {__version__}")
    sub = ap.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    for add in (_verify_args, _plan_args, _simulate_args, _diff_args, _tool_args, _gait_args, _explain_args):
        add(sub)
    return ap
