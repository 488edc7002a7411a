"""The cross-check in MuJoCo: state conventions and the A1's model against pinocchio at random
states, then runs of Lie and Stand replayed under the compiled control laws and compared with
mpgspec's verdicts and rollouts, and a falling body's touchdown with its event clock.

Bounds of the replay tests: the two simulators differ by design in the contact (MuJoCo's soft
contacts on spheres of 0.5 mm, no Baumgarte term) and in the input (held for 1 ms instead of
evaluated at every RK4 stage). What must not differ is the motion: the CoM may part by at most
2 mm (1 % of the 0.17 m the CoM travels when the A1 stands up, and twice the 1 mm that C_ground
grants a foot); measured 0.24 mm. Joints: 0.02 rad (about 1 degree); measured 0.0008 rad.
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

mujoco = pytest.importorskip("mujoco")
pin = pytest.importorskip("pinocchio")

from mpgspec import api  # noqa: E402
from mpgspec.api import compile_project, settings_for  # noqa: E402
from mpgspec.errors import SpecError  # noqa: E402
from mpgspec.execute.crosscheck import CrossCheckSettings, crosscheck_runs  # noqa: E402
from mpgspec.execute.crosscheck.mjcf import build_robot, rpy_quat  # noqa: E402
from mpgspec.execute.crosscheck.replay import held_feet  # noqa: E402
from mpgspec.execute.crosscheck.settings import settings_of  # noqa: E402
from mpgspec.execute.crosscheck.state import StateMap, quat_matrix  # noqa: E402
from mpgspec.execute.sequence import simulate_sequence  # noqa: E402
from mpgspec.report.schema import validate_report  # noqa: E402
from mpgspec.spec.crosscheck import CrossCheck  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from mpgspec.spec.models import GoalCommand, Sequence  # noqa: E402

SPECS = Path(__file__).parents[2] / "specs"
sys.path.insert(0, str(Path(__file__).parents[1]))
from a1_lie import pd_lie as _pd_lie  # noqa: E402
COM_BOUND = 0.002  # m, see the module docstring
JOINT_BOUND = 0.02  # rad


@pytest.fixture(scope="module")
def a1(tmp_path_factory):
    spec = load_project(_project(tmp_path_factory.mktemp("a1")))
    prims = compile_project(spec)
    return prims, settings_for(spec), build_robot(prims["Lie"].system, CrossCheckSettings())


def _free_body() -> tuple[object, StateMap]:
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1' mass='1'/></body></worldbody></mujoco>")
    return model, StateMap(13, 7, 6, True, np.zeros(0, int), np.zeros(0, int), 0, 0, 7, 6)


def test_quaternion_order_and_base_velocity_frame():
    """A base turned 90 degrees about z, moving forward in its own frame, moves along world y."""
    _, sm = _free_body()
    s = np.sqrt(0.5)
    x = np.zeros(13)
    x[3:7] = [0, 0, s, s]  # pinocchio: x, y, z, w
    x[7:10] = [1.0, 0, 0]  # base frame
    x[10:13] = [0, 0, 0.5]  # base frame
    qpos, qvel = sm.to_mujoco(x)
    assert np.allclose(qpos[3:7], [s, 0, 0, s])  # MuJoCo: w, x, y, z
    assert np.allclose(qvel[:3], [0, 1, 0])  # world frame
    assert np.allclose(qvel[3:6], [0, 0, 0.5])  # body frame in both
    assert np.allclose(sm.from_mujoco(qpos, qvel), x)


def test_free_joint_motion_matches_pinocchio():
    """One small step of the same velocity moves a free body alike: MuJoCo's qvel convention (world
    linear, local angular) is what the conversion assumes."""
    model, sm = _free_body()
    ff = pin.Model()
    ff.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    rng = np.random.default_rng(1)
    dt = 1e-6
    for _ in range(20):
        q = pin.randomConfiguration(ff, -np.ones(7), np.ones(7))
        v = rng.normal(size=6)
        x = np.concatenate([q, v])
        qpos, qvel = sm.to_mujoco(x)
        mujoco.mj_integratePos(model, qpos, qvel, dt)
        q_pin = pin.integrate(ff, q, v * dt)
        back = sm.from_mujoco(qpos, qvel)
        assert np.allclose(back[:3], q_pin[:3], atol=1e-11)
        assert np.allclose(back[3:7] * np.sign(back[6] * q_pin[6]), q_pin[3:7], atol=1e-11)


def test_rpy_quaternion_is_urdf_convention():
    r, p, y = 0.3, -0.7, 1.1
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    assert np.allclose(quat_matrix(rpy_quat([r, p, y])), Rz @ Ry @ Rx)


def test_a1_model_matches_pinocchio_at_random_states(a1):
    """Feet positions and velocities, CoM, mass, kinetic energy and gravity forces of MuJoCo's model
    at the converted state equal pinocchio's at random configurations and velocities."""
    prims, _, robot = a1
    system = prims["Lie"].system
    pm = system.model.pin_model
    pd = pm.createData()
    m, d = robot.model, mujoco.MjData(robot.model)
    assert m.body_mass.sum() == pytest.approx(system.model.total_mass, rel=1e-12)
    rng = np.random.default_rng(0)
    vel, Mv = np.zeros(6), np.zeros(m.nv)
    for _ in range(10):
        q = system.model.random_configuration(rng)
        v = rng.normal(size=system.model.nv)
        x = np.concatenate([q, v])
        d.qpos[:], d.qvel[:] = robot.state.to_mujoco(x)
        mujoco.mj_forward(m, d)
        assert np.allclose(robot.state.from_mujoco(d.qpos, d.qvel)[:x.size], x, atol=1e-12)
        pin.forwardKinematics(pm, pd, q, v)
        pin.updateFramePlacements(pm, pd)
        for k, f in enumerate(robot.feet):
            fid = pm.getFrameId(f)
            assert np.allclose(d.site_xpos[robot.foot_sites[k]], pd.oMf[fid].translation, atol=1e-12)
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, robot.foot_sites[k], vel, 0)
            assert np.allclose(vel[3:], pin.getFrameVelocity(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED).linear, atol=1e-10)
        assert np.allclose(d.subtree_com[1], pin.centerOfMass(pm, pd, q), atol=1e-12)
        mujoco.mj_mulM(m, d, Mv, d.qvel)
        Mp = np.triu(pin.crba(pm, pd, q))  # pinocchio fills the upper triangle
        ke_pin = 0.5 * v @ (Mp + np.triu(Mp, 1).T) @ v
        assert 0.5 * d.qvel @ Mv == pytest.approx(ke_pin, rel=1e-9)
        # gravity forces: tau_pin = T' tau_mujoco with qvel = T v (T: R on the base's linear part)
        d.qvel[:] = 0
        mujoco.mj_forward(m, d)
        g_mj = np.zeros(system.model.nv)
        sm = robot.state
        R = quat_matrix(d.qpos[3:7])
        g_mj[:3] = R.T @ d.qfrc_bias[:3]
        g_mj[3:6] = d.qfrc_bias[3:6]
        g_mj[6:] = d.qfrc_bias[sm.dof]
        assert np.allclose(g_mj, pin.computeGeneralizedGravity(pm, pd, q), atol=1e-9)


