"""Where oracle calls run: in this process, in a local process pool, or on a Dask cluster.

Algorithm 1's start points are split into tasks of (target, batch of start points), sized so
that every worker gets several even for a project with two primitives. Closed loops travel to
workers once (pickled through CasADi's serialisation; each worker rebuilds its compiled chunks
from the on-disk cache) and results come back in task order. Every rollout is computed in its own
batch slot, independently of its neighbours, so the graph does not depend on the executor or the
number of workers.

Any other per-item work of a build (the robust stage's targets, the uncertain sequence's modes)
goes through `map(fn, items)`: a picklable module-level function, results in item order, a call
that raises (or whose worker dies) is that item's Failed result, never the end of the run.
"""
from __future__ import annotations

import sys
import weakref
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager

from ..compile.primitive import CompiledPrimitive
from ..cores import usable_cores
from ..errors import UsageError
from ..settings import OracleSettings
from .cache import CachedExecutor
from .evidence import OracleEvidence, Reason
from .looplib import build_all
from .oracle import SafetyOracle
from .registry import get_backend
from .tasks import Executor, Failed, Task, call

TASKS_PER_WORKER = 4
MIN_BATCH = 16


def split(points: dict[str, tuple], workers: int) -> list[Task]:
    """Tasks of (target, contiguous batch): about TASKS_PER_WORKER per worker, no batch under MIN_BATCH.
    points: target -> (x0s, t0s) or (x0s, t0s, recheck flags)."""
    total = sum(len(p[1]) for p in points.values())
    size = max(MIN_BATCH, -(-total // max(1, workers * TASKS_PER_WORKER))) if workers > 1 else max(total, 1)
    tasks = []
    for target, (x0s, t0s, *flags) in points.items():
        for a in range(0, len(t0s), size):
            tasks.append(Task(target, x0s[a:a + size], t0s[a:a + size], flags[0][a:a + size] if flags else None))
    return tasks


def evaluate(oracles: dict, prims: dict[str, CompiledPrimitive], settings: OracleSettings,
             task: Task) -> list[OracleEvidence]:
    """One task's evidence; a compile or backend failure is the evidence of each of its calls.

    `oracles` outlives a project (one executor serves every project of a run), so an oracle is kept
    by the content of its closed loop and the settings, never by the primitive's name alone: two
    robots' `Stand` are different oracles."""
    try:
        prim = prims[task.target]
        key = (prim.digest(), settings)
        if key not in oracles:
            oracles[key] = SafetyOracle(prim, settings)
        return oracles[key].evaluate(task.x0s, task.t0s)
    except Exception as err:
        return [OracleEvidence(0, Reason.ERROR, 0.0, status="inconclusive", message=str(err)[:500])
                for _ in range(len(task))]


def prebuild(prims, settings: OracleSettings, tasks) -> None:
    """Before the tasks run: the loop libraries and what the oracle backend compiles first (when it
    offers `prebuild`) of every target, compiled side by side in this process (its workers fork
    from it, or find them in the compile cache). A failure here is left to the tasks, which build
    again and report their own errors."""
    if not (settings.jit and tasks):
        return
    targets = [prims[name] for name in dict.fromkeys(t.target for t in tasks)]
    try:
        build_all(targets)
        fn = getattr(get_backend(settings.method), "prebuild", None)
        if fn is not None:
            fn(targets, settings)
    except Exception:  # noqa: BLE001 - see the docstring
        pass


class InProcess:
    """All tasks in this process, one after the other; compiled oracles are kept for later calls."""

    workers = 1

    def __init__(self):
        self.oracles: dict = {}

    def run(self, prims, settings, tasks, progress=None):
        prebuild(prims, settings, tasks)
        out = []
        for k, task in enumerate(tasks):
            if progress:
                progress(f"oracle {task.target}", k, len(tasks))
            out.append(evaluate(self.oracles, prims, settings, task))
        return out

    def map(self, fn, items, progress=None, label="tasks", shared=None):
        """fn over items, one after the other, in this process."""
        items = list(items)
        out = []
        for k, item in enumerate(items):
            if progress:
                progress(label, k, len(items))
            out.append(call(fn, item, shared))
        return out


_worker: dict = {}


def _worker_signals() -> None:
    """In a pool worker: Ctrl-C (SIGINT to the whole process group) is the parent's to handle, and
    SIGTERM ends the worker at once (not the parent's handler, inherited through fork). On Linux
    the worker also gets SIGTERM when the parent dies, even by SIGKILL."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):  # prctl(PR_SET_PDEATHSIG, SIGTERM)
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):
            pass


def _init(prims: dict, settings: OracleSettings) -> None:
    _worker_signals()
    _worker.update(prims=prims, settings=settings, oracles={})


def _run(task: Task) -> list[OracleEvidence]:
    return evaluate(_worker["oracles"], _worker["prims"], _worker["settings"], task)


def _init_shared(shared) -> None:
    _worker_signals()
    _worker["shared"] = shared


def _call_shared(fn, item):
    return call(fn, item, _worker["shared"])


class ProcessPool:
    """A local pool of `workers` processes; each receives the closed loops once, at start-up."""

    def __init__(self, workers: int):
        self.workers = max(1, int(workers))

    def run(self, prims, settings, tasks, progress=None):
        prebuild(prims, settings, tasks)
        pool = ProcessPoolExecutor(max_workers=self.workers, initializer=_init, initargs=(prims, settings))
        return _collect(pool, [(_run, t) for t in tasks], progress, f"oracle on {self.workers} processes")

    def map(self, fn, items, progress=None, label="tasks", shared=None):
        """fn over items in up to `workers` fresh processes: each item is pickled to its worker,
        `shared` goes to each worker once, at start-up (inherited, not pickled, where they fork)."""
        items = list(items)
        if not items:
            return []
        pool = ProcessPoolExecutor(max_workers=min(self.workers, len(items)), initializer=_init_shared,
                                   initargs=(shared,))
        return _collect(pool, [(_call_shared, fn, item) for item in items], progress,
                        f"{label} on {min(self.workers, len(items))} processes",
                        Failed.of)


def _collect(pool: ProcessPoolExecutor, jobs: list[tuple], progress, what: str, on_error=None) -> list:
    """The results of jobs (function, *args) submitted to the pool, in job order; on_error(err) is
    the result of a job whose future raised (a dead worker, a result that does not pickle), else the
    error propagates. The pool is shut down after; on an error, SIGINT or SIGTERM (raised by the
    CLI's handler) its workers are stopped, so none outlives us."""
    out: list = [None] * len(jobs)
    finished = False
    try:
        futures = {pool.submit(*job): k for k, job in enumerate(jobs)}
        for done, f in enumerate(as_completed(futures), start=1):
            if on_error is None:
                out[futures[f]] = f.result()
            else:
                try:
                    out[futures[f]] = f.result()
                except Exception as err:
                    out[futures[f]] = on_error(err)
            if progress:
                progress(what, done, len(jobs))
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            _stop_pool(pool)
    return out


def _stop_pool(pool: ProcessPoolExecutor, grace: float = 2.0) -> None:
    """Cancel what has not started, then terminate the workers (kill those that linger)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    stop_processes(procs, grace)


def stop_processes(procs: list, grace: float = 2.0) -> None:
    """SIGTERM to each process, then kill each one still alive after `grace` seconds."""
    for p in procs:
        try:
            p.terminate()
        except (OSError, ValueError, AttributeError):
            pass
    for p in procs:
        try:
            p.join(grace)
            if p.is_alive():
                p.kill()
                p.join(grace)
        except (OSError, ValueError, AssertionError, AttributeError):
            pass


_dask_oracles: dict = {}


def _dask_run(task: Task, prims: dict, settings: OracleSettings) -> list[OracleEvidence]:
    key = (id(prims), settings)  # the scattered closed loops live once per worker
    return evaluate(_dask_oracles.setdefault(key, {}), prims, settings, task)


class DaskExecutor:
    """Tasks on a Dask cluster: `address` of a running scheduler, or a LocalCluster of `workers`
    processes, started on first use and kept for every later map (a verify runs a map per stage:
    starting a cluster for each cost seconds apiece) until close(), garbage collection or exit."""

    def __init__(self, address: str | None = None, workers: int = 2):
        self.address = address
        self.workers = max(1, int(workers))
        self._local = None  # (client, finalizer) of the LocalCluster started here

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_local": None}  # a copy elsewhere starts its own cluster

    @contextmanager
    def _client(self):
        """A client of the scheduler at `address` (opened and closed here), or of this executor's
        LocalCluster (started on first use)."""
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as err:  # pragma: no cover - depends on the installation
            raise UsageError("Dask is not installed; install mpgspec with the 'dask' extra: "
                             "pip install 'mpgspec[dask]'") from err
        if self.address is None:
            if self._local is None:
                cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=40)  # any free port: clusters side by side
                client = Client(cluster)
                self._local = (client, weakref.finalize(self, _close_local, client, cluster))
            yield self._local[0]
            return
        client = Client(self.address)
        try:
            self.workers = max(1, len(client.scheduler_info().get("workers", {})))
            yield client
        finally:
            client.close()

    def close(self) -> None:
        """Stop the LocalCluster this executor started, if any."""
        if self._local is not None:
            self._local[1]()
            self._local = None

    def run(self, prims, settings, tasks, progress=None):
        with self._client() as client:
            remote = client.scatter(prims, broadcast=True)
            futures = client.map(_dask_run, tasks, prims=remote, settings=settings, pure=False)
            return _gather(futures, progress, f"oracle on Dask ({self.workers} workers)")

    def map(self, fn, items, progress=None, label="tasks", shared=None):
        """fn over items on the cluster's workers; `shared` is scattered to every worker once."""
        items = list(items)
        if not items:
            return []
        with self._client() as client:
            remote = client.scatter([shared], broadcast=True)[0] if shared is not None else None  # as one datum
            futures = client.map(call, [fn] * len(items), items, shared=remote, pure=False)
            return _gather(futures, progress, f"{label} on Dask ({self.workers} workers)",
                           Failed.of)


def _close_local(client, cluster) -> None:
    client.close()
    cluster.close()


def _gather(futures: list, progress, what: str, on_error=None) -> list:
    """The results of Dask futures in their order; on_error(err) is the result of one that raised
    (a lost worker), else the error propagates."""
    from dask.distributed import as_completed as dask_completed

    index = {f.key: k for k, f in enumerate(futures)}
    out: list = [None] * len(futures)
    for done, f in enumerate(dask_completed(futures), start=1):
        if on_error is not None and f.status == "error":
            out[index[f.key]] = on_error(f.exception())
        else:
            out[index[f.key]] = f.result()
        if progress:
            progress(what, done, len(futures))
    return out


def make_executor(jobs: int = 1, dask: str | None = None, cache: bool = False) -> Executor:
    """In-process for one job, a process pool for more; Dask when asked ('local' or a scheduler
    address); with `cache`, wrapped so that stored results are reused (mpgspec.oracle.cache)."""
    if dask:
        ex: Executor = DaskExecutor(None if dask == "local" else dask, workers=max(jobs, 2) if dask == "local" else jobs)
    else:
        jobs = min(int(jobs), usable_cores()) if jobs > 1 else 1
        ex = ProcessPool(jobs) if jobs > 1 else InProcess()
    if cache:
        ex = CachedExecutor(ex)
    return ex
