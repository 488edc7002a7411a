"""The A1 project end to end: Lie <-> Stand are safe transitions, impossible stands are not, and
long rollouts keep the quaternion, the contacts and the energy in check."""
import shutil
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.oracle.oracle import SafetyOracle
from mpgspec.oracle.trace import trace
from mpgspec.spec.loader import load_project

SPEC = Path(__file__).parents[2] / "specs" / "a1"


def test_setpoints_are_on_the_ground(a1):
    _, prims, _ = a1
    sys = prims["Lie"].system
    feet = ca.Function("feet", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_z"] for f in sys.model.contact_frames])])
    for p in (prims["Lie"], prims["Stand"]):
        z = np.array(feet(p.x_star(0.0))).ravel()
        assert np.allclose(z, 0.0, atol=1e-9)
    assert prims["Stand"].x_star(0)[2] > prims["Lie"].x_star(0)[2] + 0.1


@pytest.mark.slow
def test_lie_to_stand_and_back_are_safe(a1):
    _, prims, settings = a1
    up = SafetyOracle(prims["Stand"], settings)(prims["Lie"].x_star(0.0), 0.0)
    down = SafetyOracle(prims["Lie"], settings)(prims["Stand"].x_star(0.0), 0.0)
    for ev in (up, down):
        assert ev.verdict == 1, ev
        assert ev.reason.value == "entered_E"
        assert 0.5 < ev.t_enter < settings.horizon
        assert max(ev.peak_input) <= 33.5 + 1e-9 or ev.saturated
        assert ev.min_margins["friction_cone[FL_foot]"] >= 0


def _variant(tmp_path, edit):
    dst = tmp_path / "a1"
    shutil.copytree(SPEC, dst)
    edit(dst)
    spec = load_project(dst / "project.yaml")
    return compile_project(spec), settings_for(spec)


def test_unreachable_stand_is_unsafe(tmp_path, pd_lie, a1):
    """Legs stretched past the calf joint limit: the flow must leave C before reaching E."""
    def edit(d):
        lie = pd_lie(d).read_text()  # the joint PD drives the joints to the setpoint's, past the limit
        tall = lie.replace("name: Lie", "name: StandTall").replace("1.25", "0.2").replace("-2.5", "-0.5")
        (d / "primitives" / "lie.yaml").write_text(tall)
        p = (d / "project.yaml").read_text().replace("  - primitives/stand.yaml\n", "").replace("  - primitives/walk.yaml\n", "")
        p = p.replace("  - primitives/jump.yaml\n", "").replace("  - primitives/land.yaml\n", "")
        p = p[: p.index("sequence:")]
        (d / "project.yaml").write_text(p)
    prims, settings = _variant(tmp_path, edit)
    ev = SafetyOracle(prims["StandTall"], settings)(a1[1]["Lie"].x_star(0.0), 0.0)
    assert ev.verdict == 0
    assert ev.reason.value in ("left_C", "horizon_reached")


def test_far_start_is_unsafe(a1):
    """A start tilted 0.6 rad about x with the feet off the ground is outside C_ground at once."""
    _, prims, settings = a1
    x0 = prims["Lie"].x_star(0.0).copy()
    x0[3:7] = [np.sin(0.3), 0, 0, np.cos(0.3)]
    ev = SafetyOracle(prims["Lie"], settings)(x0, 0.0)
    assert ev.verdict == 0 and ev.reason.value == "left_C" and ev.t_stop == 0.0


def test_long_rollout_drift_is_bounded(a1):
    """Five seconds holding Lie: unit quaternion, feet on the ground, energy not growing."""
    _, prims, settings = a1
    lie = prims["Lie"]
    sys = lie.system
    x0 = lie.x_star(0.0)
    x0 = x0 + np.r_[np.zeros(sys.model.nq), 0.05 * np.ones(sys.model.nv), np.zeros(sys.nx - sys.model.nq - sys.model.nv)]  # a small kick
    out = trace(lie, x0, 0.0, 5.0, settings, max_points=100000)
    X = np.array(out["x"], dtype=float)
    quat = X[3:7]
    assert np.abs(np.linalg.norm(quat, axis=0) - 1).max() < 1e-9
    feet = ca.Function("feet", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_z"] for f in sys.model.contact_frames])])
    z = np.array(feet.map(X.shape[1])(X))
    # the kick violates J v = 0; Baumgarte stabilisation keeps the drift small and removes it
    assert np.abs(z).max() < 5e-3
    assert np.abs(z[:, -1]).max() < 1e-6
    M = sys.dyn.M
    v = X[sys.model.nq:sys.model.nq + sys.model.nv]
    ke = np.array([0.5 * v[:, k] @ np.array(M(X[:sys.model.nq, k])) @ v[:, k] for k in range(0, X.shape[1], 50)])
    assert ke[-1] < 1e-6 and ke.max() <= ke[0] * 10 + 1e-3


def test_the_robot_loops_expose_their_guards(a1):
    """Every continuous law of the A1 is stepped piece by piece: each walk's 24 torque limits are
    guards by name (with the contact schedule's and the swing profile's clock guards); the ID-QP of
    Stand and Lie is sampled, held between solves, and has none to locate."""
    from mpgspec.oracle.looplib import guarded

    _, prims, _ = a1
    for name in ("Walk(slow)", "Jump", "Land"):
        g = prims[name].guards
        assert g.exposed and guarded(prims[name]), (name, g.why)
        sat = [n for n in g.names if n.startswith("saturation: ")]
        assert len(sat) == 24 and "saturation: tau_FR_calf_joint at its upper bound 33.5" in sat, (name, g.names)
    walk = prims["Walk(slow)"].guards.fn
    assert walk.n_in() == 4 and len(prims["Walk(slow)"].guards) > 24  # clock guards of the gait too
    for name in ("Stand", "Lie"):
        held = prims[name].guards
        assert not guarded(prims[name]) and len(held) == 0 and held.exposed and "held" in held.why, name
