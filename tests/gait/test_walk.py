"""The A1's walks: stable orbits shown by their multipliers, gait tables that regenerate, 20 s of
walking at every speed from the orbit, inside C, at the commanded mean speed, and E holding where the
tube is thinnest, before a touchdown."""
from pathlib import Path

import numpy as np
import pytest

from mpgspec.compile.rigidbody.system import feet_on_ground
from mpgspec.compile.system import compile_system
from mpgspec.robots.quadruped.gait.library import compare, generate, load_gait_file
from mpgspec.robots.quadruped.gait.orbit import StrideMap, find_orbit
from mpgspec.spec.loader import load_project

A1 = Path(__file__).parents[2] / "specs" / "a1"
SPEEDS = {"Walk(in_place)": 0.0, "Walk(slow)": 0.2, "Walk(medium)": 0.4, "Walk(fast)": 0.6}


@pytest.fixture(scope="module")
def spec(a1_project):
    return a1_project[0]


@pytest.fixture(scope="module")
def system(spec):
    return compile_system(spec)


@pytest.fixture(scope="module")
def prims(a1_project):
    return a1_project[1]


def _stand(sys, ctrl):
    x = sys.default_state()
    for j, a in ctrl.pose.items():
        x[sys.state_names.index(j)] = a
    return feet_on_ground(sys, x)


def test_committed_gait_tables_regenerate_within_tolerance():
    """`mpgspec gait specs/a1/gaits.yaml` reproduces the committed tables; each orbit is stable up
    to the ground symmetry, whose three multipliers are 1."""
    tables = generate(A1 / "gaits.yaml", progress=lambda m: None)
    gf = load_gait_file(A1 / "gaits.yaml")
    names = compile_system(load_project(A1 / gf.project)).state_names
    assert compare(tables, names) == []
    assert {t.node for t in tables if not hasattr(t, "orbit")} == {"Jump", "Land"}  # flows of the transients
    for t in (t for t in tables if hasattr(t, "orbit")):
        o = t.orbit
        assert o.status == "converged" and o.residual < 1e-10
        assert o.spectral_radius < 0.2
        assert set(o.neutral) == {"base_x", "base_y", "yaw"}
        for mult, defect in o.neutral.values():
            assert abs(mult - 1) < 1e-6 and defect < 1e-6
        assert o.stats["mean_speed"] == pytest.approx(o.speed, abs=1e-9)
        assert o.stats["peak_torque"] <= 33.5 and o.stats["least_normal_force"] > 0
        assert o.stats["least_cone_margin"] > 0


def test_a_destabilised_gait_is_rejected_by_its_multipliers(spec, system):
    """Without trunk roll/pitch damping (and without the cap on the tilt law) the trot still has an orbit, but it
    repels."""
    inst = next(i for i in spec.primitives if i.name == "Walk(in_place)")
    ctrl = inst.spec.controller.model_copy(update={"d_tilt": 0.0, "tilt_accel_limit": None})
    orbit = find_orbit(StrideMap(system, ctrl, 0.001), _stand(system, ctrl), 0.0)
    assert orbit.status == "converged"
    assert orbit.spectral_radius > 1.0


@pytest.mark.parametrize("name", list(SPEEDS))
def test_twenty_seconds_of_walking_from_the_orbit(prims, name):
    """The compiled Walk (the loop the oracle verifies) walks 20 s inside C at the commanded speed."""
    from verifiers.floquet_hybrid import HybridFlow

    p = prims[name]
    flow = HybridFlow(p, 0.001)
    periods = int(np.ceil(20.0 / p.period))
    x0 = np.array(p.setpoint(0.0), float).ravel()
    XT, hmin = flow.run(x0[:, None], np.zeros(1), periods)
    assert np.isfinite(XT).all()
    assert hmin[0] >= 0, f"{name} left C (least h {hmin[0]:.3g})"
    mean = (XT[0, 0] - x0[0]) / (periods * p.period)
    v = SPEEDS[name]
    assert abs(mean - v) <= max(0.1 * v, 0.01), f"{name}: mean speed {mean:.4f} m/s for {v} m/s"


