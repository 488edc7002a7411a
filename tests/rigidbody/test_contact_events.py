"""Contact events on the A1: a drop from the air touches down (plastic impact), then stands."""
import shutil
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.oracle.trace import trace
from mpgspec.spec.loader import load_project

SPEC = Path(__file__).parents[2] / "specs" / "a1"


@pytest.fixture(scope="module")
def drop_spec(tmp_path_factory, pd_lie):
    d = tmp_path_factory.mktemp("drop") / "a1"
    shutil.copytree(SPEC, d)
    pd_lie(d)  # a falling body under the joint PD
    p = (d / "project.yaml").read_text()
    p = p.replace("  - primitives/stand.yaml\n", "").replace("  - primitives/walk.yaml\n", "")
    p = p.replace("  - primitives/jump.yaml\n", "").replace("  - primitives/land.yaml\n", "")
    p = p[: p.index("sequence:")]  # the goal sequence and assertions name the primitives left out
    (d / "project.yaml").write_text(p)
    lie = (d / "primitives" / "lie.yaml").read_text()
    lie = lie.replace("name: Lie", "name: Fall").replace("  feet_on_ground: true\n", "")
    lie = lie.replace("  named: &lie\n", "  named: &lie\n    base_z: 0.16\n")
    lie = lie.replace("  profile: {duration: 1.0}\n", "")
    lie = lie.replace("roa:\n", "contacts: []\nroa:\n")
    lie = lie.replace("0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1]",
                      "0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0,0,0,0, 0,0]")
    lie = lie.replace("  - use: quadruped_ground\n", "  - use: joint_limits\n  - use: aerial\n")
    (d / "primitives" / "lie.yaml").write_text(lie)
    return load_project(d / "project.yaml")


@pytest.fixture(scope="module")
def drop(drop_spec):
    return compile_project(drop_spec)["Fall"], settings_for(drop_spec)


def test_drop_touches_down_with_an_impact(drop):
    fall, settings = drop
    sys = fall.system
    m = sys.model
    x0 = fall.x_star(0.0)
    flags = [sys.state_names.index(f"contact_{f}") for f in m.contact_frames]
    assert np.all(x0[flags] == 0) and x0[2] == pytest.approx(0.16)
    out = trace(fall, x0, 0.0, 1.0, settings, max_points=100000)
    X = np.array(out["x"], dtype=float)
    t = np.array(out["t"])
    c = X[flags]
    assert np.all(c[:, -1] == 1), "all four feet end in contact"
    feet = ca.Function("feet", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_{k}"] for f in m.contact_frames
                                                       for k in ("z", "vz")])])
    F = np.array(feet.map(X.shape[1])(X))
    k = int(np.argmax(c[0] > 0.5))  # first touchdown of FL
    # free fall until then: z0 - g t^2 / 2 reaches the foot height at about sqrt(2 h / g)
    assert 0.05 < t[k] < 0.3
    assert F[1, k - 1] < -0.3  # falling fast just before
    assert abs(F[1, k]) < 1e-6  # the plastic impact stops the foot
    assert np.all(np.abs(F[0::2, -1]) < 1e-4)  # resting on the ground
    M = sys.dyn.M
    nq, nv = m.nq, m.nv
    ke = lambda j: 0.5 * X[nq:nq + nv, j] @ np.array(M(X[:nq, j])) @ X[nq:nq + nv, j]  # noqa: E731
    assert ke(k) < ke(k - 1)  # the impact dissipates energy
    aerial = [i for i, n in enumerate(fall.h_names) if n.startswith("above_ground")]
    H = np.array([out["h"][fall.h_names[i]] for i in aerial], dtype=float)
    assert np.nanmin(H) > -2e-3


