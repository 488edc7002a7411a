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
def test_the_landing_keeps_friction_and_torque_to_spare(a1):
    """From Jump's end Land's stance feet keep at least 5 N inside their friction cones at the nominal mu
    once no_slip applies (the force split has no internal force); its `torque_limit` keeps every joint at
    most 0.8 of the motors' bound, the touchdown's landing speed taken out at that bound for tens of
    milliseconds, and the rest asks little."""
    from mpgspec.oracle.trace import trace

    spec, prims, settings = a1
    land = prims["Land"]
    end = prims["Jump"].x_star(prims["Jump"].domain[1])
    tr = trace(land, end, 0.0, 1.5, settings, max_points=100_000)
    t = np.asarray(tr["t"], float)
    U = np.array([[np.nan if v is None else v for v in row] for row in tr["u"]], float)
    peak = np.nanmax(np.abs(U), axis=0)
    bound, limit = float(land.system.u_hi.min()), float(spec.primitive("Land").spec.controller.torque_limit)
    assert limit <= 0.8 * bound and peak.max() <= limit + 1e-6
    at_limit = t[peak >= limit - 1e-3]  # the landing speed taken out at the limit, only after the touchdown (0.159 s)
    assert at_limit.size and at_limit.min() >= 0.15 and at_limit.max() - at_limit.min() < 0.1
    assert peak[t > 1.0].max() < 0.5 * bound  # at rest on the crouch
    cones = [np.array([np.nan if v is None else v for v in vals], float) for n, vals in tr["h"].items()
             if n.startswith("friction_cone")]
    assert len(cones) == 4 and min(np.nanmin(c) for c in cones) >= 5.0


def test_the_landing_settles_in_e_under_every_corner_of_the_model_error_box(a1):
    """Jump -> Land under the robust stage's parameter box (every link's mass 0.9-1.1, friction 0.4-0.8,
    motors giving 90-110 %): from Jump's end at each corner the flow stays in C_Land and ends inside
    E_Land within Land's domain. Its stiff rest holds the heavy robot on weak motors, where a mass or
    torque error of the nominal model would otherwise move the rest out of E."""
    import itertools

    from mpgspec.robust.rigid import RigidRobustRollout

    spec, prims, settings = a1
    unc = spec.project.uncertainty
    names = list(unc.parameters)
    corners = np.array(list(itertools.product(*[unc.parameters[n].range for n in names])), float)
    land = prims["Land"]
    span = float(land.domain[1] - land.domain[0])
    rr = RigidRobustRollout(land, names, "trunk", False, 1, settings, span, None, False, 0)
    n = len(corners)
    end = prims["Jump"].x_star(prims["Jump"].domain[1])
    Y, last = rr.run(np.tile(end, (n, 1)), np.zeros(n), corners, np.zeros((n, 0, 1)), tol=settings.h_tolerance,
                     until_entry=False)
    for k in range(n):
        lk = int(min(last[k], rr.N))
        assert np.nanmin(Y[k, :-1, :lk + 1]) >= -settings.h_tolerance, corners[k]
        assert Y[k, -1, lk] > 0.01, (corners[k], Y[k, -1, lk])  # inside E_Land (r = 0.05) with room


def test_the_landings_gains_ramp_from_the_touchdowns_after_it(a1):
    """The landing's height and horizontal gains are the touchdown's until the first touchdown and for
    stiffen_after seconds after it, then ramp linearly to the law's over `stiffen` seconds."""
    from mpgspec.compile.events import NEVER
    from mpgspec.robots.quadruped.land import _gains

    spec, prims, _ = a1
    c = next(i for i in spec.primitives if i.name == "Land").spec.controller
    sys = prims["Land"].system
    s = ca.SX.sym("s")
    fn = ca.Function("g", [sys.x, s], [ca.vertcat(*_gains(sys, c, s))])
    x = prims["Land"].x_star(0.0).copy()
    clock = sys.state_names.index("since_first_touchdown")
    start = [c.touchdown.kz, c.touchdown.dz, c.touchdown.kp_xy]
    final = [c.kz, c.dz, c.kp_xy]

    def at(tau, since):
        x[clock] = tau
        return np.array(fn(x, since)).ravel()

    assert at(NEVER, 0.1) == pytest.approx(start)  # in the air
    assert at(c.stiffen_after, 2.0) == pytest.approx(start)
    mid = at(c.stiffen_after + c.stiffen / 2, 2.0)
    assert mid == pytest.approx([(a + b) / 2 for a, b in zip(start, final)])
    assert at(c.stiffen_after + c.stiffen + 0.5, 2.0) == pytest.approx(final)
    assert at(0.2, 0.2) == pytest.approx(start)  # a clock carried from before switch-in is no touchdown here
