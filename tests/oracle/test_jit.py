"""The compile cache: compile_many's order, cache hits and failure fallback, same-named Functions,
the compile log, and common-subexpression elimination keeping outputs equal."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.oracle import jit
from mpgspec.oracle.integrator import build_chunk, build_chunks, initial_state
from mpgspec.oracle.jit import cache_dir, compile_cached, compile_many, with_cse
from mpgspec.spec.loader import load_project


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("MPGSPEC_JIT_LOG", raising=False)


def _fns(tag: str, n: int) -> list[ca.Function]:
    x = ca.SX.sym("x", 2)
    return [ca.Function(f"{tag}{k}", [x], [(k + 1) * ca.sin(x[0]) + x[1] ** (k + 1)]) for k in range(n)]


def _eval(fn: ca.Function, v) -> np.ndarray:
    return np.asarray(fn(ca.DM(v))).ravel()


def test_compile_many_keeps_order_and_values():
    fns = _fns("order", 4)
    out = compile_many(fns, ("-O1",), n_jobs=2)
    assert [f.name() for f in out] == [f.name() for f in fns]
    for f, g in zip(fns, out):
        assert not g.is_a("SXFunction")  # loaded from a library
        np.testing.assert_allclose(_eval(g, [0.3, 1.7]), _eval(f, [0.3, 1.7]), rtol=1e-14)


def test_compile_many_hits_the_cache(tmp_path, monkeypatch):
    log = tmp_path / "jit.jsonl"
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(log))
    fns = _fns("hit", 2)
    compile_many(fns, ("-O1",))
    libs = sorted(cache_dir().glob("*.so"))
    assert len(libs) == 2
    stamps = [p.stat().st_mtime_ns for p in libs]
    compile_many(fns, ("-O1",))
    assert [p.stat().st_mtime_ns for p in sorted(cache_dir().glob("*.so"))] == stamps
    recs = [json.loads(line) for line in log.read_text().splitlines()]
    assert [r["hit"] for r in recs] == [False, False, True, True]
    assert [r["name"] for r in recs] == ["hit0", "hit1", "hit0", "hit1"]


def test_failed_compile_falls_back_to_the_uncompiled_function(monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    fns = _fns("fail", 2)
    with pytest.warns(UserWarning, match="running it uncompiled"):
        out = compile_many(fns, ("-O1",), n_jobs=2)
    assert all(a is b for a, b in zip(out, fns))
    assert not list(cache_dir().glob("*.so"))


def test_same_name_different_code_loads_its_own_library():
    x = ca.SX.sym("x")
    f = ca.Function("twin", [x], [2 * x])
    g = ca.Function("twin", [x], [3 * x + 1])
    cf, cg = compile_many([f, g], ("-O1",), n_jobs=2)
    cf2 = compile_cached(f, ("-O1",))
    cg2 = compile_cached(g, ("-O1",))
    assert float(cf(1.5)) == 3.0 and float(cf2(1.5)) == 3.0
    assert float(cg(1.5)) == 5.5 and float(cg2(1.5)) == 5.5
    assert len(list(cache_dir().glob("twin_*.so"))) == 2


def test_compile_log_records_each_call(tmp_path, monkeypatch):
    log = tmp_path / "log.jsonl"
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(log))
    (f,) = _fns("logged", 1)
    compile_cached(f, ("-O1",))
    compile_cached(f, ("-O1",))
    first, second = [json.loads(line) for line in log.read_text().splitlines()]
    assert first["name"] == "logged0" and first["hit"] is False and first["gcc_s"] > 0
    assert first["c_bytes"] > 100 and first["flags"] == ["-O1"]
    assert second["hit"] is True and second["gcc_s"] == 0 and second["c_bytes"] == first["c_bytes"]


def test_large_code_gets_the_large_code_flags(monkeypatch, tmp_path):
    log = tmp_path / "log.jsonl"
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(log))
    monkeypatch.setattr(jit, "LARGE_CODE", 10)
    compile_cached(_fns("big", 1)[0], ("-O1",))
    assert json.loads(log.read_text())["flags"] == ["-O1", *jit.LARGE_CODE_FLAGS]


def _repeated(sym):
    x = sym("x", 3)
    a = ca.sin(x[0] * x[1]) + ca.exp(x[2] * x[0])
    b = ca.sin(x[0] * x[1]) + ca.exp(x[2] * x[0])  # the same expression built twice
    return x, ca.vertcat(a * b, a + b, ca.sqrt(1 + a * a))


@pytest.mark.parametrize("sym", [ca.SX.sym, ca.MX.sym])
def test_cse_keeps_outputs_and_shrinks_the_code(sym):
    x, y = _repeated(sym)
    f = ca.Function("rep", [x], [y])
    g = with_cse(f)
    assert g.name() == f.name() and g.n_in() == f.n_in()
    assert g.n_instructions() < f.n_instructions()
    rng = np.random.default_rng(0)
    for v in rng.uniform(-1, 1, (20, 3)):
        np.testing.assert_allclose(_eval(g, v), _eval(f, v), rtol=1e-15, atol=0)
    cf, cg = compile_many([f, g], ("-O1",))
    for v in rng.uniform(-1, 1, (5, 3)):
        assert np.max(np.abs(_eval(cf, v) - _eval(cg, v))) <= 1e-14


def test_build_chunks_compiles_several_primitives_like_build_chunk(tmp_path):
    root = Path(__file__).resolve().parents[2]
    prims = list(compile_project(load_project(root / "specs" / "pendulum" / "project.yaml")).values())[:2]
    chunks = build_chunks(prims + prims[:1], 0.005, 16)
    assert len(chunks) == 3 and chunks[2] is chunks[0]
    assert [c.prim for c in chunks[:2]] == prims
    for p, c in zip(prims, chunks):
        assert build_chunk(p, 0.005, 16) is c  # remembered on the primitive under build_chunk's key
        plain = build_chunk(p, 0.005, 16, jit=False)
        assert c.fn.class_name() != plain.fn.class_name()  # loaded from a library
        z = initial_state(p, np.asarray(p.setpoint(0.0), float).ravel() + 0.1, 0.0)[:, None]
        zf, out = c.run(z)
        zf0, out0 = plain.run(z)
        np.testing.assert_allclose(zf, zf0, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(out, out0, rtol=1e-12, atol=1e-12)


def test_two_processes_compile_one_library_once(tmp_path):
    """Concurrent processes asking for the same library: one gcc runs, the other waits and loads it."""
    import os
    import subprocess
    import sys

    count = tmp_path / "gcc_calls"
    cc = tmp_path / "cc"
    cc.write_text(f"#!/bin/sh\necho x >> {count}\nsleep 1\nexec gcc \"$@\"\n")
    cc.chmod(0o755)
    script = ("import casadi as ca, numpy as np\nfrom mpgspec.oracle.jit import compile_cached\n"
              "x = ca.SX.sym('x')\nf = compile_cached(ca.Function('shared_lib', [x], [3 * x + 1]), ('-O1',))\n"
              "print(float(f(2)))\n")
    env = {**os.environ, "CC": str(cc)}
    procs = [subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(2)]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert outs == ["7.0", "7.0"]
    assert count.read_text().count("x") == 1


def _caller(hot: bool) -> ca.Function:
    """An MX caller of two SX Functions, one of them named as hot code."""
    x = ca.SX.sym("x", 3)
    inner = ca.Function(("hot_" if hot else "") + "step", [x], [ca.fmax(ca.sin(x) * x[0], ca.cos(x)) + ca.sqrt(1 + x * x)])
    rare = ca.Function("rare", [x], [ca.exp(x) - ca.fmin(x, 0.5)])
    X = ca.MX.sym("X", 3)
    return ca.Function("caller", [X], [inner(X) + rare(inner(X))])


def test_hot_code_is_optimised_alone_with_the_same_values(monkeypatch):
    code = _caller(True)
    cg = ca.CodeGenerator("caller.c", {"with_header": False})
    cg.add(code)
    src = cg.dump()
    hot = jit.hot_code(src, ("-O0",))
    assert hot.count('#pragma GCC optimize ("O1")') == 2  # CasADi's helpers and the hot Function
    assert hot.count("#pragma GCC push_options") == hot.count("#pragma GCC pop_options") == 2
    body = hot[hot.index("hot_step:("):]
    assert body.index("#pragma GCC pop_options") < body.index("/* rare:(")  # the rarely run code stays at -O0
    assert jit.hot_code(src, ("-O1",)) == src and jit.hot_code(src.replace("hot_", "cold_"), ("-O0",)) == \
        src.replace("hot_", "cold_")
    v = [0.3, -1.7, 2.5]
    monkeypatch.setenv("MPGSPEC_QUICK_CC", "")  # gcc, which reads the pragmas (tcc builds -O0 code without them)
    a, b = compile_cached(_caller(True), ("-O0",)), compile_cached(_caller(False), ("-O0",))
    assert np.array_equal(_eval(a, v), _eval(b, v))  # bit for bit: -O1 does not reassociate
    np.testing.assert_allclose(_eval(a, v), _eval(_caller(True), v), rtol=1e-15)


def _mixed() -> ca.Function:
    """Arithmetic, libm, branches and the min/max CasADi's generated code uses."""
    x = ca.SX.sym("x", 3)
    y = ca.if_else(x[0] > x[1], ca.sin(x[0]) * ca.exp(-x[2] ** 2), ca.atan2(x[1], 1 + x[2] ** 2))
    z = ca.fmax(ca.sqrt(1 + x[0] ** 2) - ca.fmin(ca.cos(x[1]), x[2]), ca.fabs(ca.floor(3 * x[2]) / 7)) + x[0] ** 3 / 3
    return ca.Function("mixed", [x], [ca.vertcat(y, z, ca.tanh(y * z) + ca.log(1 + z * z))])


