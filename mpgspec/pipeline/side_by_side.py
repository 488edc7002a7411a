"""Several projects verified side by side: one process per project, up to `workers` at once.

A project's stages leave a core idle much of the time (gcc of one large library, the report, Python
between compiled calls), so a run over several projects takes about the time of the longest one
when a second core is free, instead of their sum. Each project runs in its own forked process with
its own executor (`jobs` workers, as a run of that project alone would have), builds its report and
writes its files there, and sends back its result without the compiled project (CasADi objects stay
in the process that made them). The largest project folders start first (the long projects, so
the run ends with the longest instead of after it); results keep the order of the files; progress
events come back through a queue and reach the caller's progress callback in this process. A
project whose process dies is that project's error and no other's; SIGINT or SIGTERM stops every
project process (each unwinds: its executor's workers stopped, its temporary report folders removed).

The reports are those of a run one project after the other: each project is computed alone, from
the same inputs, in the same way (report.json identical apart from timing).
"""
from __future__ import annotations

import importlib
import multiprocessing
import signal
import threading
from multiprocessing.connection import wait
from pathlib import Path

from ..oracle.executors import _worker_signals, make_executor, stop_processes
from ..oracle.unwind import unwinding
from ..progress import Progress
from .results import ProjectResult, VerifyResult, write_reports

GRACE_S = 5.0
"""How long a stopped project process may take to unwind before it is killed."""

_queue: list = []
"""In a project process: the queue its progress events go to."""


def verify_side_by_side(files: list[Path], out_dir: Path | None, overrides: dict | None, progress: Progress | None,
                        jobs: int, cache: bool, workers: int, allow_paths=None) -> VerifyResult:
    """Verify `files` in up to `workers` processes at once, each project's reports written to
    out_dir/<project>/ by its own process (nothing written when out_dir is None)."""
    importlib.import_module(f"{__package__}.project")  # imported once here, inherited by every project process

    ctx = multiprocessing.get_context("fork")
    queue = ctx.SimpleQueue()
    relay = threading.Thread(target=_relay, args=(queue, progress), name="progress relay", daemon=True)
    relay.start()
    results: list = [None] * len(files)
    running: dict = {}  # connection -> (index, process)
    pending = sorted(enumerate(Path(f) for f in files), key=lambda kp: -_weight(kp[1]))
    try:
        while pending or running:
            while pending and len(running) < max(1, workers):
                k, path = pending.pop(0)
                here, there = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_child, args=(there, queue, path, out_dir, overrides, jobs, cache,
                                                        allow_paths), name=f"mpgspec {path.parent.name}")
                proc.start()
                there.close()
                running[here] = (k, proc)
            for conn in wait(list(running)):
                k, proc = running.pop(conn)
                results[k] = _receive(conn, files[k])
                proc.join()
    finally:
        stop_processes([proc for _, proc in running.values()], GRACE_S)  # each unwinds, or is killed
        queue.put(None)
        relay.join(GRACE_S)
    return VerifyResult(results)


def _weight(path: Path) -> float:
    """How long the project is expected to take, to start the longest first: the bytes of its
    folder (gait tables, robot models, primitives: the large projects are the slow ones)."""
    try:
        return float(sum(f.stat().st_size for f in path.parent.rglob("*") if f.is_file()))
    except OSError:
        return 0.0


def _receive(conn, path: Path) -> ProjectResult:
    """The project's result from its process, or its error when the process died first."""
    try:
        res = conn.recv()
    except (EOFError, OSError) as err:
        res = err
    conn.close()
    return res if isinstance(res, ProjectResult) else _died(path, res)


def _relay(queue, progress: Progress | None) -> None:
    """Hand the project processes' progress events to `progress`, until None arrives."""
    while (event := queue.get()) is not None:
        if progress is not None:
            try:
                progress(*event)
            except Exception:  # noqa: BLE001 - a broken display never ends the run
                pass


def _child(conn, queue, path: Path, *args) -> None:
    """A project process: Ctrl-C is the parent's to handle; SIGTERM unwinds the project; the
    parent's death sends SIGTERM."""
    _worker_signals()
    signal.signal(signal.SIGTERM, unwinding(SystemExit))
    _queue[:] = [queue]
    try:
        res = _verify_one(path, *args)
    except BaseException as err:  # noqa: BLE001 - reported as this project's error
        res = err
    try:
        conn.send(res)
    except Exception as err:  # noqa: BLE001 - e.g. a result that does not pickle
        conn.send(RuntimeError(f"its result could not be sent back: {type(err).__name__}: {err}"))
    conn.close()


def _progress(project: str, what: str, i: int, n: int) -> None:
    _queue[0].put((project, what, i, n))


def _verify_one(path: Path, out_dir: Path | None, overrides: dict | None, jobs: int, cache: bool,
                allow_paths) -> ProjectResult:
    """One project in this process: built, checked, its reports written; its result without the
    compiled project."""
    from .project import run_project

    executor = make_executor(jobs, None, cache=cache)
    res = run_project(path, None, overrides, _progress, executor=executor, allow_paths=allow_paths)
    if out_dir is not None:
        write_reports(VerifyResult([res]), out_dir, _progress)
    res.compiled = None
    return res


def _died(path: Path, err) -> ProjectResult:
    """The result of a project whose process died or whose result could not come back."""
    why = f"internal error: the project's process ended: {type(err).__name__}: {err}"
    return ProjectResult(Path(path), status="error",
                         errors=[{"code": "MPG900", "message": why, "text": f"{path}: MPG900 {why}"}])
