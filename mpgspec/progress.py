"""Progress of `mpgspec verify`: the phase of each project (load, compile and JIT, regions of
attraction, oracle, traces, sequence, assumptions, report) with elapsed time. A live display (rich)
on a terminal, plain lines otherwise (CI logs); a closing summary across projects.
"""
from __future__ import annotations

import sys
import time
from typing import Callable

Progress = Callable[[str, str, int, int], None]
"""progress(project, phase, done, total): called as each stage of a build starts (Display is one)."""

PHASES = ("load", "compile", "regions of attraction", "oracle", "traces", "sequence", "robust", "assumptions",
          "report")
PLAIN_EVERY_S = 2.0  # plain lines: at most one per phase this often, plus phase starts and ends


def of_project(progress: Progress | None, project: str) -> Callable[[str, int, int], None] | None:
    """progress bound to one project: what(phase, done, total) for the stages' executors and maps;
    None without progress."""
    return (lambda what, i, n: progress(project, what, i, n)) if progress else None


def phase_of(what: str) -> str:
    """The phase a progress message belongs to ('oracle Swing(1)' -> 'oracle')."""
    return next((p for p in PHASES if what.startswith(p)), what)


class Display:
    """A progress callback (project, what, i, n) that shows phases with elapsed time.

    live: rich's live display (default: when the stream is a terminal and rich is installed)."""

    def __init__(self, stream=None, live: bool | None = None, line=lambda s: s):
        self.stream = stream or sys.stderr
        self.line = line
        self.t0 = time.perf_counter()
        self.cur: dict[str, tuple[str, float]] = {}  # project -> (its phase, when the phase began)
        self.last_plain = 0.0
        self._live = None
        self._tasks: dict[str, object] = {}  # project -> its line of the live display
        if live is None:
            live = bool(getattr(self.stream, "isatty", lambda: False)())
        if live:
            try:
                from rich.console import Console
                from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

                self._live = Progress(TextColumn("[bold]{task.fields[project]}[/] {task.description}"), BarColumn(),
                                      MofNCompleteColumn(), TimeElapsedColumn(),
                                      console=Console(file=self.stream), transient=True)
                self._live.start()
            except ImportError:
                self._live = None

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def __call__(self, project: str, what: str, i: int, n: int) -> None:
        now = time.perf_counter()
        phase = phase_of(what)
        changed = self.cur.get(project, (None,))[0] != phase
        if changed:
            self._finish_phase(project, now)
            self.cur[project] = (phase, now)
        if self._live is not None:
            if project not in self._tasks:  # one line per project: projects may run side by side
                self._tasks[project] = self._live.add_task(what, total=None, project=project)
            self._live.update(self._tasks[project], description=what, completed=i, total=n or None)
            return
        if changed or (n and i >= n) or now - self.last_plain >= PLAIN_EVERY_S:
            self.last_plain = now
            count = f" ({i}/{n})" if n else ""
            print(self.line(f"[{project}] {what}{count} · {now - self.t0:.1f} s"), file=self.stream, flush=True)

    def _finish_phase(self, project: str, now: float) -> None:
        if project not in self.cur or self._live is None:
            return
        phase, t0 = self.cur[project]
        self._live.console.print(f"[dim]{project}[/] {phase} done in {now - t0:.1f} s")

    def close(self) -> None:
        """End the live display (the finished phases stay on the screen)."""
        now = time.perf_counter()
        for project in list(self.cur):
            self._finish_phase(project, now)
        self.cur = {}
        if self._live is not None:
            self._live.stop()
            self._live = None


def summary(projects, elapsed: float) -> str:
    """One line over every project: results, oracle calls, warnings and the wall time."""
    st = [p.status for p in projects]
    calls = sum(int(((p.report or {}).get("timing") or {}).get("oracle_calls", 0)) for p in projects)
    cached = sum(int(((p.report or {}).get("timing") or {}).get("cache_hits", 0)) for p in projects)
    warns = sum(int(getattr(p, "warnings", 0)) for p in projects)  # ProjectResult.warnings
    parts = [f"{st.count('pass')} passed", f"{st.count('fail')} failed"] + (
        [f"{st.count('error')} errors"] if "error" in st else [])
    n = len(projects)
    return (f"{n} project{'s' if n != 1 else ''}: {', '.join(parts)}; {calls} oracle calls"
            f"{f' ({cached} from the cache)' if cached else ''}"
            f"{f'; {warns} warning' + ('s' if warns != 1 else '') if warns else ''}; {elapsed:.1f} s in all")