def _log(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


@pytest.mark.skipif(jit.quick_compiler() is None, reason="no tcc (Debian's tcc) on this machine")
def test_unoptimised_code_goes_to_the_quick_compiler_and_computes_the_same_bits(tmp_path, monkeypatch):
    log = tmp_path / "log.jsonl"
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(log))
    pts = np.random.default_rng(3).uniform(-3, 3, (3, 2000))
    quick = compile_cached(_mixed(), ("-O0",)).map(pts.shape[1])
    optimised = compile_cached(_mixed(), ("-O1",)).map(pts.shape[1])
    monkeypatch.setenv("MPGSPEC_QUICK_CC", "")  # everything to gcc
    plain = compile_cached(_mixed(), ("-O0",)).map(pts.shape[1])
    assert [r["cc"] for r in _log(log)] == ["tcc", "gcc", "gcc"]
    assert len(list(cache_dir().glob("mixed_*.so"))) == 3  # the compiler is part of the library's name
    a, b = np.asarray(quick(pts)), np.asarray(plain(pts))
    assert np.array_equal(a, b)  # bit for bit: both evaluate IEEE doubles in the order written
    np.testing.assert_allclose(a, np.asarray(_mixed().map(pts.shape[1])(pts)), rtol=1e-13)
    np.testing.assert_allclose(np.asarray(optimised(pts)), a, rtol=1e-13)