def test_model_holds_the_spec(a1):
    """Torque limit on every motor, friction on feet and floor, one sphere per foot, no meshes."""
    prims, _, robot = a1
    m = robot.model
    assert np.allclose(m.actuator_ctrlrange, [[-33.5, 33.5]] * 12)
    assert np.allclose(m.actuator_forcerange, [[-33.5, 33.5]] * 12)
    assert np.allclose(m.geom_friction[robot.foot_geoms, 0], 0.6) and m.geom_friction[robot.floor, 0] == 0.6
    assert np.allclose(m.geom_size[robot.foot_geoms, 0], CrossCheckSettings().foot_radius)
    assert m.nmesh == 0
    lo, hi = prims["Lie"].system.model.position_limits
    jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in prims["Lie"].system.model.joint_names]
    assert np.allclose(m.jnt_range[jid], np.column_stack([lo, hi])) and m.jnt_limited[jid].all()
    assert held_feet(prims["Stand"], 0.3) == tuple(robot.feet)


def test_settings_are_checked():
    with pytest.raises(ValueError, match="whole number of timesteps"):
        CrossCheck(control_rate=1000, timestep=3e-4)
    with pytest.raises(ValueError, match="at least twice the timestep"):
        CrossCheck(timestep=1e-4, contact={"timeconst": 1e-4})
    assert CrossCheckSettings.from_spec(CrossCheck(control_rate=500, timestep=5e-4)).substeps == 4


