"""A poisoned or unusable cache never changes a verdict: rows rewritten to a real "safe" evidence,
evidence moved between keys, compiled chunks replaced, a truncated or random-bytes database, a
cache path that is a file, a database that cannot be opened, the cache cleared during a run. Each
run's verdicts and exit code equal those of a clean run (the tiny CLI project with one assertion
that cannot hold: exit 1)."""
from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from mpgspec import integrity
from mpgspec.cli import main
from mpgspec.oracle import cache as cache_mod

TINY = Path(__file__).parents[1] / "fixtures" / "cli_tiny" / "project.yaml"


@pytest.fixture()
def failing(tmp_path) -> Path:
    """The tiny project plus `edge: Left -> Right`, which cannot hold (Right forbids x < 0.4)."""
    text = TINY.read_text().replace("assertions:\n", "assertions:\n  - edge: {from: Left, to: Right}\n", 1)
    path = tmp_path / "spec" / "project.yaml"
    path.parent.mkdir()
    path.write_text(text)
    return path


def verify(capsys, spec: Path, out: Path) -> tuple[int, dict, str]:
    rc = main(["verify", str(spec), "--out", str(out), "-q"])
    o, e = capsys.readouterr()
    (path,) = out.glob("*/report.json")
    return rc, json.loads(path.read_text()), o + e


def verdicts(report: dict) -> dict:
    """What a run decided: its edges with class and windows, and each assertion's outcome."""
    return {"edges": sorted((t["from"], t["to"], t["class"], json.dumps(t.get("windows"))) for t in report["transitions"]),
            "assertions": [(a["description"], a["status"]) for a in report["assertions"]],
            "verdicts": {k: report["verdicts"][k] for k in ("safe", "unsafe", "inconclusive", "errors")}}


@pytest.fixture(scope="module")
def compiled(tmp_path_factory) -> Path:
    """A jit folder with the tiny project's compiled chunks (sealed under this process's key), built
    once: each test's fresh cache starts with a copy, so its runs start without stored results but
    do not compile the same code again. A test that changes the key or the libraries still sees
    them rejected and rebuilt."""
    root = tmp_path_factory.mktemp("compiled")
    spec = root / "spec" / "project.yaml"
    spec.parent.mkdir()
    spec.write_text(TINY.read_text())
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MPGSPEC_CACHE", str(root / "cache"))
        main(["verify", str(spec), "--out", str(root / "out"), "-q"])
    return root / "cache" / "jit"


@pytest.fixture()
def clean(capsys, tmp_path, monkeypatch, failing, compiled):
    """(exit code, verdicts) of a run on a fresh cache (no stored results; the compiled chunks
    copied), which it leaves filled."""
    shutil.copytree(compiled, tmp_path / "cache" / "jit")
    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path / "cache"))
    rc, rep, _ = verify(capsys, failing, tmp_path / "clean")
    assert rc == 1
    return rc, verdicts(rep)


def _db(tmp_path) -> sqlite3.Connection:
    return sqlite3.connect(tmp_path / "cache" / "results.sqlite")


def test_rows_rewritten_to_a_real_safe_evidence_are_recomputed(capsys, tmp_path, failing, clean):
    with _db(tmp_path) as db:
        rows = db.execute("SELECT key, evidence FROM results2").fetchall()
        safe = next(v for _k, v in rows if json.loads(v)["verdict"] == 1)
        db.execute("UPDATE results2 SET evidence = ?", (safe,))  # the attacker has no key: macs stay as they were
    rc, rep, out = verify(capsys, failing, tmp_path / "poisoned")
    assert (rc, verdicts(rep)) == clean
    n_changed = sum(v != safe for _k, v in rows)
    assert rep["timing"]["cache_rejected"] == n_changed > 0
    assert f"{n_changed} stored results failed their integrity check" in out


def test_a_genuine_row_moved_to_another_key_is_rejected(capsys, tmp_path, failing, clean):
    with _db(tmp_path) as db:
        rows = db.execute("SELECT key, evidence, mac FROM results2").fetchall()
        _k, safe, tag = next(r for r in rows if json.loads(r[1])["verdict"] == 1)
        db.execute("UPDATE results2 SET evidence = ?, mac = ?", (safe, tag))
    rc, rep, _ = verify(capsys, failing, tmp_path / "moved")
    assert (rc, verdicts(rep)) == clean and rep["timing"]["cache_rejected"] >= len(rows) - 1


