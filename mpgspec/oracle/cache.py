"""Content-addressed store of oracle results, so unchanged work is never simulated twice.

A cell's key hashes what decides its verdict: the target's closed loop (CompiledPrimitive.digest:
its serialised CasADi Functions and numbers), the start state and clock, the oracle settings,
the backend and mpgspec's version. Editing one primitive changes its digest and its setpoint
samples, so only the edges into and out of it run again. Results are kept as JSON rows in one
SQLite file next to the compiled chunks (MPGSPEC_CACHE, else ~/.cache/mpgspec).

Every row carries an HMAC of its key and value (mpgspec.integrity: the key never lives in the cache
folder). A row whose HMAC does not verify (edited, copied from another machine, written by a
pull request into a restored CI cache) is ignored, recomputed and counted (stats["cache_rejected"]).
A cache that cannot be used (a read-only or corrupt database, MPGSPEC_CACHE naming a file, the
file removed during a run) degrades to an in-memory store for the rest of the run, with one warning.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
import warnings
from pathlib import Path

import numpy as np

from functools import lru_cache

from .. import __version__
from ..integrity import authentic, mac
from .evidence import OracleEvidence, Reason
from .tasks import Executor, Task


PRESENTATION = ("mpgspec/cli/", "mpgspec/report/sections/", "mpgspec/report/ci.py", "mpgspec/report/diff.py",
                "mpgspec/report/fig6.py", "mpgspec/report/files.py", "mpgspec/report/findings.py",
                "mpgspec/report/html.py", "mpgspec/report/index.py", "mpgspec/report/playback.py",
                "mpgspec/report/svg.py", "mpgspec/report/write.py")
"""Source that only shows or writes what was computed (the command line, pages, pictures, CI formats):
nothing it does reaches a cached result, so a change to it keeps the cache. Everything else is hashed."""


def code_files(root: Path) -> list[Path]:
    """The source files code_version hashes: mpgspec's and the verifiers', but PRESENTATION."""
    files = sorted(f for d in ("mpgspec", "verifiers") for f in (root / d).rglob("*.py"))
    return [f for f in files if not f.relative_to(root).as_posix().startswith(PRESENTATION)]


@lru_cache(maxsize=1)
def code_version() -> str:
    """The package version and a hash of the source of mpgspec and its verifiers: cached results
    are keyed by it, so a changed oracle, judge or verifier never serves results computed by the old one
    (a change to how results are shown, PRESENTATION, keeps them)."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256(__version__.encode())
    for f in code_files(root):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return f"{__version__}+{h.hexdigest()[:16]}"


def cache_root() -> Path:
    return Path(os.environ.get("MPGSPEC_CACHE", Path.home() / ".cache" / "mpgspec"))


class ResultStore:
    """Oracle evidence and memoised values by key, in SQLite (one writer: the process that runs the
    build), each row authenticated (the module's docstring)."""

    def __init__(self, path: Path | None = None):
        self.path = Path(path) if path else cache_root() / "results.sqlite"
        self._db: sqlite3.Connection | None = None
        self.rejected = 0
        self.unusable: str | None = None

    @property
    def db(self) -> sqlite3.Connection:
        if self._db is None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._db = self._open(sqlite3.connect(self.path))
            except (OSError, sqlite3.Error) as e:
                self._degrade(e)
        return self._db

    @staticmethod
    def _open(db: sqlite3.Connection) -> sqlite3.Connection:
        db.execute("CREATE TABLE IF NOT EXISTS results2 (key TEXT PRIMARY KEY, evidence TEXT, mac TEXT)")
        db.execute("CREATE TABLE IF NOT EXISTS memo2 (key TEXT PRIMARY KEY, value TEXT, mac TEXT)")
        return db

    def _degrade(self, err: Exception) -> None:
        """Go on with an in-memory store (nothing from the file is trusted or kept), warning once."""
        if self.unusable is None:
            self.unusable = f"{type(err).__name__}: {err}"
            warnings.warn(f"the result cache {self.path} cannot be used ({self.unusable}); this run keeps "
                          "its results in memory only")
        if self._db is not None:
            try:
                self._db.close()
            except sqlite3.Error:
                pass
        self._db = self._open(sqlite3.connect(":memory:"))

    def _rows(self, sql: str, args) -> list:
        try:
            return self.db.execute(sql, args).fetchall()
        except sqlite3.Error as e:
            self._degrade(e)
            return []

    def _write(self, sql: str, rows: list) -> None:
        try:
            with self.db:
                self.db.executemany(sql, rows)
        except sqlite3.Error as e:
            self._degrade(e)
            with self.db:
                self.db.executemany(sql, rows)

    def _verified(self, table: str, key: str, value, tag) -> bool:
        ok = isinstance(value, str) and authentic(tag, table, key, value)
        self.rejected += not ok
        return ok

    def get(self, keys: list[str]) -> dict[str, OracleEvidence]:
        out = {}
        for a in range(0, len(keys), 500):
            part = keys[a:a + 500]
            rows = self._rows(f"SELECT key, evidence, mac FROM results2 WHERE key IN ({','.join('?' * len(part))})",
                              part)
            for k, v, tag in rows:
                if self._verified("results", k, v, tag):
                    try:
                        out[k] = _load(v)
                    except (ValueError, TypeError, KeyError):  # authentic but unreadable (an older layout)
                        self.rejected += 1
        return out

    def put(self, items: dict[str, OracleEvidence]) -> None:
        rows = []
        for k, e in items.items():
            text = json.dumps(e.to_dict())
            rows.append((k, text, mac("results", k, text)))
        self._write("INSERT OR REPLACE INTO results2 VALUES (?, ?, ?)", rows)

    def _memo_text(self, key: str, count: bool) -> str | None:
        """The authentic JSON text stored under key, else None (counted as rejected when `count`)."""
        rows = self._rows("SELECT value, mac FROM memo2 WHERE key = ?", (key,))
        if not rows:
            return None
        value, tag = rows[0]
        ok = isinstance(value, str) and authentic(tag, "memo", key, value)
        self.rejected += count and not ok
        return value if ok else None

    def memo_get(self, key: str):
        text = self._memo_text(key, count=True)
        return None if text is None else json.loads(text)

    def memo_has(self, key: str) -> bool:
        return self._memo_text(key, count=False) is not None

    def memo_put(self, key: str, value) -> None:
        text = json.dumps(value, default=_plain)
        self._write("INSERT OR REPLACE INTO memo2 VALUES (?, ?, ?)", [(key, text, mac("memo", key, text))])

    def count(self) -> int:
        if not self.path.is_file():
            return 0
        rows = self._rows("SELECT COUNT(*) FROM results2", ())
        return rows[0][0] if rows else 0

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
        return self.store.memo_get(key)

    def has(self, key: str) -> bool:
        """Whether an authentic value is stored under key."""
        return self.store.memo_has(key)

    def put(self, key: str, value) -> None:
        self.store.memo_put(key, value)


