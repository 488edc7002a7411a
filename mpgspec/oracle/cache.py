"""Content-addressed store of oracle results, so unchanged work is never simulated twice.

A cell's key hashes what decides its verdict: the target's closed loop (CompiledPrimitive.digest:
its serialised CasADi Functions and numbers), the start state and clock, the oracle settings,
the backend and mpgspec's version. Editing one primitive changes its digest and its setpoint
samples, so only the edges into and out of it run again. Results are kept as JSON rows in one
SQLite file next to the compiled chunks (MPGSPEC_CACHE, else ~/.cache/mpgspec).
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
from pathlib import Path

import numpy as np

from functools import lru_cache

from .. import __version__
from .evidence import OracleEvidence, Reason
from .tasks import Executor, Task


@lru_cache(maxsize=1)
def code_version() -> str:
    """The package version and a hash of the source of mpgspec and its verifiers: cached results
    are keyed by it, so a changed oracle, judge or verifier never serves results computed by the old one."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256(__version__.encode())
    for d in ("mpgspec", "verifiers"):
        for f in sorted((root / d).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return f"{__version__}+{h.hexdigest()[:16]}"


def cache_root() -> Path:
    return Path(os.environ.get("MPGSPEC_CACHE", Path.home() / ".cache" / "mpgspec"))


class ResultStore:
    """Oracle evidence by key, in SQLite (one writer: the process that runs the build)."""

    def __init__(self, path: Path | None = None):
        self.path = Path(path) if path else cache_root() / "results.sqlite"
        self._db: sqlite3.Connection | None = None

    @property
    def db(self) -> sqlite3.Connection:
        if self._db is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path)
            self._db.execute("CREATE TABLE IF NOT EXISTS results (key TEXT PRIMARY KEY, evidence TEXT)")
            self._db.execute("CREATE TABLE IF NOT EXISTS memo (key TEXT PRIMARY KEY, value TEXT)")
        return self._db

    def get(self, keys: list[str]) -> dict[str, OracleEvidence]:
        out = {}
        for a in range(0, len(keys), 500):
            part = keys[a:a + 500]
            rows = self.db.execute(f"SELECT key, evidence FROM results WHERE key IN ({','.join('?' * len(part))})", part)
            out.update((k, _load(v)) for k, v in rows)
        return out

    def put(self, items: dict[str, OracleEvidence]) -> None:
        with self.db:
            self.db.executemany("INSERT OR REPLACE INTO results VALUES (?, ?)",
                                [(k, json.dumps(e.to_dict())) for k, e in items.items()])

    def count(self) -> int:
        return self.db.execute("SELECT COUNT(*) FROM results").fetchone()[0] if self.path.exists() else 0

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None


def _plain(o):
    """numpy scalars and arrays as JSON numbers and lists."""
    if hasattr(o, "tolist"):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _load(text: str) -> OracleEvidence:
    d = json.loads(text)
    d["reason"] = Reason(d["reason"])
    return OracleEvidence(**d)


class Memo:
    """JSON values of other deterministic per-primitive work (sized regions of attraction,
    assumption checks), keyed by the content hash of what they depend on."""

    def __init__(self, store: ResultStore):
        self.store = store

    def key(self, *parts) -> str:
        return hashlib.sha256("|".join(map(str, (*parts, code_version()))).encode()).hexdigest()

    def get(self, key: str):
        row = self.store.db.execute("SELECT value FROM memo WHERE key = ?", (key,)).fetchone()
        return json.loads(row[0]) if row else None

    def has(self, key: str) -> bool:
        """Whether a value is stored under key (without reading it)."""
        return self.store.db.execute("SELECT 1 FROM memo WHERE key = ?", (key,)).fetchone() is not None

    def put(self, key: str, value) -> None:
        with self.store.db:
            self.store.db.execute("INSERT OR REPLACE INTO memo VALUES (?, ?)", (key, json.dumps(value, default=_plain)))


class CachedExecutor:
    """Runs only the start points whose results are not stored yet, through the inner executor."""

    def __init__(self, inner: Executor, store: ResultStore | None = None):
        self.inner = inner
        self.store = store or ResultStore()
        self.stats = {"cache_hits": 0, "cache_misses": 0}
        self.memo = Memo(self.store)

    @property
    def workers(self) -> int:
        return self.inner.workers

    def map(self, fn, items, progress=None, label="tasks", shared=None) -> list:
        """The inner executor's map (its results are not stored here: the stages memoise their own)."""
        return self.inner.map(fn, items, progress, label, shared)

    def run(self, prims, settings, tasks: list[Task], progress=None):
        base = {t: hashlib.sha256(f"{prims[t].digest()}|{settings!r}|{code_version()}".encode()).hexdigest()
                for t in {task.target for task in tasks}}
        keys = [[_key(base[task.target], x, t0) for x, t0 in zip(task.x0s, task.t0s)] for task in tasks]
        found = self.store.get([k for ks in keys for k in ks])
        todo, where = [], []
        for i, (task, ks) in enumerate(zip(tasks, keys)):
            miss = [j for j, k in enumerate(ks) if k not in found]
            if miss:
                todo.append(Task(task.target, task.x0s[miss], task.t0s[miss]))
                where.append((i, miss))
        fresh = self.inner.run(prims, settings, todo, progress) if todo else []
        new = {}
        out = [[found.get(k) for k in ks] for ks in keys]
        for (i, miss), evs in zip(where, fresh):
            for j, e in zip(miss, evs):
                out[i][j] = e
                if e.reason is not Reason.ERROR:  # a crash may be transient: never remembered
                    new[keys[i][j]] = e
        self.store.put(new)
        self.stats["cache_hits"] += sum(len(ks) for ks in keys) - sum(len(m) for _, m in where)
        self.stats["cache_misses"] += sum(len(m) for _, m in where)
        return out


def _key(base: str, x0: np.ndarray, t0: float) -> str:
    return hashlib.sha256(base.encode() + np.ascontiguousarray(x0, float).tobytes() + np.float64(t0).tobytes()).hexdigest()


def info() -> dict:
    """What the cache holds: stored oracle results and compiled chunks, with their sizes."""
    root = cache_root()
    libs = list((root / "jit").glob("*.so")) if (root / "jit").exists() else []
    store = ResultStore()
    db = store.path
    try:
        n = store.count()
    finally:
        store.close()
    return {"folder": str(root), "oracle_results": n, "results_bytes": db.stat().st_size if db.exists() else 0,
            "compiled_chunks": len(libs), "compiled_bytes": sum(p.stat().st_size for p in libs)}


def clear() -> dict:
    """Remove stored oracle results and compiled chunks; returns what was there."""
    before = info()
    root = cache_root()
    (root / "results.sqlite").unlink(missing_ok=True)
    shutil.rmtree(root / "jit", ignore_errors=True)
    return before