def test_a_forged_mac_without_the_key_is_rejected(capsys, tmp_path, failing, clean, monkeypatch):
    with _db(tmp_path) as db:
        rows = db.execute("SELECT key, evidence FROM results2").fetchall()
        safe = next(v for _k, v in rows if json.loads(v)["verdict"] == 1)
        monkeypatch.setenv(integrity.KEY_ENV, "a key the attacker chose")
        db.executemany("UPDATE results2 SET evidence = ?, mac = ? WHERE key = ?",
                       [(safe, integrity.mac("results", k, safe), k) for k, _v in rows])
        monkeypatch.delenv(integrity.KEY_ENV)
    rc, rep, _ = verify(capsys, failing, tmp_path / "forged")
    assert (rc, verdicts(rep)) == clean and rep["timing"]["cache_rejected"] == len(rows)


def test_another_key_trusts_nothing_stored_and_decides_the_same(capsys, tmp_path, failing, clean, monkeypatch):
    monkeypatch.setenv(integrity.KEY_ENV, "the main branch's own key")
    rc, rep, _ = verify(capsys, failing, tmp_path / "other_key")
    assert (rc, verdicts(rep)) == clean and rep["timing"]["cache_hits"] == 0


def test_replaced_compiled_chunks_are_compiled_again(tmp_path, failing, clean):
    """In a new process (this one has the genuine libraries loaded): every library replaced by
    garbage, the stored results dropped so that the oracle runs through the chunks."""
    libs = list((tmp_path / "cache" / "jit").glob("*.so"))
    assert libs
    for lib in libs:
        fake = lib.with_suffix(".fake")
        fake.write_bytes(b"\x7fELF garbage" * 64)
        os.replace(fake, lib)
    with _db(tmp_path) as db:
        db.execute("DELETE FROM results2")
    env = {**os.environ, "MPGSPEC_CACHE": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-m", "mpgspec", "verify", str(failing), "--out", str(tmp_path / "chunks"), "-q"],
                       capture_output=True, text=True, env=env, timeout=600)
    (path,) = (tmp_path / "chunks").glob("*/report.json")
    assert (r.returncode, verdicts(json.loads(path.read_text()))) == clean, r.stderr[-2000:]
    rebuilt = [lib for lib in libs if b"garbage" not in lib.read_bytes()[:64]]
    assert rebuilt and "Traceback" not in r.stderr  # the chunks the oracle needed were compiled again


