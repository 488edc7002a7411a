"""The A1's robot library: robust steps that call it equal the inlined ones, bit for bit, and their
gradients agree; one library serves every target, and each target's step is compiled once for its
rollouts and its sequence stepper."""
import numpy as np
import pytest

from mpgspec.robust.rigid import RigidRobustRollout, library_for, rigid_step, robust_jump, robust_plant

NAMES = ["mass_scale", "friction"]


def _steps(prim, settings):
    lib = library_for(prim, settings)
    assert lib is not None
    with_lib = rigid_step(prim, robust_plant(prim, "trunk", lib), NAMES, "trunk", True, settings.dt, lib)
    inline = rigid_step(prim, robust_plant(prim, "trunk"), NAMES, "trunk", True, settings.dt)
    return lib, with_lib, inline


@pytest.mark.parametrize("name", ["Walk(slow)", "Jump", "Stand"])
def test_library_step_equals_the_inlined_step(a1, name):
    """Walk(slow): a contact schedule (its touchdowns at the schedule's boundaries); Jump: contact
    events on the perturbed plant; Stand: a sampled ID-QP."""
    _, prims, settings = a1
    prim = prims[name]
    lib, (step, first, *_), (step0, first0, *_) = _steps(prim, settings)
    rng = np.random.default_rng(1)
    nx, nz = prim.system.nx, step.size1_in(0)
    clocks = [b - settings.dt / 2 for b in prim.boundaries[:6]] + list(rng.uniform(0, 1, 6))
    for t in clocks:
        xs = prim.system.default_state()
        x = xs + 0.02 * rng.standard_normal(nx)
        z = np.concatenate([x, [t, rng.uniform(0, 1)], xs, [rng.uniform(.9, 1.1), rng.uniform(.4, .8)],
                            np.zeros(nz - 2 * nx - 4)])
        d = rng.uniform(-7.5, 7.5, 3)
        for a, b in zip(step(z, d), step0(z, d)):
            np.testing.assert_array_equal(np.array(a), np.array(b))
        for a, b in zip(first(x, t, 0.0, [1.0, 0.6], d), first0(x, t, 0.0, [1.0, 0.6], d)):
            np.testing.assert_array_equal(np.array(a), np.array(b))


def test_a_scheduled_touchdown_through_the_library_moves_the_state(a1):
    """At a boundary where a foot joins the schedule's mode the library's jump puts it down with an
    impact (not the identity), exactly as the inlined jump does."""
    _, prims, settings = a1
    prim = prims["Walk(slow)"]
    lib = library_for(prim, settings)
    jl, j0 = robust_jump(prim, "trunk", lib), robust_jump(prim, "trunk")
    x = prim.system.default_state()
    x[prim.system.model.nq:prim.system.model.nq + 6] = 0.3  # a moving base
    moved = 0
    for b in prim.boundaries:
        a = np.array(jl(x, np.zeros(prim.system.nu), b, 1.0, 1.0, np.zeros(3))).ravel()
        np.testing.assert_array_equal(a, np.array(j0(x, np.zeros(prim.system.nu), b, 1.0, 1.0, np.zeros(3))).ravel())
        moved += not np.allclose(a, x)
    assert moved


def test_one_library_for_every_target_and_its_gradient(a1):
    """Two targets share the robot's library; the push gradient, through its variant with reverse
    derivatives (built on the first gradient), equals the inlined one."""
    _, prims, settings = a1
    short = dict(segments=4, settings=settings, horizon=0.05, duration=0.04)
    rr = RigidRobustRollout(prims["Walk(slow)"], NAMES, "trunk", True, **short)
    rr_jump = RigidRobustRollout(prims["Jump"], NAMES, "trunk", True, **short)
    assert rr.lib is not None and rr.lib.path == rr_jump.lib.path  # one robot library
    assert rr.libs[0] == rr.lib.path and len(set(rr.libs + rr_jump.libs)) == 3  # and a step library per target
    rr0 = RigidRobustRollout(prims["Walk(slow)"], NAMES, "trunk", True, **{**short, "settings": settings.replace(jit=False)})
    x0 = np.tile(prims["Walk(slow)"].system.default_state(), (2, 1))
    # a sample at switch-in (the first sample's own dependence on the push) and the last one, in one call
    args = (x0, np.zeros(2), np.array([[1.05, 0.5]] * 2), np.full((2, 3, 4), 2.0), [0, 0], [0, rr.N])
    g, g0 = rr.gradients(*args), rr0.gradients(*args)
    assert np.abs(g[1]).max() > 0
    assert len(rr.libs) == 4 and rr.lib.path not in rr.libs[2:]  # the reverse variant and the step's twin, once
    np.testing.assert_allclose(g, g0, rtol=1e-9, atol=1e-12)


def test_requests_build_once_per_system(monkeypatch):
    """Requests for one system share one build (and threads that ask while it builds wait for it);
    another system gets its own."""
    import threading
    import time

    from mpgspec.robust import library

    calls = []

    def build(sys, reverse):
        calls.append((sys, reverse))
        time.sleep(0.2)
        return f"library of {sys.name}" + (" with reverse derivatives" if reverse else "")

    class System:
        def __init__(self, name):
            self.name = name

    monkeypatch.setattr(library, "_build", build)
    a, b = System("a"), System("b")
    got = []
    threads = [threading.Thread(target=lambda: got.append(library.robot_library(a))) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got == ["library of a"] * 3
    assert library.robot_library(b) == "library of b"
    assert library.robot_library(a, True) == library.robot_library(a, True) == "library of a with reverse derivatives"
    assert calls == [(a, False), (b, False), (a, True)]


def test_a_library_compiled_in_the_background_is_loaded_once_done(tmp_path, monkeypatch):
    """compile_library without waiting returns at once and leaves gcc running; the next call with the
    same code waits for that compile instead of starting another, and loads the library."""
    import json

    import casadi as ca

    from mpgspec.oracle.jit import compile_library

    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("MPGSPEC_JIT_LOG", str(tmp_path / "jit.jsonl"))
    x = ca.SX.sym("x", 3)
    fn = ca.Function("lib_bg_f", [x], [ca.sin(x) * ca.dot(x, x)])
    assert compile_library("lib_bg", [fn], ("-O1",), wait=False) is None
    path = compile_library("lib_bg", [fn], ("-O1",))
    assert path is not None and path.exists()
    f = ca.external("lib_bg_f", str(path))
    np.testing.assert_allclose(np.array(f([1.0, 2.0, 3.0])).ravel(), np.sin([1, 2, 3]) * 14.0)
    log = [json.loads(line) for line in open(tmp_path / "jit.jsonl")]
    assert len(log) == 1 and log[0]["name"] == "lib_bg"  # one compile: the second call found it (or waited)
