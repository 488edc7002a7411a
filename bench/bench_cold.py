"""Cold benchmark: `mpgspec verify` from an empty cache, as a new user's first command, and again with
nothing changed; per project and phase, with what gcc cost.

    python bench/bench_cold.py                        # specs/, the working tree only
    python bench/bench_cold.py --baseline main~3      # the same run of another commit first, then ratios
    options: PATH ... (projects or folders, default specs/), -j N (passed to verify), --keep DIR, --no-write

Each side runs `python -m mpgspec verify PATH ... -q` in a subprocess with a fresh MPGSPEC_CACHE,
so nothing compiled or stored before is reused, then once more with nothing changed. CC points at a
wrapper around gcc, and MPGSPEC_QUICK_CC at one around tcc when it is installed, that record per
compiled library the compiler, the C source's bytes and the compiler's CPU seconds (its children's
rusage): this works for any commit, instrumented or not (one that knows no quick compiler sends
everything to CC). Phase times come from
each project's report.json (`timing`). A baseline commit is checked out into a temporary worktree and
run with the same interpreter and packages (PYTHONPATH), cold then warm, before the working tree:
both sides meet the same machine within one invocation, and the ratios (baseline / now) are what to
read; the absolute times depend on the load.

Prints a table and replaces (or appends) the section "Cold verify" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import machine, revision, write_section  # noqa: E402

HEADING = "## Cold verify"
PHASES = ("compile_s", "roa_s", "graph_s", "traces_s", "plan_execute_s", "crosscheck_s", "robust_s",
          "assumptions_s", "checks_s")
"""Phases from report.json; the check stage's parts overlap (each from the stage's start), checks_s is
the whole stage (absent before the parts ran side by side)."""
CC_WRAPPER = """#!{python}
import json, os, resource, subprocess, sys
src = next((a for a in sys.argv[1:] if a.endswith(".c")), "")
before = resource.getrusage(resource.RUSAGE_CHILDREN)
rc = subprocess.call([{compiler!r}, *sys.argv[1:]])
after = resource.getrusage(resource.RUSAGE_CHILDREN)
cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
with open({log!r}, "a") as f:
    f.write(json.dumps({{"name": os.path.basename(src)[:-2], "c_bytes": os.path.getsize(src) if src else 0,
                        "gcc_s": cpu, "cc": os.path.basename({compiler!r})}}) + "\\n")
sys.exit(rc)
"""


def run_side(tree: Path, paths: list[str], jobs: int | None, work: Path) -> dict:
    """Cold then warm `mpgspec verify` of `paths` with the code of `tree`: wall times, gcc log, phases."""
    cache, out, log = work / "cache", work / "reports", work / "gcc.jsonl"
    env = {**os.environ, "MPGSPEC_CACHE": str(cache), "PYTHONPATH": str(tree)}
    quick = shutil.which(os.environ.get("MPGSPEC_QUICK_CC", "tcc") or "-")
    for var, compiler in (("CC", "gcc"), ("MPGSPEC_QUICK_CC", quick)):
        if compiler:
            cc = work / f"cc_{Path(compiler).name}"
            cc.write_text(CC_WRAPPER.format(python=sys.executable, log=str(log), compiler=compiler))
            cc.chmod(0o755)
            env[var] = str(cc)
    cmd = [sys.executable, "-m", "mpgspec", "verify", *paths, "--out", str(out), "-q"]
    if jobs:
        cmd += ["-j", str(jobs)]
    side = {}
    for which in ("cold", "warm"):
        t = time.perf_counter()
        proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
        side[f"{which}_s"] = time.perf_counter() - t
        side[f"{which}_exit"] = proc.returncode
        (work / f"{which}.log").write_text(proc.stdout + proc.stderr)  # kept with --keep
        if proc.returncode != 0:  # 1: a failed check (the lines naming it), else a crash
            lines = (proc.stdout + proc.stderr).splitlines()
            print("\n".join([ln for ln in lines if "FAIL" in ln or "error" in ln.lower()][:20] or lines[-20:]),
                  file=sys.stderr)
        if which == "cold":
            side["phases"] = _phases(out)
            side["gcc"] = _gcc(log)
    return side


def _phases(out: Path) -> dict:
    """{project: {phase: seconds}} from each report.json written."""
    res = {}
    for rj in sorted(out.glob("*/report.json")):
        timing = json.loads(rj.read_text()).get("timing", {})
        res[rj.parent.name] = {k: float(timing[k]) for k in PHASES if k in timing}
    return res


def _gcc(log: Path) -> dict:
    """Libraries compiled, C bytes and compiler CPU seconds, in total, by compiler and by kind (name up
    to its first '_'); the quick compiler's probe is not a library."""
    rows = [json.loads(ln) for ln in log.read_text().splitlines()] if log.exists() else []
    rows = [r for r in rows if r["name"] != "probe"]
    by_cc = defaultdict(float)
    for r in rows:
        by_cc[r.get("cc", "gcc")] += r["gcc_s"]
    kinds = defaultdict(lambda: [0, 0, 0.0])
    for r in rows:
        k = kinds[r["name"].split("_")[0]]
        k[0], k[1], k[2] = k[0] + 1, k[1] + r["c_bytes"], k[2] + r["gcc_s"]
    return {"libraries": len(rows), "c_bytes": sum(r["c_bytes"] for r in rows),
            "gcc_s": sum(r["gcc_s"] for r in rows), "by_cc": dict(by_cc),
            "kinds": {k: tuple(v) for k, v in sorted(kinds.items())}}


