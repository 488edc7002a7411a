"""Helpers shared by the benchmarks: interleaved timing rounds, median ratios, machine facts, the paper's
joint-PD Lie as a continuous-law baseline."""
from __future__ import annotations

import importlib.util
import os
import platform
import statistics
import time
from pathlib import Path


def rounds(fns: dict, repeats: int) -> dict[str, list[float]]:
    """Wall times of every fn, interleaved: `repeats` rounds that each run all of them once, so
    that load from other processes hits all measurements alike and per-round ratios stay fair."""
    out = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t = time.perf_counter()
            fn()
            out[k].append(time.perf_counter() - t)
    return out


def med_ratio(a: list[float], b: list[float]) -> float:
    """Median over rounds of a/b."""
    return statistics.median(x / y for x, y in zip(a, b))


def machine(**versions: str) -> dict:
    """CPU count and model, Python and the given package versions."""
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        avail = len(os.sched_getaffinity(0))
    except AttributeError:
        avail = os.cpu_count()
    return {"nproc": avail, "cpu": cpu or platform.processor() or platform.machine(),
            "python": platform.python_version(), **versions, "platform": platform.platform()}


def markdown_table(rows: list[tuple[str, str]]) -> str:
    """The | measure | value | table of a benchmark's section."""
    w = max(len(a) for a, _ in rows)
    return "\n".join([f"| {'measure':{w}s} | value |", f"|{'-' * (w + 2)}|-------|"]
                     + [f"| {a:{w}s} | {b} |" for a, b in rows])


def stamp(mach: dict, script: str, quick: bool, repeats: int, seconds: float) -> str:
    """When, what and where a section was measured: date, revision, CPUs, Python and CasADi, the
    load average, the command and its rounds and wall time."""
    import datetime

    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3]) if Path("/proc/loadavg").exists() else "?"
    return (f"{when}, {mach['revision']}; {mach['nproc']} CPU ({mach['cpu']}), Python {mach['python']}, CasADi "
            f"{mach['casadi']}; load average {load}; `python bench/{script}{' --quick' if quick else ''}` "
            f"(medians of {repeats} interleaved rounds; {seconds:.0f} s wall).")


def revision(root: Path, paths: tuple[str, ...] = ("mpgspec", "verifiers", "specs")) -> str:
    """The commit measured, and which of `paths` have uncommitted changes (the benchmark measures
    the working tree)."""
    import subprocess

    def git(*a: str) -> str:
        return subprocess.run(["git", "-C", str(root), *a], capture_output=True, text=True, check=True).stdout

    try:
        head = git("rev-parse", "--short", "HEAD").strip()
        changed = [ln[3:] for ln in git("status", "--porcelain", "--", *paths).splitlines() if ln.strip()]
    except (OSError, subprocess.CalledProcessError):
        return "unknown revision"
    if not changed:
        return f"commit {head}"
    return f"commit {head} + uncommitted changes in {', '.join(sorted(changed))}"


def run_build(build, spec, settings, oracle_cls):
    """mpgspec.api.build across its two shapes, with an explicit in-process executor when it takes one
    (so that no result cache answers for the oracle): (prims, graph, timing, oracle_of), where
    oracle_of(name) is the oracle the build used (or a new one on the build's primitive, whose
    compiled chunks are remembered on it, so no JIT happens again)."""
    import inspect

    kw = {}
    if "executor" in inspect.signature(build).parameters:  # in-process and uncached: every call is simulated
        try:
            from mpgspec.oracle.executors import InProcess
            kw["executor"] = InProcess()
        except ImportError:
            pass
    res = build(spec, settings, **kw)
    if isinstance(res, tuple) and len(res) == 2 and hasattr(res[1], "graph"):  # (CompiledProject, VerifiedGraph)
        cp, vg = res
        prims, g, timing, oracles = cp.prims, vg.graph, dict(vg.timing), {}
        timing.setdefault("compile_s", cp.timing.get("compile_s", 0.0))
    else:  # (prims, graph, oracles, timing, roa)
        prims, g, oracles, timing = res[:4]

    def oracle_of(name):
        if name not in oracles:
            oracles[name] = oracle_cls(prims[name], settings)
        return oracles[name]

    return prims, g, timing, oracle_of


def a1_target_jobs(targets) -> tuple:
    """(specs/a1's compiled project, its robust target jobs by target name among `targets`): the nominal graph
    built first, its oracle calls from the result cache when they are there."""
    from mpgspec import api
    from mpgspec.pipeline.stages import build
    from mpgspec.robust.graph import target_jobs
    from mpgspec.spec.loader import load_project

    spec = load_project(Path(__file__).resolve().parent.parent / "specs" / "a1" / "project.yaml")
    cp, vg = build(spec, api.settings_for(spec), executor=api.executor(1, None, cache=True))
    _, jobs = target_jobs(spec, cp.prims, cp.settings, vg.graph)
    return cp, {j.target: j for j in jobs if j.target in targets}


def write_section(results: Path, heading: str, section: str) -> None:
    """Replace the `heading` section of the results file with `section` (append it if missing)."""
    text = results.read_text() if results.exists() else "# Oracle benchmark results\n"
    i = text.find(heading)
    if i >= 0:  # replace this benchmark's previous section only
        j = text.find("\n## ", i + len(heading))
        text = text[:i] + section + ("\n" + text[j + 1:] if j >= 0 else "")
    else:
        text = text.rstrip("\n") + "\n\n" + section
    results.write_text(text)


def publish(heading: str, mach: dict, script: str, repeats: int, seconds: float, table: str, write: bool) -> None:
    """Print a benchmark's section (its stamp and table) and, with `write`, put it in bench/RESULTS.md."""
    head = stamp(mach, script, False, repeats, seconds)
    print(head + "\n\n" + table)
    if write:
        write_section(Path(__file__).parent / "RESULTS.md", heading, heading + "\n\n" + head + "\n\n" + table + "\n")


def publish_rows(heading: str, script: str, repeats: int, t_start: float, rows: list[tuple[str, str]],
                 write: bool) -> None:
    """publish() of a two-column table (markdown_table(rows)) stamped with this machine, CasADi's
    version and the revision measured; the run's wall time counted from t_start (time.perf_counter)."""
    import casadi as ca

    mach = machine(casadi=ca.__version__, revision=revision(Path(__file__).resolve().parent.parent))
    publish(heading, mach, script, repeats, time.perf_counter() - t_start, markdown_table(rows), write)


def pd_lie(folder: Path) -> Path:
    """In a copy of specs/a1 at `folder`, Lie runs the paper's joint PD (r = 0.023) instead of the ID-QP:
    the benchmarks' continuous law on four grounded feet, as the tests use it (tests/a1_lie.py)."""
    return _a1_lie().pd_lie(folder)


def with_controller(text: str, block: str) -> str:
    """A primitive file's text with its controller block replaced by `block` (tests/a1_lie.py)."""
    return _a1_lie().with_controller(text, block)


def _a1_lie():
    """tests/a1_lie.py, loaded by its path so that tests/ does not go onto sys.path."""
    path = Path(__file__).resolve().parents[1] / "tests" / "a1_lie.py"
    spec = importlib.util.spec_from_file_location("mpgspec_tests_a1_lie", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