def test_contact_schedule_sets_the_flags_by_the_clock(tmp_path, pd_lie):
    """Diagonal pair lifted on [0.2, 0.4): the flags follow the clock, and rejoining feet are stopped."""
    d = tmp_path / "a1"
    shutil.copytree(SPEC, d)
    pd_lie(d)  # the joint PD holds every leg where it is, lifted or not
    p = (d / "project.yaml").read_text()
    p = p.replace("  - primitives/stand.yaml\n", "").replace("  - primitives/walk.yaml\n", "")
    p = p.replace("  - primitives/jump.yaml\n", "").replace("  - primitives/land.yaml\n", "")
    (d / "project.yaml").write_text(p[: p.index("sequence:")])
    lie = (d / "primitives" / "lie.yaml").read_text()
    lie = lie.replace("roa:\n", "contact_schedule:\n  - {until: 0.2, feet: [FL_foot, FR_foot, RL_foot, RR_foot]}\n"
                      "  - {until: 0.4, feet: [FL_foot, RR_foot]}\n"
                      "  - {until: 9.0, feet: [FL_foot, FR_foot, RL_foot, RR_foot]}\nroa:\n")
    lie = lie.replace("0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1]",
                      "0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0.1,0.1,0.1, 0,0,0,0, 0,0]")
    (d / "primitives" / "lie.yaml").write_text(lie)
    spec = load_project(d / "project.yaml")
    lie_p = compile_project(spec)["Lie"]
    sys = lie_p.system
    m = sys.model
    flags = [sys.state_names.index(f"contact_{f}") for f in m.contact_frames]
    x0 = lie_p.x_star(0.0)
    assert np.all(x0[flags] == 1)
    out = trace(lie_p, x0, 0.0, 0.6, settings_for(spec), max_points=100000)
    X = np.array(out["x"], dtype=float)
    t = np.array(out["t"])
    c = X[flags]
    lifted = (t > 0.2 + 1e-6) & (t < 0.4 - 1e-6)
    assert np.all(c[[0, 3]] == 1)
    assert np.all(c[[1, 2]][:, lifted] == 0) and np.all(c[[1, 2]][:, t < 0.2 - 1e-6] == 1)
    assert np.all(c[[1, 2]][:, t > 0.4 + 1e-6] == 1)
    feet_v = ca.Function("v", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_v{a}"] for f in ("FR_foot", "RL_foot")
                                                     for a in "xyz"])])
    k = int(np.argmax((t > 0.3) & (c[1] == 1)))  # the first state after the feet rejoined
    assert t[k] == pytest.approx(0.4, abs=1.5e-3)
    assert np.abs(np.array(feet_v(X[:, k]))).max() < 1e-6  # the impact stopped the rejoining feet
    assert np.abs(np.array(feet_v(X[:, k - 1]))).max() > 1e-3  # they were moving just before


def test_a_backend_without_jump_maps_refuses_the_hybrid_drop(drop, drop_spec):
    """scipy has no discrete part: it must refuse contact events by name, not fall through the ground."""
    from mpgspec.api import build
    from mpgspec.errors import SpecError
    from mpgspec.oracle import SafetyOracle
    from mpgspec.oracle.oracle import CapabilityError

    fall, settings = drop
    with pytest.raises(CapabilityError, match="lacks the capability hybrid"):
        SafetyOracle(fall, settings.replace(method="scipy"))
    e = SafetyOracle(fall, settings)(fall.x_star(0.0), 0.0)  # rk4 applies the impacts
    assert e.status in ("safe", "unsafe", "inconclusive") and e.reason.value != "error"
    with pytest.raises(SpecError) as err:
        build(drop_spec, settings.replace(method="scipy"))
    assert err.value.code == "MPG120" and "oracle.method" in err.value.format()


def test_the_static_torque_on_two_feet_carries_no_rounding_noise(drop):
    """With one or two feet in contact the base's rows of static_torque's normal equations are
    rank-deficient (no turn about the line through two point contacts is resisted): a 1e-9 ridge
    amplified rounding into about 4e-5 N m of torque noise under a state change of 1e-16, enough
    for an input-saturation guard at its bound to chatter. With three or more feet the solve is
    well posed and keeps its ridge of 1e-9."""
    from mpgspec.compile.rigidbody import system as rs

    prim, _s = drop
    sys_ = prim.system
    names = sys_.state_names
    feet = tuple(sys_.model.contact_frames)
    u = ca.Function("u", [sys_.x], [sys_.static_torque(feet)])
    x = np.asarray(prim.x_star(0.0), float).ravel().copy()
    rng = np.random.default_rng(3)
    for held in (feet[2:], feet):
        for f in feet:
            x[names.index(f"contact_{f}")] = float(f in held)
        u0 = np.asarray(u(x)).ravel()
        bump = np.zeros_like(x)
        bump[:sys_.model.nq] = 1e-16 * rng.standard_normal(sys_.model.nq)
        noise = max(np.abs(np.asarray(u(x + k * bump)).ravel() - u0).max() for k in (1, 2, 3))
        assert np.isfinite(u0).all() and np.abs(u0).max() > 1.0, (held, u0)
        assert noise < 1e-6, (held, noise)
    assert rs.RIDGE == 1e-9 and rs.FEW_FEET_RIDGE > rs.RIDGE