def _project(tmp_path: Path, **keys) -> Path:
    """specs/a1 with Lie and Stand only (no walks to compile), Lie under the paper's joint PD (a
    continuous law beside Stand's sampled ID-QP), no assertions, and `keys` set."""
    dst = tmp_path / "a1"
    shutil.copytree(SPECS / "a1", dst, ignore=shutil.ignore_patterns("gaits*", "walks.yaml"))
    _pd_lie(dst)
    doc = yaml.safe_load((dst / "project.yaml").read_text())
    doc["primitives"] = ["primitives/lie.yaml", "primitives/stand.yaml"]
    for k in ("assertions", "sequence", "crosscheck", "uncertainty"):
        doc.pop(k, None)
    doc.update(keys)
    (dst / "project.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst / "project.yaml"


def test_crosscheck_needs_a_sequence(tmp_path):
    spec = load_project(_project(tmp_path, crosscheck={"simulator": "mujoco"}))
    with pytest.raises(SpecError) as err:
        settings_of(spec)
    assert err.value.code == "MPG108" and err.value.location.line > 0


@pytest.mark.slow
def test_lie_stand_replay_agrees_with_mpgspec(tmp_path):
    """Stand -> Lie -> Stand on the A1, naive and through the graph, verified with a crosscheck block:
    MuJoCo's verdicts match mpgspec's (an assertion of the project), the CoM and joints stay within
    the bounds above, no held foot leaves the floor, and the report holds the cross-check."""
    path = _project(tmp_path, assertions=[{"simulation_safe": "naive"}, {"simulation_safe": "graph"}],
                    sequence={"start": "Stand", "duration": 6.5, "commands": [{"t": 1, "goal": "Lie"},
                                                                             {"t": 4, "goal": "Stand"}]},
                    crosscheck={"simulator": "mujoco", "control_rate": 1000, "require_agreement": True})
    res = api.verify(path, out_dir=tmp_path / "reports")["a1"]
    assert res.status == "pass", [a for a in res.report["assertions"] if a["status"] != "pass"]
    report = json.loads(Path(res.files["json"]).read_text())
    validate_report(report)
    xc = report["crosscheck"]
    assert xc["agree"] and set(xc["runs"]) == {"naive", "graph"}
    naive = xc["runs"]["naive"]
    assert [(s["to"], s["t"]) for s in naive["switches"]] == [("Stand", 0), ("Lie", 1), ("Stand", 4)]
    for run in xc["runs"].values():
        assert run["mujoco"]["safe"] and run["mpgspec"]["safe"]
        assert run["divergence"]["com"]["max"] < COM_BOUND
        assert run["divergence"]["joint"]["max"] < JOINT_BOUND
        assert run["contact"]["lift_off"] is None and run["contact"]["trunk_contact"] is None
        assert all(w["mujoco"] >= 0 for w in run["worst"])
        assert all(s["roa_margin"] is None or np.isfinite(s["roa_margin"]) for s in run["switches"])
        assert run["law_failures"] == {}  # Stand's warm-started ID-QP solves all converge
    assert [a["kind"] for a in report["assertions"]].count("crosscheck") == 2
    html = Path(res.files["html"]).read_text()
    assert 'id="crosscheck"' in html and "Cross-check in MuJoCo" in html and "2 / 2" in html


@pytest.mark.slow
def test_unsafe_switch_fails_alike(tmp_path):
    """Lie -> a stand with the calves stretched past their limit: both simulators leave C first at the
    same joint limit within a few milliseconds, and agree up to there."""
    path = _project(tmp_path)
    tall = yaml.safe_load((path.parent / "primitives" / "lie.yaml").read_text())
    tall["name"] = "StandTall"
    tall["setpoint"]["named"] = {f"{leg}_{j}_joint": q for leg in ("FL", "FR", "RL", "RR")
                                 for j, q in (("thigh", 0.2), ("calf", -0.5))}
    (path.parent / "primitives" / "tall.yaml").write_text(yaml.safe_dump(tall, sort_keys=False))
    doc = yaml.safe_load(path.read_text())
    doc["primitives"].append("primitives/tall.yaml")
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    spec = load_project(path)
    prims, settings = compile_project(spec), settings_for(spec)
    seq = Sequence(start="Lie", duration=2.0, commands=[GoalCommand(t=0.5, goal="StandTall")])
    run = simulate_sequence(prims, None, None, seq, settings, "naive")
    res = crosscheck_runs(prims, {"naive": run}, seq.duration, CrossCheckSettings(runs=("naive",)), settings.h_tolerance)
    r = res.runs["naive"]
    mine, theirs = r["mujoco"]["first_violation"], r["mpgspec"]["first_violation"]
    assert r["agree"] and not r["mujoco"]["safe"] and not r["mpgspec"]["safe"]
    assert mine["h"] == theirs["h"] and mine["primitive"] == theirs["primitive"] == "StandTall"
    assert "calf_joint" in mine["h"] and abs(mine["t"] - theirs["t"]) <= 0.005
    assert r["divergence"]["until"] == pytest.approx(min(mine["t"], theirs["t"]))
    assert r["divergence"]["com_until"] < COM_BOUND and r["divergence"]["joint_until"] < JOINT_BOUND


def test_cli_refuses_a_crosscheck_it_cannot_run(capsys):
    """`mpgspec simulate --crosscheck` on an analytic system: a located spec error before any work."""
    from mpgspec.cli import main

    assert main(["simulate", str(SPECS / "pendulum"), "--crosscheck"]) == 2
    assert "MPG108" in capsys.readouterr().err


class _DictMemo:
    def __init__(self):
        self.d = {}

    def key(self, *parts):
        return repr(parts)

    def get(self, key):
        return self.d.get(key)

    def put(self, key, value):
        self.d[key] = json.loads(json.dumps(value))


def test_comparisons_are_kept_by_content(a1, monkeypatch):
    """A second cross-check of the same run takes the comparison from the memo, replaying nothing."""
    from mpgspec.execute.crosscheck import compare as cmp

    prims, settings, robot = a1
    seq = Sequence(start="Lie", duration=0.05, commands=[GoalCommand(t=0.05, goal="Lie")])
    run = simulate_sequence(prims, None, None, seq, settings, "naive")
    memo, xs = _DictMemo(), CrossCheckSettings(runs=("naive",), settle=0.01)
    first = crosscheck_runs(prims, {"naive": run}, seq.duration, xs, robot=robot, memo=memo)
    assert len(memo.d) == 1 and first.runs["naive"]["mujoco"]["safe"]
    other = crosscheck_runs(prims, {"naive": run}, seq.duration, xs.replace(settle=0.0), robot=robot, memo=memo)
    assert len(memo.d) == 2 and other.runs["naive"]["start_offset"] < 1e-12  # other settings: replayed
    monkeypatch.setattr(cmp, "replay", lambda *a, **k: pytest.fail("replayed again"))
    again = crosscheck_runs(prims, {"naive": run}, seq.duration, xs, robot=robot, memo=memo)
    assert again.runs["naive"]["divergence"] == first.runs["naive"]["divergence"]


def test_a_sampled_law_replays_warm_started_and_held(a1, monkeypatch):
    """Stand's ID-QP in the replay is the oracle's: each solve starts from the previous one's
    solution (cold at switch-in) and its input is held; u is the saturated solve and h that of the
    open loop under it. A solve the compiled solver cannot finish is counted, and the virtual
    machine's last iterate applied."""
    from mpgspec.execute.crosscheck import replay as rp
    from mpgspec.oracle import looplib

    prims, _settings, _robot = a1
    p = prims["Stand"]
    law = rp._Law(p, 1000.0, failures := {})
    x_sw = prims["Lie"].x_star(0.0)
    w, xs = np.zeros(p.sampled.nw), [x_sw + 1e-3 * k * (np.arange(len(x_sw)) >= 7) for k in range(3)]
    for k, x in enumerate(xs):
        hv, u = law(x, 1e-3 * k, 1e-3 * k, x_sw)
        u_raw, w = (np.asarray(v, float).ravel() for v in p.sampled.solve(x, 1e-3 * k, 1e-3 * k, x_sw, w))
        assert np.allclose(u, np.clip(u_raw, p.system.u_lo, p.system.u_hi), atol=1e-9, rtol=0)
        h_ref = np.asarray(p.loop_u(x, 1e-3 * k, 1e-3 * k, x_sw, u_raw)[1], float).ravel()
        act = (h_ref < 1e8) & (hv < 1e8)  # h outside its window is parked at INACTIVE
        assert act.sum() > 10 and np.allclose(hv[act], h_ref[act], atol=1e-9, rtol=1e-9)
    assert failures == {}
    solve, open_loop = looplib.held_law(p)

    def fails(*a):
        raise RuntimeError("no convergence")

    monkeypatch.setitem(p.cache, "looplib_held", (fails, open_loop))
    law = rp._Law(p, 1000.0, failures)
    _hv, u = law(xs[0], 0.0, 0.0, x_sw)
    u_raw = np.asarray(p.sampled.solve(xs[0], 0.0, 0.0, x_sw, np.zeros(p.sampled.nw))[0], float).ravel()
    assert failures == {"Stand": 1} and np.allclose(u, np.clip(u_raw, p.system.u_lo, p.system.u_hi))


def test_runs_replayed_side_by_side_equal_the_runs_replayed_here(a1):
    """Two runs replayed through a pool of two processes (each builds the MuJoCo model itself) give
    the comparisons of the same runs replayed one after the other in this process."""
    from mpgspec.oracle.executors import ProcessPool

    prims, settings, robot = a1
    seq = Sequence(start="Lie", duration=0.05, commands=[GoalCommand(t=0.02, goal="Lie")])
    runs = {m: simulate_sequence(prims, None, None, seq, settings, "naive") for m in ("naive", "graph")}
    xs = CrossCheckSettings(runs=("naive", "graph"), settle=0.01)
    here = crosscheck_runs(prims, runs, seq.duration, xs, robot=robot)
    pool = crosscheck_runs(prims, runs, seq.duration, xs, robot=robot, executor=ProcessPool(2))
    for r in (*here.runs.values(), *pool.runs.values()):
        assert r.pop("wall_s") > 0  # the replay's own time: the one entry that may differ
    assert json.dumps(pool.to_dict(), default=float) == json.dumps(here.to_dict(), default=float)
    assert list(pool.runs) == ["naive", "graph"]


@pytest.mark.slow
def test_falling_body_touches_down_alike(tmp_path):
    """tests/fixtures/falling_body held 0.1 m up by Air (no contacts), then Land while it falls: MuJoCo
    keeps the contact flag and the first-touchdown clock as mpgspec does, both find the first
    touchdown within a control period of the free-fall time, and Land's event-anchored safe set
    (C_aerial before it, C_ground 0.16 s after it) holds in both."""
    dst = tmp_path / "falling_body"
    shutil.copytree(SPECS.parent / "tests" / "fixtures" / "falling_body", dst)
    doc = yaml.safe_load((dst / "project.yaml").read_text())
    land = doc["primitives"][0]
    air = {**land, "name": "Air", "contacts": [], "setpoint": {"named": {"base_z": 0.3}},
           "safe_set": [{"use": "joint_limits"}]}
    doc["primitives"] = [air, land]
    (dst / "project.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    spec = load_project(dst / "project.yaml")
    prims, settings = compile_project(spec), settings_for(spec)
    seq = Sequence(start="Air", duration=0.6, commands=[GoalCommand(t=0.02, goal="Land")])
    run = simulate_sequence(prims, None, None, seq, settings, "naive", max_points=10_000)
    xs = CrossCheckSettings(runs=("naive",), settle=0.0)
    res = crosscheck_runs(prims, {"naive": run}, seq.duration, xs, settings.h_tolerance)
    r = res.runs["naive"]
    assert r["agree"] and r["mujoco"]["safe"] and r["mpgspec"]["safe"], r
    names = prims["Land"].system.state_names
    k_flag, k_tau = names.index("contact_foot"), names.index("since_first_touchdown")
    t_c = np.sqrt(2 * 0.1 / 9.81)
    x_mpg = np.asarray(run.x)
    t = np.asarray(run.t)
    late = t >= 0.3
    assert (x_mpg[late, k_flag] == 1).all()
    touchdown_mpg = float(np.median(t[late] - x_mpg[late, k_tau]))
    # MuJoCo's side, from the replay's own states at the same times
    from mpgspec.execute.crosscheck.mjcf import build_robot as build
    from mpgspec.execute.crosscheck.replay import replay as run_mujoco

    rep = run_mujoco(build(prims["Land"].system, xs), prims, run.switches, seq.duration, xs)
    x_mj = rep.x[np.round(t[late] * 1000).astype(int)]
    assert (x_mj[:, k_flag] == 1).all()
    touchdown_mj = float(np.median(t[late] - x_mj[:, k_tau]))
    assert abs(touchdown_mpg - t_c) <= 0.003 and abs(touchdown_mj - t_c) <= 0.003
    assert abs(touchdown_mj - touchdown_mpg) <= 0.002
    # mpgspec finds the touchdown at the end of an oracle step (2 ms here), the foot up to 1.4 m/s x
    # 2 ms = 2.8 mm in the ground, and its drift correction lifts it out again: twice that at most
    assert r["divergence"]["com"]["max"] < 2 * np.sqrt(2 * 9.81 * 0.1) * settings.dt
    k_z = names.index("base_z")
    assert np.abs(x_mj[:, k_z] - x_mpg[late, k_z]).max() < 5e-4  # and agree again once it stands


def test_the_graph_executor_switches_from_mujocos_state(a1):
    """The graph run's executor on MuJoCo's state: Lie's settled start is inside E_Lie, so when
    Stand is commanded at 0.02 s it switches at that control update to the verified t_B, and the
    report's entry says every goal was reached, 0 s from mpgspec's run."""
    from mpgspec.execute.crosscheck.executor import ExecutorPlan

    prims, settings, robot = a1
    seq = Sequence(start="Lie", duration=0.05, commands=[GoalCommand(t=0.0, goal="Lie"),
                                                         GoalCommand(t=0.02, goal="Stand")])
    table = {"Lie": {"Stand": "Stand", "Lie": None}, "Stand": {"Lie": "Lie", "Stand": None}}
    plan = ExecutorPlan("Lie", ((0.0, "Lie"), (0.02, "Stand")), table,
                        {("Lie", "Stand"): ([0.0], [0.0], [1.0]), ("Stand", "Lie"): ([0.0], [0.0], [1.0])})
    run = simulate_sequence(prims, None, None, seq, settings, "naive")
    xs = CrossCheckSettings(runs=("graph",), settle=0.01)
    res = crosscheck_runs(prims, {"graph": run}, seq.duration, xs, robot=robot, plan=plan)
    e = res.runs["graph"]["executor"]
    assert [(s["from"], s["to"]) for s in e["switches"]] == [(None, "Lie"), ("Lie", "Stand")]
    assert e["switches"][1]["t"] == pytest.approx(0.02) and e["switches"][1]["roa_margin"] > 0
    assert e["safe"] and e["reached_every_goal"] and e["waiting"] is None
    assert [g["arrived"] for g in e["goals"]] == [0.0, pytest.approx(0.02)]
    assert e["largest_lag_s"] == pytest.approx(0.0, abs=1e-9)
    # an executor that cannot enter E waits and says so: E_Lie shrunk to nothing
    tiny = {**prims, "Lie": prims["Lie"].with_radius(1e-12)}
    e2 = crosscheck_runs(tiny, {"graph": run}, seq.duration, xs, robot=robot, plan=plan).runs["graph"]["executor"]
    assert not e2["reached_every_goal"] and e2["waiting"]["primitive"] == "Lie"
    assert e2["waiting"]["best_roa_margin"] < 0 and len(e2["switches"]) == 1
    # ... and one whose switch was checked only from a share of E_Lie the state never comes within
    plan.edges[("Lie", "Stand")] = ([0.0], [0.0], [1e-9])
    e3 = crosscheck_runs(prims, {"graph": run}, seq.duration, xs, robot=robot, plan=plan).runs["graph"]["executor"]
    assert not e3["reached_every_goal"] and e3["waiting"]["primitive"] == "Lie" and len(e3["switches"]) == 1
    assert e3["waiting"]["best_roa_margin"] > 0