@pytest.mark.slow
def test_nodes_of_one_gait_in_two_files_each_get_their_own_law(tmp_path):
    """Walk nodes written in two files may differ in more than their speed (here the touchdown height and the tilt
    law, which specs/a1 sets per node with `nodes`):
    each table is the orbit of its own node's law, so verify finds every table current."""
    import re
    import shutil

    from mpgspec.robots.quadruped.gait.library import _table_on_disk
    from mpgspec.robots.quadruped.setup import trot_inputs

    d = tmp_path / "a1"
    shutil.copytree(A1, d)
    walk = d / "primitives" / "walk.yaml"
    text = walk.read_text()
    every = "  speed: {in_place: 0.0, slow: 0.2, medium: 0.4, fast: 0.6}\n"
    node = "  fast: {controller: {touchdown_height: 0.0007, d_tilt: 60, tilt_accel_limit: 100}}\n"
    assert every in text and node in text
    walk.write_text(text.replace(every, "  speed: {in_place: 0.0, slow: 0.2, medium: 0.4}\n").replace(node, ""))
    fast = re.sub(r"nodes:\n(?:  .*\n)+", "", text.replace(every, "  speed: {fast: 0.6}\n"))
    fast, n = re.subn(r"\n  touchdown_height: 0\.001\n", "\n  touchdown_height: 0.0007\n", fast)
    fast, m = re.subn(r"\n  d_tilt: 50\n  tilt_accel_limit: 40\n", "\n  d_tilt: 60\n  tilt_accel_limit: 100\n", fast)
    assert n == m == 1
    (d / "primitives" / "walk_fast.yaml").write_text(fast)  # the fast node's own file, its settings written out
    project = d / "project.yaml"
    project.write_text(project.read_text().replace("  - primitives/walk.yaml\n",
                                                   "  - primitives/walk.yaml\n  - primitives/walk_fast.yaml\n"))
    gaits = d / "gaits.yaml"  # the walks only: the transients' flows are those committed
    gaits.write_text(gaits.read_text().split("transients:")[0])
    messages = []
    tables = generate(gaits, progress=messages.append)
    # one stride map per law: in place and slow (1 mm), medium (0.7 mm), fast (0.7 mm, its own tilt law)
    assert sum(m.startswith("compiling the stride map") for m in messages) == 3
    spec = load_project(project)
    sys = compile_system(spec)
    for inst in (i for i in spec.primitives if i.base == "Walk"):  # what verify's staleness check compares
        table = next(t for t in tables if t.node == inst.name)
        assert table.inputs == trot_inputs(inst.spec.controller, sys, float(next(iter(inst.argument.values()))))
    ours = {t.node: t.orbit.X for t in tables if hasattr(t, "orbit")}
    committed = {n: _table_on_disk(A1 / "gaits" / f)[1:] for n, f in (("Walk(in_place)", "walk_0.csv"), ("Walk(fast)", "walk_0.6.csv"))}
    for n in committed:  # each its own law: as committed, where the two laws come from one file's `nodes`
        assert np.allclose(ours[n], committed[n], atol=1e-9), n


def test_a_gait_table_outside_the_project_is_refused(tmp_path):
    """`mpgspec gait` writes tables only inside the project folder, and says so before any work."""
    import shutil

    from mpgspec.errors import SpecError

    d = tmp_path / "a1"
    shutil.copytree(A1, d)
    walk = d / "primitives" / "walk.yaml"
    walk.write_text(walk.read_text().replace("  gait: ../gaits/walk_{speed}.csv", "  gait: ../../escaped_{speed}.csv"))
    with pytest.raises(SpecError) as err:
        generate(d / "gaits.yaml", progress=lambda m: None)
    assert err.value.code == "MPG305" and "controller.gait" in err.value.format()
    assert not list(tmp_path.glob("escaped_*"))


