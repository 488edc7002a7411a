"""The loop library (mpgspec/oracle/looplib.py): a judged chunk and a trace chunk of an A1 walk whose
closed loop and jump are called from the primitive's compiled library give the same bits
as the chunks with everything inlined, and the cross-check's compiled law equals CasADi's virtual
machine evaluating prim.loop."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.oracle import looplib
from mpgspec.oracle.integrator import build_chunk, initial_state, start_states
from mpgspec.oracle.judged import build_judged_chunk
from mpgspec.spec.loader import load_project

NAME = "Walk(slow)"
REFERENCE_FLAGS = ("-O0",)
"""The inlined references are compiled unoptimised (by the quick compiler when one is installed):
IEEE arithmetic in the order written, so their bits are the same as optimised code's."""


@pytest.fixture(scope="module")
def walk(a1_project):
    """(a copy that inlines everything, a copy with its loop library attached, settings)."""
    _spec, prims, settings = a1_project
    inline = dataclasses.replace(prims[NAME], cache={"looplib": None})
    lib = dataclasses.replace(prims[NAME], cache={})
    assert looplib.attach(lib) is not None
    return inline, lib, settings


def _starts(prim, n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    t0s = np.linspace(0.0, float(prim.period), n, endpoint=False)
    X = np.array([prim.x_star(t) for t in t0s])
    X[:, :prim.system.model.nq] += 1e-3 * rng.standard_normal((n, prim.system.model.nq))
    return X, t0s


def test_judged_chunk_through_the_library_gives_the_inlined_bits(walk):
    inline, lib, s = walk
    X, t0s = _starts(inline)
    a = build_judged_chunk(inline, s.dt, 8, s.chunk, s.h_tolerance, 1.0, flags=REFERENCE_FLAGS)
    b = build_judged_chunk(lib, s.dt, 8, s.chunk, s.h_tolerance, 1.0)
    assert looplib.libs_of(lib) and not looplib.libs_of(inline)
    Z = np.vstack([start_states(inline, X, t0s), a.lay.start(np.full(len(t0s), 1.0))])
    za, zb = Z.copy(), Z.copy()
    for _ in range(4):
        za, zb = a.run(za).copy(), b.run(zb).copy()
        np.testing.assert_array_equal(za, zb)
    assert np.isfinite(za[:a.nz]).all()


def test_trace_chunk_through_the_library_gives_the_inlined_bits(walk):
    inline, lib, s = walk
    X, t0s = _starts(inline, 1)
    a = build_chunk(inline, s.dt, 8, with_state=True, boundaries=False, flags=REFERENCE_FLAGS)
    b = build_chunk(lib, s.dt, 8, with_state=True, boundaries=False)
    z = initial_state(inline, X[0], t0s[0])[:, None]
    (za, oa), (zb, ob) = a.run(z), b.run(z)
    np.testing.assert_array_equal(za, zb)
    np.testing.assert_array_equal(oa, ob)


def test_crosscheck_law_equals_the_virtual_machine(walk):
    _inline, lib, _s = walk
    law = looplib.law(lib)
    X, t0s = _starts(lib, 4)
    for x, t in zip(X, t0s):
        for s_ in (0.0, 0.3):  # before and after the windows anchored on time since switch-in open
            _xdot, h_vm, _ur, u_vm = lib.loop(x, t, s_, X[0])
            h, u = law(x, t, s_, X[0])
            np.testing.assert_array_equal(np.asarray(h, float).ravel(), np.asarray(h_vm, float).ravel())
            np.testing.assert_array_equal(np.asarray(u, float).ravel(), np.asarray(u_vm, float).ravel())


def test_without_a_compiler_the_loop_stays_inlined(a1_project, tmp_path, monkeypatch):
    """gcc failing: no library is attached (with a warning), so chunks inline the loop as before."""
    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "false")
    p = dataclasses.replace(a1_project[1][NAME], cache={})
    with pytest.warns(UserWarning, match="compiling (loop|margin)_"):
        assert looplib.attach(p) is None
    assert looplib.libs_of(p) == () and looplib.caller_flags(p, ("-O1",)) == ("-O1",)
    assert looplib.law(p) is None


def test_small_loops_have_no_library(a1_project):
    """Only loops called from MX graphs get a library; a pendulum-sized loop stays inlined SX."""
    prims = compile_project(load_project(Path(__file__).parents[2] / "specs" / "pendulum" / "project.yaml"))
    assert not any(looplib.is_large(p) for p in prims.values())
    assert all(looplib.is_large(p) for p in a1_project[1].values())


def test_walks_share_one_jump_library_and_the_plain_loop_is_loop_g_without_guards(a1_project):
    """Primitives whose jumps are the same Function (the walks' scheduled touchdowns) link one jump
    library; a guarded loop's plain `loop` is a call into `loop_g` and gives its first outputs."""
    _spec, prims, _ = a1_project
    a, b = (dataclasses.replace(prims[n], cache={}) for n in (NAME, "Walk(fast)"))
    la, lb = looplib.attach(a), looplib.attach(b)
    jumps = [[p for p in lib.paths if p.name.startswith("jump_")] for lib in (la, lb)]
    assert len(jumps[0]) == 1 and jumps[0] == jumps[1]
    assert set(la.paths) - set(jumps[0]) != set(lb.paths) - set(jumps[1])  # each its own loop
    x, t = a.x_star(0.1), 0.1
    x_sw = x + 1e-3
    plain, guarded = la.get("loop")(x, t, 0.2, x_sw), la.get("loop_g")(x, t, 0.2, x_sw)
    assert len(plain) == 4 and len(guarded) == 5
    for u, v in zip(plain, guarded):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))
    assert np.isfinite(np.asarray(plain[0])).all()