def test_what_the_quick_compiler_cannot_build_goes_to_gcc(tmp_path, monkeypatch):
    """A quick compiler that builds its probe but fails on the real code: gcc builds it, no warning."""
    fake = tmp_path / "quickcc"
    fake.write_text('#!/bin/sh\ncase "$*" in *probe.c*) exec gcc "$@";; esac\necho "cannot" >&2\nexit 1\n')
    fake.chmod(0o755)
    log = tmp_path / "log.jsonl"
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(log))
    monkeypatch.setenv("MPGSPEC_QUICK_CC", str(fake))
    assert jit.quick_compiler() == str(fake)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = compile_cached(_mixed(), ("-O0",))
    assert not f.is_a("SXFunction") and [r["cc"] for r in _log(log)] == ["gcc"]
    np.testing.assert_allclose(_eval(f, [0.3, -1.2, 0.8]), _eval(_mixed(), [0.3, -1.2, 0.8]), rtol=1e-14)
    for name in ("/nonexistent/tcc", ""):  # missing or switched off: no quick compiler
        monkeypatch.setenv("MPGSPEC_QUICK_CC", name)
        assert jit.quick_compiler() is None


def test_a_guarded_small_loops_chunk_is_optimised_only_when_gcc_builds_it(monkeypatch):
    """With tcc the judged chunk keeps the project's -O0 (tcc builds it in milliseconds); without it,
    gcc builds it at GUARDED_FLAGS; an optimising project flag is kept either way."""
    from mpgspec.oracle import judged
    from mpgspec.oracle.looplib import guarded

    root = Path(__file__).resolve().parents[2]
    prims = compile_project(load_project(root / "specs" / "pendulum" / "project.yaml"))
    p = next(p for p in prims.values() if guarded(p))
    fake = Path(jit.__file__)  # any existing file name that is not a compiler: the probe fails
    for quick, want in (("gcc", ("-O0",)), (str(fake), judged.GUARDED_FLAGS), ("", judged.GUARDED_FLAGS)):
        monkeypatch.setenv("MPGSPEC_QUICK_CC", quick)
        assert judged._flags(p, ("-O0",)) == want, quick
        assert judged._flags(p, ("-O2",)) == ("-O2",)