def baseline_tree(ref: str, tmp: Path) -> Path:
    """A detached worktree of `ref` (removed by the caller)."""
    tree = tmp / "baseline"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), ref], check=True,
                   capture_output=True)
    return tree


def table(sides: dict[str, dict]) -> list[tuple]:
    """Rows (measure, value per side..., ratio baseline/now when there is a baseline)."""
    names = list(sides)
    rows = [("cold `mpgspec verify` wall", *(f"{sides[n]['cold_s']:.0f} s" for n in names)),
            ("nothing changed, wall", *(f"{sides[n]['warm_s']:.1f} s" for n in names)),
            ("exit codes (cold, warm)", *(f"{sides[n]['cold_exit']}, {sides[n]['warm_exit']}" for n in names)),
            ("libraries compiled", *(str(sides[n]["gcc"]["libraries"]) for n in names)),
            ("C bytes compiled", *(f"{sides[n]['gcc']['c_bytes'] / 1e6:.1f} MB" for n in names)),
            ("compiler CPU seconds", *(f"{sides[n]['gcc']['gcc_s']:.0f} s" for n in names)),
            ("of them tcc", *(f"{sides[n]['gcc']['by_cc'].get('tcc', 0.0):.1f} s" for n in names))]
    projects = sorted({p for n in names for p in sides[n]["phases"]})
    for p in projects:
        for ph in PHASES:
            vals = [sides[n]["phases"].get(p, {}).get(ph) for n in names]
            if any(v is not None and v >= 0.05 for v in vals):
                rows.append((f"{p}: {ph[:-2]}", *("-" if v is None else f"{v:.1f} s" for v in vals)))
    if len(names) == 2:
        b, a = (sides[n] for n in names)
        ratios = {"cold `mpgspec verify` wall": b["cold_s"] / a["cold_s"],
                  "nothing changed, wall": b["warm_s"] / a["warm_s"],
                  "compiler CPU seconds": b["gcc"]["gcc_s"] / max(a["gcc"]["gcc_s"], 1e-9)}
        rows = [(*r, f"{ratios[r[0]]:.2f}x" if r[0] in ratios else "") for r in rows]
    return rows


def markdown(rows: list[tuple], names: list[str]) -> str:
    head = ["measure", *names] + (["baseline / now"] if len(names) == 2 else [])
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", default=["specs/"])
    ap.add_argument("--baseline", metavar="REF", help="a commit to run first, for ratios")
    ap.add_argument("-j", "--jobs", type=int, help="passed to mpgspec verify")
    ap.add_argument("--keep", metavar="DIR", help="copy each side's reports and its runs' output (cold.log, warm.log) "
                                                  "to DIR/<side>/ (to compare verdicts)")
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    sides: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        try:
            if args.baseline:
                tree = baseline_tree(args.baseline, tmp)
                (tmp / "b").mkdir()
                sides[f"baseline {args.baseline}"] = run_side(tree, args.paths, args.jobs, tmp / "b")
            (tmp / "a").mkdir()
            sides["now"] = run_side(ROOT, args.paths, args.jobs, tmp / "a")
            if args.keep:
                for side, sub in (("baseline", "b"), ("now", "a")):
                    if (tmp / sub / "reports").exists():
                        shutil.copytree(tmp / sub / "reports", Path(args.keep) / side, dirs_exist_ok=True)
                    for log in (tmp / sub).glob("*.log"):  # the cold and warm runs' output
                        shutil.copy(log, Path(args.keep) / side / log.name)
        finally:
            if args.baseline:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tmp / "baseline")],
                               capture_output=True)
    rows = table(sides)
    text = markdown(rows, list(sides))
    print(text)
    kinds = sides["now"]["gcc"]["kinds"]
    by_kind = ", ".join(f"{k} {n} ({b / 1e6:.1f} MB, {s:.0f} s)" for k, (n, b, s) in kinds.items())
    print(f"\ncompiler by kind (now): {by_kind}")
    if not args.no_write:
        mach = machine(casadi=_casadi_version(), revision=revision(ROOT))
        load = Path("/proc/loadavg").read_text().split()[:3] if Path("/proc/loadavg").exists() else ["?"]
        stamp = (f"{time.strftime('%Y-%m-%d %H:%M')}, {mach['revision']}; {mach['nproc']} CPU ({mach['cpu']}), "
                 f"Python {mach['python']}, CasADi {mach['casadi']}; load average {' '.join(load)} at the end; "
                 f"`python bench/bench_cold.py {' '.join(argv if argv is not None else sys.argv[1:])}` "
                 f"({time.perf_counter() - t0:.0f} s wall).")
        section = (f"{HEADING}\n\n{stamp} Each side: a fresh MPGSPEC_CACHE, `mpgspec verify "
                   f"{' '.join(args.paths)} -q` cold, then again with nothing changed; compiler CPU seconds from "
                   f"wrappers around gcc and tcc; phases from report.json.\n\n{text}\n\ncompiler by kind (now): "
                   f"{by_kind}\n")
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, section)
    return 0


def _casadi_version() -> str:
    try:
        import casadi
        return casadi.__version__
    except ImportError:
        return "?"


if __name__ == "__main__":
    sys.exit(main())
