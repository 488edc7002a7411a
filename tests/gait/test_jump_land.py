"""The A1's Jump and Land against physics they must obey: in flight the centre of mass falls at g
and keeps its horizontal velocity, the feet leave the ground at T_t, the takeoff speed follows the
profile, and Land catches the robot from Jump's end and settles it into its E."""
import casadi as ca
import numpy as np
import pytest

from mpgspec.oracle import SafetyOracle

G = 9.81


@pytest.fixture(scope="module")
def a1(a1_project):
    return a1_project


def _com(sys):
    return ca.Function("com", [sys.x], [ca.vertcat(*[sys.extra_env[f"com_{a}"] for a in "xyz"])])


def _flight(prims):
    jump = prims["Jump"]
    sys = jump.system
    t = np.round(np.arange(0.0, 0.25 + 1e-9, 0.001), 6)
    X = np.array([jump.x_star(ti) for ti in t])
    flags = X[:, [sys.state_names.index(f"contact_{f}") for f in sys.model.contact_frames]]
    com = np.array(_com(sys).map(len(t))(X.T)).T
    return jump, sys, t, X, flags, com


def test_the_feet_leave_the_ground_at_the_takeoff_time_and_stay_up(a1):
    _, prims, _ = a1
    jump, sys, t, X, flags, _ = _flight(prims)
    T_t = jump.info["jump"]["takeoff_time"]
    assert (flags[t < T_t] == 1).all()
    takeoff = t[np.argmax(flags.sum(axis=1) == 0)]
    assert T_t <= takeoff <= T_t + 0.005
    clock = X[-1, sys.state_names.index("since_takeoff")]
    assert t[-1] - clock == pytest.approx(takeoff, abs=1e-6)  # the event clock dates it
    feet = ca.Function("z", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_z"] for f in sys.model.contact_frames])])
    assert np.array(feet(X[-1])).min() > 0.1  # tucked, well above the ground near the apex


def test_the_centre_of_mass_is_ballistic_in_flight(a1):
    """With no foot on the ground only gravity acts on the CoM: z'' = -g, x' and y' constant."""
    _, prims, _ = a1
    jump, _, t, _, flags, com = _flight(prims)
    air = np.flatnonzero(flags.sum(axis=1) == 0)[2:-1]
    acc = (com[air + 1] - 2 * com[air] + com[air - 1]) / 0.001**2
    assert acc[:, 2] == pytest.approx(-G, abs=0.02)
    assert np.abs(acc[:, :2]).max() < 0.02
    v = (com[air + 1] - com[air - 1]) / 0.002
    v_t = jump.info["jump"]["takeoff_velocity"]
    # the CoM task lags its profile: about 0.90 m/s of the 1.0 asked for leaves the ground
    assert v[0, 2] == pytest.approx(v_t - G * (t[air[0]] - jump.info["jump"]["takeoff_time"]), rel=0.2)
    apex = com[:, 2].max() - com[air[0], 2]
    assert apex == pytest.approx(v[0, 2] ** 2 / (2 * G), rel=0.05)


@pytest.mark.slow
def test_land_catches_the_jump_and_no_other_primitive_does(a1):
    _, prims, settings = a1
    end = prims["Jump"].x_star(prims["Jump"].domain[1])
    land = SafetyOracle(prims["Land"], settings)(end, 0.0)
    assert land.status == "safe" and 0.3 < land.t_enter < 1.5
    stand = SafetyOracle(prims["Stand"], settings)(end, 0.0)
    assert stand.status == "unsafe" and stand.t_stop == 0.0  # C_ground needs the feet down and still
    assert stand.violated.startswith(("on_ground", "foot_still"))
    standing = SafetyOracle(prims["Land"], settings)(prims["Stand"].x_star(0.0), 0.0)
    assert standing.status == "unsafe" and standing.violated.startswith("airborne")


@pytest.mark.slow
def test_the_landing_asks_at_most_the_laws_limit_with_friction_to_spare(a1):
    """Land's PD is a cushion of bounded torque (controller.limit, 0.8 of the motors' 33.5 N m): from
    Jump's end its flow asks at most that (and reaches it at the touchdown), so a motor 10 % weaker
    still gives what is asked. The stance feet keep at least 5 N inside their friction cones on the
    way into E."""
    from mpgspec.oracle.trace import trace

    spec, prims, settings = a1
    land = prims["Land"]
    inst = next(i for i in spec.primitives if i.name == "Land")
    limit = float(inst.spec.controller.limit)
    assert limit == pytest.approx(0.8 * float(land.system.u_hi.min()))
    end = prims["Jump"].x_star(prims["Jump"].domain[1])
    tr = trace(land, end, 0.0, 1.0, settings, max_points=100_000)
    U = np.array([[np.nan if v is None else v for v in row] for row in tr["u"]])
    assert np.nanmax(np.abs(U)) <= limit + 1e-9 and np.nanmax(np.abs(U)) >= limit - 1e-6  # it does bind
    X = np.array([[np.nan if v is None else v for v in row] for row in tr["x"]])
    k = int(np.argmax(np.nanmax(np.abs(U), axis=0) >= limit - 1e-6))
    raw = np.array(land.loop_raw(X[:, k], tr["t"][k], tr["t"][k], end)[2]).ravel() if land.loop_raw is not None \
        else None
    if raw is not None:  # the raw request (before the actuators' U) is the law's own, bounded too
        assert np.abs(raw).max() <= limit + 1e-9
    cones = [np.array([np.nan if v is None else v for v in vals], float) for n, vals in tr["h"].items()
             if n.startswith("friction_cone")]
    assert len(cones) == 4 and min(np.nanmin(c) for c in cones) >= 5.0