@pytest.mark.parametrize("name, spread", [("Walk(in_place)", 0.01), ("Stand", 0.005)])
def test_a_period_map_ends_where_its_steps_end(prims, name, spread):
    """HybridFlow's period map (one loop evaluation per state: h of x_k taken from the loop the step
    from x_k evaluates) gives the last column of its step-by-step period (the fold of the step that
    evaluates h at its end) bit for bit: states, clock and least h, from starts inside and outside C at
    clocks on the dt grid. Stand holds a sampled law: there both are folds of the same held step. Its
    starts spread less: an offset of 0.01 in every state leaves its ID-QP, whose forces keep a friction
    margin and 20 N a foot, no input at one of them (a rollout's law failure, as the oracle reports it)."""
    from mpgspec.certify.hybrid_orbit import HybridFlow

    p = prims[name]
    flow = HybridFlow(p, 0.001, period=p.period or 0.2)
    rng = np.random.default_rng(7)
    xs = np.array(p.setpoint(0.0), float).ravel()
    X0 = xs[:, None] + np.c_[np.zeros(xs.size), spread * rng.standard_normal((xs.size, 3))]
    t0 = np.array([0.0, 0.0, 0.05, 0.117])
    n = X0.shape[1]
    Z = np.vstack([X0, t0[None, :], np.full((1, n), np.inf), np.zeros((flow.hold, n))])
    end = np.array(flow.period_end.map(n)(Z), float)[:X0.shape[0] + 2]  # states, clock, least h
    last = np.stack([flow.states(X0[:, j], t0[j])[:, -1] for j in range(n)], 1)
    assert np.array_equal(end, last)
    hmin = end[-1]
    assert np.isfinite(hmin).all() and (hmin < 0).any() and (hmin >= 0).any()  # both kinds of start


def _leave_c_before_touchdown(p, r: float, m: int, seed: int) -> tuple[int, int]:
    """(starts that leave C within three periods, starts inside C) of m seeded starts on and inside E's
    sphere of radius r at phases in the last 20 ms before the first pair's scheduled touchdown, drawn as
    the floquet verifier draws them (put on the contact manifold of the feet held at their phase)."""
    from mpgspec.certify.hybrid_orbit import orbit
    from verifiers.floquet_hybrid import HybridFlow, inverse_root, sphere_starts

    flow, W = HybridFlow(p, 0.001), np.asarray(p.W)
    Xs = orbit(flow, W)[0]
    X0, k = sphere_starts(p, flow.dt, Xs, W, inverse_root(W), r, m, np.random.default_rng(seed), (160, 180))
    t0 = k * flow.dt
    inside = flow.least_h(X0, t0) >= 0
    XT, hmin, _ = flow.run_until(X0[:, inside], t0[inside], 3)
    return int((~(hmin >= 0) | ~np.isfinite(XT).all(axis=0)).sum()), int(inside.sum())


def test_e_of_a_walk_holds_before_a_touchdown_where_a_radius_sized_over_the_period_does_not(prims):
    """E_Walk(t) is a safe region of attraction where the tube is thinnest, the last 20 ms before a
    touchdown: at the project's radii (0.025, 0.005 in the last 30 ms before a touchdown) no start there leaves
    C; with one radius for every phase, 0.0121 (what a sizing with its starts spread over the whole period
    finds) loses some and 0.025 many (a swing foot below the ground or still up when the touchdown comes)."""
    import dataclasses

    p = prims["Walk(medium)"]
    assert p.radius == 0.025 and float(p.radius_at(0.17)) == pytest.approx(0.005)
    bad, n = _leave_c_before_touchdown(p, p.radius, 160, 1)
    assert n >= 150 and bad == 0, f"{bad} of {n} starts leave C at r(t) = {p.radius}, 0.005 before the touchdown"
    flat = dataclasses.replace(p, narrow=(), narrow_ratio=1.0)  # one radius for every phase
    bad, n = _leave_c_before_touchdown(flat, 0.0121, 160, 1)
    assert bad >= 3, f"{bad} of {n} starts leave C at r = 0.0121"  # 6 of 160 with this seed
    bad, n = _leave_c_before_touchdown(flat, p.radius, 160, 1)
    assert bad >= 0.1 * n, f"{bad} of {n} starts leave C at r = {p.radius}"