class CachedExecutor:
    """Runs only the start points whose results are not stored yet, through the inner executor.

    verify (a fraction in [0, 1]; default MPGSPEC_VERIFY_CACHE, which `verify --verify-cache` sets):
    that share of the stored results, picked by their keys (the same ones every run), and every
    stored result of the rows a task flags (Task.recheck: the edges assertions name) is run again
    and compared with what was stored; a different verdict is a mismatch (stats["cache_mismatch"]),
    the fresh result is used and stored, and the CLI fails."""

    def __init__(self, inner: Executor, store: ResultStore | None = None, verify: float | None = None):
        self.inner = inner
        self.store = store or ResultStore()
        self.verify = verify_fraction() if verify is None else float(verify)
        self._stats = {"cache_hits": 0, "cache_misses": 0, "cache_verified": 0, "cache_mismatch": 0}
        self.memo = Memo(self.store)

    @property
    def stats(self) -> dict:
        """Oracle calls taken from the cache and run, stored rows that failed their check, stored
        results run again (verify) and those that disagreed."""
        return {**self._stats, "cache_rejected": self.store.rejected}

    @property
    def workers(self) -> int:
        return self.inner.workers

    def map(self, fn, items, progress=None, label="tasks", shared=None) -> list:
        """The inner executor's map (its results are not stored here: the stages memoise their own)."""
        return self.inner.map(fn, items, progress, label, shared)

    def _rechecked(self, key: str) -> bool:
        return self.verify > 0 and int(key[:12], 16) < self.verify * 16 ** 12

    def run(self, prims, settings, tasks: list[Task], progress=None):
        base = {t: hashlib.sha256(f"{prims[t].digest()}|{settings!r}|{code_version()}".encode()).hexdigest()
                for t in {task.target for task in tasks}}
        keys = [[_key(base[task.target], x, t0) for x, t0 in zip(task.x0s, task.t0s)] for task in tasks]
        found = self.store.get([k for ks in keys for k in ks])
        todo, where = [], []
        for i, (task, ks) in enumerate(zip(tasks, keys)):
            again = task.recheck if task.recheck is not None and self.verify > 0 else np.zeros(len(ks), bool)
            miss = [j for j, k in enumerate(ks) if k not in found or self._rechecked(k) or again[j]]
            if miss:
                todo.append(Task(task.target, task.x0s[miss], task.t0s[miss]))
                where.append((i, miss))
        fresh = self.inner.run(prims, settings, todo, progress) if todo else []
        new = {}
        out = [[found.get(k) for k in ks] for ks in keys]
        for (i, miss), evs in zip(where, fresh):
            for j, e in zip(miss, evs):
                k = keys[i][j]
                if k in found:  # a stored result run again
                    self._stats["cache_verified"] += 1
                    old = found[k]
                    if (old.verdict, old.status, old.reason) != (e.verdict, e.status, e.reason):
                        self._stats["cache_mismatch"] += 1
                out[i][j] = e
                if e.reason is not Reason.ERROR:  # a crash may be transient: never remembered
                    new[k] = e
        self.store.put(new)
        hits = sum(k in found for ks in keys for k in ks)
        self._stats["cache_hits"] += hits
        self._stats["cache_misses"] += sum(len(ks) for ks in keys) - hits
        return out


VERIFY_ENV = "MPGSPEC_VERIFY_CACHE"


def verify_fraction() -> float:
    """The share of stored results to run again (MPGSPEC_VERIFY_CACHE; 0 when unset or not a number
    in [0, 1], which `verify --verify-cache` refuses before setting it)."""
    try:
        f = float(os.environ.get(VERIFY_ENV, "0"))
    except ValueError:
        return 0.0
    return f if 0.0 <= f <= 1.0 else 0.0


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
    try:
        (root / "results.sqlite").unlink(missing_ok=True)
    except OSError:  # MPGSPEC_CACHE names a file, or the folder is read-only: nothing of ours to remove
        pass
    shutil.rmtree(root / "jit", ignore_errors=True)
    return before