@pytest.mark.parametrize("damage", ["truncated", "random bytes", "a folder"])
def test_an_unusable_database_degrades_to_memory(capsys, tmp_path, failing, clean, damage):
    db = tmp_path / "cache" / "results.sqlite"
    if damage == "truncated":
        data = db.read_bytes()
        db.write_bytes(data[: len(data) // 3])
    elif damage == "random bytes":
        db.write_bytes(bytes(range(256)) * 64)
    else:
        db.unlink()
        db.mkdir()
    with pytest.warns(UserWarning, match="cannot be used"):
        rc, rep, out = verify(capsys, failing, tmp_path / "damaged")
    assert (rc, verdicts(rep)) == clean and "Traceback" not in out


def test_a_cache_path_that_is_a_file(capsys, tmp_path, failing, clean, monkeypatch):
    path = tmp_path / "not_a_folder"
    path.write_text("x")
    monkeypatch.setenv("MPGSPEC_CACHE", str(path))
    with pytest.warns(UserWarning):
        rc, rep, out = verify(capsys, failing, tmp_path / "file_cache")
    assert (rc, verdicts(rep)) == clean and "Traceback" not in out
    assert main(["cache", "info"]) == 0 and main(["cache", "clear"]) == 0


def test_clearing_the_cache_during_a_run(capsys, tmp_path, failing, clean, monkeypatch):
    real_put = cache_mod.ResultStore.put

    def put_after_clear(self, items):
        cache_mod.clear()
        return real_put(self, items)

    with _db(tmp_path) as db:
        db.execute("DELETE FROM results2")
    monkeypatch.setattr(cache_mod.ResultStore, "put", put_after_clear)
    rc, rep, out = verify(capsys, failing, tmp_path / "cleared")
    assert (rc, verdicts(rep)) == clean and "Traceback" not in out


def test_verify_cache_catches_a_row_forged_with_the_key(capsys, tmp_path, failing, clean, monkeypatch):
    """A row rewritten with a valid HMAC (the key leaked): run again under MPGSPEC_VERIFY_CACHE=1,
    every stored result is recomputed and compared; the mismatch fails the run (exit 1, loudly)."""
    with _db(tmp_path) as db:
        rows = db.execute("SELECT key, evidence FROM results2").fetchall()
        safe = next(v for _k, v in rows if json.loads(v)["verdict"] == 1)
        forged = [(safe, integrity.mac("results", k, safe), k) for k, v in rows if json.loads(v)["verdict"] != 1]
        db.executemany("UPDATE results2 SET evidence = ?, mac = ? WHERE key = ?", forged)
    assert forged
    monkeypatch.setenv(cache_mod.VERIFY_ENV, "1")
    rc, rep, out = verify(capsys, failing, tmp_path / "verified")
    t = rep["timing"]
    assert t["cache_verified"] == len(rows) and t["cache_mismatch"] == len(forged)
    assert verdicts(rep) == clean[1] and rc == 1 and "disagreed with a fresh run" in out
    monkeypatch.setenv(cache_mod.VERIFY_ENV, "0")
    rc, rep, _ = verify(capsys, failing, tmp_path / "after")  # the fresh results replaced the forged ones
    assert (rc, verdicts(rep)) == clean and rep["timing"]["cache_hits"] == len(rows)


@pytest.mark.parametrize("value", ["-0.1", "1.5", "nan"])
def test_verify_cache_takes_a_fraction(capsys, value):
    rc = main(["verify", str(TINY), "--no-write", "-q", "--verify-cache", value])
    _out, err = capsys.readouterr()
    assert rc == 2 and "--verify-cache" in err


def test_verify_cache_flag_reruns_the_stored_results(capsys, tmp_path, failing, clean, monkeypatch):
    monkeypatch.delenv(cache_mod.VERIFY_ENV, raising=False)
    monkeypatch.setattr(os, "environ", dict(os.environ))  # the flag sets the variable for this run only
    rc = main(["verify", str(failing), "--out", str(tmp_path / "v"), "-q", "--verify-cache", "1"])
    out = capsys.readouterr()
    (path,) = (tmp_path / "v").glob("*/report.json")
    t = json.loads(path.read_text())["timing"]
    assert rc == 1 and t["cache_verified"] == t["oracle_calls"] > 0 and t["cache_mismatch"] == 0, out


def test_verify_cache_reruns_every_call_of_the_asserted_edges(capsys, tmp_path, failing, clean, monkeypatch):
    """A tiny fraction samples almost nothing by key, but every stored call into an edge an assertion
    names (Left -> Mid, Left -> Right, Mid -> Right) is run again and compared."""
    with _db(tmp_path) as db:
        stored = db.execute("SELECT COUNT(*) FROM results2").fetchone()[0]
    monkeypatch.setenv(cache_mod.VERIFY_ENV, "1e-12")
    rc, rep, _ = verify(capsys, failing, tmp_path / "asserted")
    named = sum(len(t["t_A"]) * len(t["t_B"]) for t in rep["transitions"]
                if (t["from"], t["to"]) in {("Left", "Mid"), ("Left", "Right"), ("Mid", "Right")})
    t = rep["timing"]
    assert (rc, verdicts(rep)) == clean and 0 < named == t["cache_verified"] < stored and t["cache_mismatch"] == 0


def _fresh_key():
    integrity._key.cache_clear()
    return integrity.key()


def test_the_key_lives_outside_the_cache_and_survives_a_read_only_home(tmp_path, monkeypatch):
    monkeypatch.delenv(integrity.KEY_ENV, raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    first = _fresh_key()
    assert (tmp_path / "config" / "mpgspec" / "cache.key").stat().st_mode & 0o777 == 0o600
    assert _fresh_key() == first  # the same key for the next process
    blocked = tmp_path / "a_file"
    blocked.write_text("x")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(blocked))  # cannot hold a folder: the private temporary one
    monkeypatch.setattr(integrity.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    second = _fresh_key()
    assert _fresh_key() == second and (tmp_path / "tmp").iterdir()
    monkeypatch.setattr(integrity.tempfile, "gettempdir", lambda: str(blocked))
    with pytest.warns(UserWarning, match="no usable cache key"):
        third = _fresh_key()
    assert third != _fresh_key()  # random per process: nothing stored before verifies
    monkeypatch.undo()
    _fresh_key()
