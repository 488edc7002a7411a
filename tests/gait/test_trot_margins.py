"""The A1 trot's margins by design: swing feet stay above the ground on every walk's orbit, `aerial`
allows no swing foot below it, a switch between speeds asks a bounded horizontal force, a switch in from a
crouch a bounded vertical one, and a swing foot lifts before it is pulled over."""
import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from mpgspec.compile.rigidbody.system import AIRBORNE_TOLERANCE

WALKS = ["Walk(in_place)", "Walk(slow)", "Walk(medium)", "Walk(fast)"]


@pytest.fixture(scope="module")
def prims(a1_project):
    return a1_project[1]


def _feet_z(p):
    sys = p.system
    feet = sys.model.contact_frames
    return feet, ca.Function("feet_z", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_z"] for f in feet])])


@pytest.mark.parametrize("name", WALKS)
def test_swing_feet_stay_above_the_ground_on_the_orbit(prims, name):
    """Every swing foot of x*(t) is above the ground, and half a millisecond before its scheduled
    touchdown still at least 0.2 mm above it (the descent aims above the ground, so a foot that
    runs ahead of its profile does not land early)."""
    p = prims[name]
    feet, fz = _feet_z(p)
    ts = np.arange(0.0, p.period, 5e-4)
    z = np.array([np.asarray(fz(p.x_star(t))).ravel() for t in ts])
    for k, f in enumerate(feet):
        swing = np.array([f not in p.contacts.held(t) for t in ts])
        assert swing.any()
        assert z[swing, k].min() > 0, (f, z[swing, k].min())
        last = np.flatnonzero(swing)  # the sample before each touchdown: the end of each run of swing samples
        ends = last[np.r_[np.diff(last) > 1, True]]
        assert z[ends, k].min() > 2e-4, (f, z[ends, k])


def test_aerial_allows_no_swing_foot_below_the_ground(prims):
    """above_ground of a foot the schedule does not hold is z + 10 um; of a held foot z + 1 mm."""
    p = prims["Walk(slow)"]
    feet, fz = _feet_z(p)
    t = 0.1  # pair B (FR, RL) swings, pair A (FL, RR) stands
    x = np.asarray(p.x_star(t), float).ravel()
    hv = np.asarray(p.h(x, t, 0.0, x), float).ravel()
    z = np.asarray(fz(x)).ravel()
    for k, f in enumerate(feet):
        h = hv[p.h_names.index(f"above_ground[{f}]")]
        allow = 1e-3 if f in p.contacts.held(t) else AIRBORNE_TOLERANCE
        assert h == pytest.approx(z[k] + allow, abs=1e-12)
    assert AIRBORNE_TOLERANCE <= 1e-5


def _ground_force(p, x, t):
    """Total external force on the robot but gravity (N): m a_com - m g, from the closed loop's
    accelerations through pinocchio's centroidal momentum."""
    m = p.system.model
    pm = m.pin_model
    data = pm.createData()
    xdot = np.asarray(p.f_cl(x, t, 0.0, x), float).ravel()
    q, v, a = x[:m.nq], x[m.nq:m.nq + m.nv], xdot[m.nq:m.nq + m.nv]
    dh = pin.computeCentroidalMomentumTimeVariation(pm, data, q, v, a)
    return np.asarray(dh.linear) - pin.computeTotalMass(pm) * pm.gravity.linear


def test_a_switch_between_speeds_asks_a_bounded_horizontal_force(prims):
    """Walk(in_place)'s law from Walk(fast)'s orbit (0.6 m/s too fast, all four feet down) asks the
    ground for m * accel_limit of braking force (2 m/s^2: 27.5 N), not m * kv * 0.6 (82 N)."""
    fast, slow = prims["Walk(fast)"], prims["Walk(in_place)"]
    x = np.asarray(fast.x_star(0.005), float).ravel()
    mass = pin.computeTotalMass(slow.system.model.pin_model)
    F = _ground_force(slow, x, 0.005)
    assert np.hypot(F[0], F[1]) == pytest.approx(mass * 2.0, rel=0.1)
    assert F[0] < 0  # braking
    # on its own orbit the limit does not bind: the force is the orbit's, far below the limit
    y = np.asarray(slow.x_star(0.005), float).ravel()
    assert np.hypot(*_ground_force(slow, y, 0.005)[:2]) < 0.5 * mass * 2.0


def test_a_switch_in_from_a_crouch_asks_a_bounded_vertical_force(prims):
    """Walk(in_place)'s law from Land's rest (its CoM about 6 cm below the walk's h_d, at rest, all four feet
    down) asks the ground for m (g + height_accel_limit) (4 m/s^2), not the m (g + kz e) of its stiff height
    law (kz 2500: over 100 m/s^2): the height error saturates at height_accel_limit / kz."""
    land, walk = prims["Land"], prims["Walk(in_place)"]
    x = np.asarray(land.x_star(land.domain[1]), float).ravel()  # the end of its domain, settled
    mass = pin.computeTotalMass(walk.system.model.pin_model)
    g = 9.81
    F = _ground_force(walk, x, 0.005)
    assert F[2] == pytest.approx(mass * (g + 4.0), rel=0.05)
    # on its own orbit the limit does not bind: the vertical force stays within the limit's band
    y = np.asarray(walk.x_star(0.005), float).ravel()
    assert abs(_ground_force(walk, y, 0.005)[2] - mass * g) < mass * 4.0


def test_a_swing_foot_lifts_before_it_is_pulled_over(prims):
    """Right after lift-off (clock 0.02 + 1 ms) a swing foot of Walk(in_place), started from
    Walk(fast)'s state, is pulled up, not along: its horizontal acceleration is small against its
    vertical one (lift_fraction ramps the horizontal pull in)."""
    fast, walk = prims["Walk(fast)"], prims["Walk(in_place)"]
    t = 0.021
    x = np.asarray(fast.x_star(t), float).ravel()
    m = walk.system.model
    pm = m.pin_model
    data = pm.createData()
    xdot = np.asarray(walk.f_cl(x, t, 0.0, x), float).ravel()
    q, v, a = x[:m.nq], x[m.nq:m.nq + m.nv], xdot[m.nq:m.nq + m.nv]
    pin.forwardKinematics(pm, data, q, v, a)
    pin.updateFramePlacements(pm, data)
    for f in ("FR_foot", "RL_foot"):  # pair B swings first
        fid = pm.getFrameId(f)
        acc = pin.getFrameClassicalAcceleration(pm, data, fid, pin.LOCAL_WORLD_ALIGNED).linear
        assert abs(acc[2]) > 2 * np.hypot(acc[0], acc[1]), (f, acc)


def test_e_narrows_before_each_scheduled_touchdown(a1_project):
    """roa.before_touchdown: E(t) of a walk has the narrow radius in the last `window` seconds before each
    scheduled touchdown (the trot's at 0.18 s and 0.36 s = 0) and roa.radius elsewhere; the RoA margin the
    oracle and the executors read is r(t) - ||x - x*(t)||_W, and a share of E (with_radius) keeps the ratio."""
    import dataclasses

    from mpgspec.compile.primitive import compile_primitive
    from mpgspec.spec.primitive import NarrowE

    spec, prims, _s = a1_project
    walk = prims["Walk(fast)"]
    assert walk.contacts.touchdowns == [0.0, 0.18]
    inst = spec.primitive("Walk(fast)")
    roa = inst.spec.roa.model_copy(update={"radius": 0.025, "before_touchdown": NarrowE(window=0.03, radius=0.006)})
    p = compile_primitive(dataclasses.replace(inst, spec=inst.spec.model_copy(update={"roa": roa})), walk.system)
    assert p.narrow == ((0.15, 0.18), (0.33, 0.36)) and p.narrow_ratio == pytest.approx(0.24)
    for t, r in [(0.01, 0.025), (0.149, 0.025), (0.151, 0.006), (0.179, 0.006), (0.181, 0.025), (0.34, 0.006),
                 (0.37, 0.025), (0.36 + 0.16, 0.006)]:
        assert float(p.roa_margin(walk.x_star(t), t)) == pytest.approx(r, abs=1e-12), t
        assert float(p.radius_at(t)) == pytest.approx(r, abs=1e-12), t
    half = p.with_radius(0.0125)
    assert float(half.radius_at(0.16)) == pytest.approx(0.003) and float(half.radius_at(0.1)) == pytest.approx(0.0125)
    flat = dataclasses.replace(walk, narrow=(), narrow_ratio=1.0).with_radius(0.025)  # one radius for every phase
    assert p.digest() != flat.digest()  # the narrowing is part of what decides a verdict


def test_the_swing_feedforward_path_is_minimum_jerk_pieces():
    """With swing_feedforward the swing path is quintic: each piece's velocity and acceleration are the
    derivatives of its position and velocity, it meets its ends with the asked position and velocity and
    zero acceleration (no step in the feedforward at lift-off, at the apex or at the placement's end)."""
    from mpgspec.robots.quadruped.trot import _smootherstep, quintic_profile

    s = ca.SX.sym("s")
    for T, p0, v0, pf, vf in [(0.08, 0.0, 0.0, 0.07, 0.0), (0.08, 0.07, 0.0, 0.0007, -0.3)]:
        f = ca.Function("q", [s], list(quintic_profile(s, T, p0, v0, pf, vf)))
        for t in np.linspace(0.001, T - 0.001, 9):
            (v_, a_), (pp, vp), (pm, vm) = f(t)[1:], f(t + 1e-6)[:2], f(t - 1e-6)[:2]
            assert float(v_) == pytest.approx(float(pp - pm) / 2e-6, rel=1e-6, abs=1e-9)
            assert float(a_) == pytest.approx(float(vp - vm) / 2e-6, rel=1e-5, abs=1e-6)
        start, end = [np.array([float(v) for v in f(x)]) for x in (0.0, T)]
        assert start == pytest.approx([p0, v0, 0.0], abs=1e-12) and end == pytest.approx([pf, vf, 0.0], abs=1e-9)
        assert [float(v) for v in f(T + 0.01)] == pytest.approx([pf, vf, 0.0])
    g = ca.Function("g", [s], list(_smootherstep(s)))
    for sig in np.linspace(0.01, 0.99, 9):
        (dy, ddy), (yp, dyp), (ym, dym) = g(sig)[1:], g(sig + 1e-6)[:2], g(sig - 1e-6)[:2]
        assert float(dy) == pytest.approx(float(yp - ym) / 2e-6, rel=1e-6, abs=1e-9)
        assert float(ddy) == pytest.approx(float(dyp - dym) / 2e-6, rel=1e-5, abs=1e-6)
    assert [float(v) for v in g(0.0)] == [0.0, 0.0, 0.0] and [float(v) for v in g(1.0)] == [1.0, 0.0, 0.0]


def test_a_sequence_runs_clock_is_its_time(a1_project):
    """A goal-sequence run's time is the time its steps took: Walk(fast) run from its orbit for one
    second (0.5 ms steps, some shortened to the touchdown windows' edges) is on the orbit at the clock
    of each sample's own time, x(t) = x*(c0 + t) (counting a shortened step as a whole one drifted by
    2.5 ms a stride)."""
    from mpgspec.execute.sequence import simulate_sequence
    from mpgspec.spec.project import Sequence

    spec, prims, settings = a1_project
    p = prims["Walk(fast)"]
    seq = Sequence(start="Walk(fast)", commands=[{"t": 0, "goal": "Walk(fast)"}], duration=1.0, dt=0.0005)
    run = simulate_sequence(prims, None, None, seq, settings, "naive")
    assert run.safe and run.t[-1] > 0.99
    W, c0 = np.asarray(p.W), p.start_clock()
    changes = np.r_[0.0, p.contacts.boundaries]  # lift-offs and touchdowns: x*(t) is a table across them

    def off(t, x):
        e = np.asarray(x) - p.x_star(c0 + t)
        return float(np.sqrt(e @ W @ e))

    far = [(t, x) for t, x in zip(run.t, run.x) if np.abs((c0 + t) % p.period - changes).min() > 2e-3]
    assert len(far) > 1500
    worst = max(off(t, x) for t, x in far)
    assert worst < 0.01, worst  # 0.64 when a shortened step counted as a whole one


def test_the_tilt_limit_bounds_the_levelling_acceleration(prims):
    """tilt_accel_limit scales the roll and pitch acceleration the tilt PD asks down to its norm, direction kept,
    and leaves yaw damping and a request within the limit as they were."""
    from mpgspec.robots.quadruped.stance import level_trunk_moment, trunk

    sys = prims["Walk(slow)"].system
    tk = trunk(sys)
    inertia = np.diag([0.02, 0.06, 0.07])
    free = level_trunk_moment(tk, inertia, 300.0, 50.0, 10.0)
    capped = level_trunk_moment(tk, inertia, 300.0, 50.0, 10.0, tilt_limit=40.0)
    I_G = ca.mtimes([tk.Ryaw, ca.DM(inertia), tk.Ryaw.T])
    accel = ca.Function("accel", [sys.x], [ca.solve(I_G, free), ca.solve(I_G, capped)])
    x = np.asarray(prims["Walk(slow)"].x_star(0.1), float).ravel()
    a_free, a_cap = (np.asarray(a).ravel() for a in accel(x))
    assert np.linalg.norm(a_free[:2]) < 40.0  # on the orbit: within the limit, unchanged
    np.testing.assert_allclose(a_cap, a_free, atol=1e-9)
    m = sys.model
    kicked = x.copy()
    kicked[m.nq + 3:m.nq + 5] += [2.0, -1.5]  # roll and pitch rates of a hard landing
    a_free, a_cap = (np.asarray(a).ravel() for a in accel(kicked))
    assert np.linalg.norm(a_free[:2]) > 100.0
    assert np.linalg.norm(a_cap[:2]) == pytest.approx(40.0, rel=1e-6)
    np.testing.assert_allclose(a_cap[:2] / 40.0, a_free[:2] / np.linalg.norm(a_free[:2]), atol=1e-9)
    assert a_cap[2] == pytest.approx(a_free[2], abs=1e-9)  # yaw damping untouched
