"""Robust edges of a rigid body (the A1's Lie and Stand): mass scale, friction, a push on the trunk."""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from mpgspec import api
from mpgspec.compile.rigidbody.system import no_slip
from mpgspec.errors import SpecErrors
from mpgspec.spec.uncertainty_refs import check_uncertainty, check_uncertainty_compiled
from mpgspec.robust.graph import robust_stage
from mpgspec.robust.rigid import RigidRobustRollout, no_slip_rows
from mpgspec.robust.rollout import judge
from mpgspec.spec.loader import load_project

A1 = Path(__file__).resolve().parents[2] / "specs" / "a1"
PEND = Path(__file__).resolve().parents[2] / "specs" / "pendulum"


def _lie_stand(spec):
    """The A1 with Lie and Stand only: the robust graph's assertions among them, constant pushes, no
    sequence runs."""
    unc = spec.project.uncertainty
    keep = [a for a in unc.assertions if _names(a) <= {"Lie", "Stand"}]
    unc = unc.model_copy(update={"assertions": keep, "search": 0, "runs": 0})
    return dataclasses.replace(spec, primitives=[p for p in spec.primitives if p.name in ("Lie", "Stand")],
                               project=spec.project.model_copy(update={"uncertainty": unc}))


def _names(assertion) -> set[str]:
    from mpgspec.spec.project import node_refs

    return {name for name, _ in node_refs(assertion) or ()}


@pytest.fixture(scope="module")
def built():
    spec = _lie_stand(load_project(A1 / "project.yaml"))
    return api.build(spec, api.settings_for(spec))


@pytest.fixture(scope="module")
def system(built):
    return built[0].prims["Stand"].system


def _random_state(sys, rng):
    m = sys.model
    q = m.random_configuration(rng)
    v = rng.normal(size=m.nv)
    return q, v, np.concatenate([q, v, sys.default_state()[m.nq + m.nv:]])  # flags and event clocks


def _flags(sys, x, on: bool):
    """x with every contact flag set (on) or cleared: the A1's plant holds the flagged feet."""
    m = sys.model
    y = np.array(x, float)
    y[m.nq + m.nv:m.nq + m.nv + len(m.contact_frames)] = 1.0 if on else 0.0
    return y


def _scaled(model: pin.Model, k: float) -> pin.Model:
    mk = model.copy()
    for i in range(1, mk.njoints):
        y = mk.inertias[i]
        mk.inertias[i] = pin.Inertia(k * y.mass, y.lever, k * y.inertia)
    return mk


def test_mass_scale_is_the_nominal_dynamics_under_tau_over_k(system):
    rng = np.random.default_rng(3)
    m = system.model
    model, k = m.pin_model, 1.07
    mk = _scaled(model, k)
    q, v, x = _random_state(system, rng)
    u = rng.normal(size=m.nu) * 5
    tau = m.actuation_matrix @ u
    a_scaled = pin.aba(mk, mk.createData(), q, v, tau)
    assert np.allclose(a_scaled, pin.aba(model, model.createData(), q, v, tau / k), atol=1e-9)
    plant = system.uncertain_plant((), "trunk")
    xdot = np.array(plant(_flags(system, x, False), u, k, np.zeros(3), 0.0)[0]).ravel()
    assert np.allclose(xdot[m.nq:m.nq + m.nv], a_scaled, atol=1e-8)
    held = _flags(system, x, True)  # ground forces scale with k
    lam_k = plant(held, u, k, np.zeros(3), 0.0)[1]
    lam_1 = plant(held, u / k, 1.0, np.zeros(3), 0.0)[1]
    assert np.allclose(np.array(lam_k), k * np.array(lam_1), atol=1e-8)


def test_push_changes_the_base_acceleration_by_its_generalized_force(system):
    rng = np.random.default_rng(5)
    m = system.model
    model, data = m.pin_model, m.pin_model.createData()
    q, v, x = _random_state(system, rng)
    u, F = rng.normal(size=m.nu), np.array([20.0, -12.0, 5.0])
    plant, x = system.uncertain_plant((), "trunk"), _flags(system, x, False)

    def aerial(*a):
        return plant(*a, 0.0)

    da = (np.array(aerial(x, u, 1.0, F)[0]) - np.array(aerial(x, u, 1.0, np.zeros(3))[0])).ravel()[m.nq:m.nq + m.nv]
    R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
    fext = [pin.Force.Zero() for _ in range(model.njoints)]
    p = m.frame("trunk").translation
    fext[1] = pin.Force(R.T @ F, np.cross(p, R.T @ F))  # at the trunk, in the base joint's frame
    tau = m.actuation_matrix @ u
    ref = pin.aba(model, data, q, v, tau, fext) - pin.aba(model, data, q, v, tau)
    assert np.allclose(da, ref, atol=1e-9)
    pin.centerOfMass(model, data, q, np.zeros(m.nv), da)  # the centre of mass accelerates by F / m
    assert np.allclose(data.acom[0] * m.total_mass, F, atol=1e-8)
    a_k = (np.array(aerial(x, u, 1.1, F)[0]) - np.array(aerial(x, u, 1.1, np.zeros(3))[0])).ravel()[m.nq:m.nq + m.nv]
    assert np.allclose(a_k, da / 1.1, atol=1e-9)  # a heavier robot is pushed less


def test_friction_reaches_the_cone_function_with_the_plants_ground_forces(built):
    cp, vg = built
    stand, lie = cp.prims["Stand"], cp.prims["Lie"]
    rr = RigidRobustRollout(stand, ["mass_scale", "friction"], "trunk", True, 4, cp.settings, 2.5, 0.2)
    x0 = lie.x_star(0.0)
    rows = no_slip_rows(stand)
    assert sorted(k for _, k in rows.values()) == [0] * 4 + [1] * 4
    F = np.array([7.5, -7.5, 0.0])
    y = {mu: np.array(rr.first(x0, 0.0, 0.0, [1.1, mu], np.tile(F[:, None], (1, 4)))).ravel() for mu in (0.4, 0.8)}
    sys = stand.system
    u = np.clip(y[0.4][rr.nh + 2:rr.nh + 2 + sys.nu], sys.u_lo, sys.u_hi)  # after [h; margin; c]: the held input
    lam = np.array(rr.plant_fn(x0, u, 1.1, F, 0.0)[1]).ravel()
    for j, (foot, kind) in rows.items():
        fx, fy, fz = lam[3 * foot:3 * foot + 3]
        for mu in (0.4, 0.8):
            assert y[mu][j] == pytest.approx(float(no_slip(fx, fy, fz, mu)[kind]), abs=1e-9)
        assert y[0.8][j] - y[0.4][j] == pytest.approx(0.4 * fz if kind else 0.0, abs=1e-9)
    others = [j for j in range(len(stand.h_names)) if j not in rows]
    assert np.allclose(y[0.4][others], y[0.8][others])
    # the nominal scenario is the oracle's rollout
    Y, last = rr.run(x0[None], np.zeros(1), np.array([[1.0, 0.6]]), np.zeros((1, 3, 4)))
    ok, margin, k = judge(Y[0, :-1], Y[0, -1], int(last[0]), 0.0)
    ev = vg.graph.edge("Lie", "Stand").evidence[0][0]
    assert ok and ev.verdict == 1 and k * cp.settings.dt == pytest.approx(ev.t_enter, abs=0.01)


def test_torque_scale_with_the_same_mass_scale_is_the_nominal_flow(built):
    """k M a + k H = k u + J^T (k lam): every link k times heavier and every actuator delivering k
    times its command is the nominal flow, ground forces k times the nominal ones; the torque error
    alone is not."""
    cp, _ = built
    stand, lie = cp.prims["Stand"], cp.prims["Lie"]
    rr = RigidRobustRollout(stand, ["mass_scale", "friction", "torque_scale"], "trunk", False, 1, cp.settings, 1.0)
    k = 1.08
    TH = np.array([[1.0, 0.6, 1.0], [k, 0.6, k], [1.0, 0.6, k]])
    X0 = np.tile(lie.x_star(0.0), (3, 1))
    Y, last = rr.run(X0, np.zeros(3), TH, np.zeros((3, 0, 1)), np.full(3, rr.N), tol=1e9, until_entry=False)
    assert (last == rr.N).all()
    rows = no_slip_rows(stand)
    others = [j for j in range(rr.nh) if j not in rows] + [rr.nh]  # every other h and the RoA margin
    np.testing.assert_allclose(Y[1, others], Y[0, others], rtol=0, atol=1e-7)
    slip = sorted(rows)
    np.testing.assert_allclose(Y[1, slip], k * Y[0, slip], rtol=1e-6, atol=1e-7)
    assert np.abs(Y[2, others] - Y[0, others]).max() > 1e-3  # 8 % more torque alone moves the flow


def test_a_velocity_error_moves_what_the_law_reads_not_the_plant(built):
    """The law reads the base's linear velocity with the error added: Stand's ID-QP solved from x0
    with the error is the one solved from the state shifted by it, while h and the RoA margin are
    judged on the true state; an error of 0 is the rollout without the parameter."""
    cp, _ = built
    stand, lie = cp.prims["Stand"], cp.prims["Lie"]
    names = ["mass_scale", "friction", "velocity_error_x", "velocity_error_y"]
    rr = RigidRobustRollout(stand, names, "trunk", False, 1, cp.settings, 1.0)
    plain = RigidRobustRollout(stand, names[:2], "trunk", False, 1, cp.settings, 1.0)
    sys = stand.system
    x0 = lie.x_star(0.0)
    vx = sys.model.nq  # the base's linear velocity x in the state
    shifted = x0.copy()
    shifted[vx] += 0.05
    shifted[vx + 1] -= 0.02

    def first(r, x, th):
        y = np.array(r.first(x, 0.0, 0.0, th, np.zeros((0, 1)))).ravel()
        return y[: r.nh + 1], y[r.nh + 2: r.nh + 2 + sys.nu]  # [h; margin], the held input

    (hm_err, u_err), (hm_shift, u_shift) = first(rr, x0, [1, 0.6, 0.05, -0.02]), first(rr, shifted, [1, 0.6, 0, 0])
    hm_true, u_true = first(plain, x0, [1, 0.6])
    np.testing.assert_allclose(u_err, u_shift, rtol=0, atol=1e-9)
    assert np.abs(u_err - u_true).max() > 1e-3  # the ID-QP damps the velocity it reads
    assert hm_err[-1] == pytest.approx(hm_true[-1], abs=1e-12) and hm_shift[-1] != pytest.approx(hm_true[-1], abs=1e-6)
    X0 = np.tile(x0, (3, 1))
    TH = np.array([[1, 0.6, 0, 0], [1, 0.6, 0.05, 0], [1, 0.6, -0.05, 0]])
    Y, last = rr.run(X0, np.zeros(3), TH, np.zeros((3, 0, 1)), np.full(3, rr.N), tol=1e9, until_entry=False)
    Y0, _ = plain.run(x0[None], np.zeros(1), np.array([[1, 0.6]]), np.zeros((1, 0, 1)), np.full(1, plain.N), tol=1e9,
                      until_entry=False)
    np.testing.assert_allclose(Y[0], Y0[0], rtol=0, atol=1e-9)
    assert np.abs(Y[1] - Y[0]).max() > 1e-3 and np.abs(Y[2] - Y[0]).max() > 1e-3


@pytest.mark.parametrize("target", ["Lie", "Stand"])  # the paper's joint PD (a continuous law) and a sampled ID-QP
def test_latency_queues_the_laws_requests_and_the_plant_receives_the_oldest(built, a1_pd_lie, target):
    """With a latency of 2 steps the hold ends with the two requests not yet applied: at switch-in the
    law's request there, twice; each step appends the request at its start (the sampled law: the
    input it holds) and applies the queue's head, held over the step."""
    cp, _ = built
    prim = a1_pd_lie[1]["Lie"] if target == "Lie" else cp.prims[target]
    sys = prim.system
    source = cp.prims["Stand" if target == "Lie" else "Lie"]
    names = ["mass_scale", "friction"]
    rr = RigidRobustRollout(prim, names, "trunk", False, 1, cp.settings, 1.0, latency=2)
    plain = RigidRobustRollout(prim, names, "trunk", False, 1, cp.settings, 1.0)
    assert rr.nhold == plain.nhold + 2 * sys.nu
    x0, th = source.x_star(0.0), [1.0, 0.6]
    nl = plain.nhold

    def asked(x, t, s, hold):  # the request at a state: the sampled law's held input, else k(x)
        if prim.sampled is not None:
            return np.array(hold[1:1 + sys.nu]).ravel()
        return np.array(prim.control(x, t, s, x0)[0]).ravel()

    _, hold0 = rr._first(x0, 0.0, 0.0, th, np.zeros(0))
    hold0 = np.array(hold0).ravel()
    u0 = asked(x0, 0.0, 0.0, hold0)
    np.testing.assert_allclose(hold0[nl:], np.concatenate([u0, u0]), rtol=0, atol=1e-12)
    z = np.concatenate([x0, [0.0, 0.0], x0, th, hold0])
    nx = sys.nx
    for k in range(3):
        before = z
        z = np.array(rr._step(z, np.zeros(0))[0]).ravel()
        q_before, q_after = before[2 * nx + 4 + nl:], z[2 * nx + 4 + nl:]
        request = asked(before[:nx], before[nx], before[nx + 1], before[2 * nx + 4:])
        np.testing.assert_allclose(q_after, np.concatenate([q_before[sys.nu:], request]), rtol=0, atol=1e-9)
    # the plant's flow differs from the one without latency
    Y, _ = rr.run(x0[None], np.zeros(1), np.array([th]), np.zeros((1, 0, 1)), np.full(1, rr.N), tol=1e9,
                  until_entry=False)
    Y0, _ = plain.run(x0[None], np.zeros(1), np.array([th]), np.zeros((1, 0, 1)), np.full(1, plain.N), tol=1e9,
                      until_entry=False)
    assert np.abs(Y - Y0).max() > 1e-4


def test_the_robust_stage_runs_lie_and_stand_with_one_step_of_latency(built):
    """The stage takes the latency from the spec to every target's rollouts and reports it: the ID-QP
    of Lie and Stand withstands one step of delay on the nominal plant (worst margin the feet's 1 mm
    contact tolerance), as on the whole A1 (README)."""
    cp, vg = built
    unc = cp.spec.project.uncertainty.model_copy(update={
        "latency": 0.001, "parameters": {}, "disturbance": None, "cells": 2, "runs": 0, "assertions": []})
    spec = dataclasses.replace(cp.spec, project=cp.spec.project.model_copy(update={"uncertainty": unc}))
    from mpgspec.robust.graph import target_jobs

    _, jobs = target_jobs(spec, cp.prims, cp.settings, vg.graph)
    assert jobs and {job.rollout.latency for job in jobs} == {1}  # whole oracle steps (dt = 1 ms)
    d = robust_stage(dataclasses.replace(cp, spec=spec), vg).to_dict()
    assert d["scenarios"]["latency"] == 0.001 and d["scenarios"]["per_cell"] == 1
    edges = {(e["from"], e["to"]): e for e in d["edges"]}
    assert set(edges) == {("Lie", "Stand"), ("Stand", "Lie")}
    for e in edges.values():
        assert e["survives"] and e["worst_margin"] == pytest.approx(0.001, abs=1e-6), e


@pytest.mark.parametrize("latency, found", [(0.0015, "1.5 steps"), (0.0005, "0.5 steps")])
def test_a_latency_that_is_not_whole_steps_is_a_located_spec_error(tmp_path, latency, found):
    path = _a1_with(tmp_path, BASE + f"  latency: {latency}\n  parameters: {{friction: {{range: [0.4, 0.8]}}}}\n")
    with pytest.raises(SpecErrors) as ei:
        check_uncertainty(load_project(path))
    err = ei.value.errors[0]
    assert err.code == "MPG104" and err.key == "uncertainty.latency" and err.location.line > 0 and found in err.found


def test_a_velocity_error_on_a_fixed_base_is_a_located_spec_error(tmp_path):
    import yaml

    path = _a1_with(tmp_path, BASE + "  parameters: {velocity_error_x: {range: [-0.05, 0.05]}}\n")
    doc = yaml.safe_load(path.read_text())
    doc["system"]["floating_base"] = False
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(SpecErrors) as ei:
        check_uncertainty(load_project(path))
    err = ei.value.errors[0]
    assert err.code == "MPG108" and err.key == "uncertainty.parameters.velocity_error_x" and err.location.line > 0
    assert "fixed" in err.message


def test_a1_robust_lie_stand_reports_worst_cases(built):
    rob = robust_stage(*built)
    d = rob.to_dict()
    edges = {(e["from"], e["to"]): e for e in d["edges"]}
    assert set(edges) == {("Lie", "Stand"), ("Stand", "Lie")} and d["scenarios"]["nodes"] == ["Lie", "Stand"]
    up, down = edges[("Lie", "Stand")], edges[("Stand", "Lie")]
    # the ID-QP's stiff height and profiled posture hold both rests over the box: every scenario ends in E
    # (the earlier Stand gains, and Lie's joint PD, settled outside it with the mass 10 % off); the feet's
    # 1 mm tolerance binds
    for e in (up, down):
        assert e["survives"] and e["worst_margin"] == pytest.approx(0.001, abs=2e-5), e
        assert (e["worst_case"]["binding"]["h"] or "").startswith("foot_still"), e
        assert max(abs(v) for v in e["worst_case"]["disturbance"]["force_x"]) <= 7.5
    assert d["scenarios"]["disturbance"]["force"] == {"frame": "trunk", "bound": [7.5, 7.5, 0.0], "duration": 0.2}
    assert all(a.status == "pass" for a in rob.assertions), [a.message for a in rob.assertions]
    assert set(rob.graph.nodes) == {"Lie", "Stand"} and rob.graph.edge("Stand", "Lie") is not None
    assert rob.graph.edge("Lie", "Stand") is not None


def _a1_with(tmp_path: Path, block: str) -> Path:
    dst = tmp_path / "a1"
    shutil.copytree(A1, dst)
    text = (dst / "project.yaml").read_text()
    (dst / "project.yaml").write_text(text[: text.index("\nuncertainty:")] + "\n" + block)
    return dst / "project.yaml"


BASE = "uncertainty:\n  nodes: [Lie, Stand]\n  search: 0\n  runs: 0\n"


@pytest.mark.parametrize("block, key, hint", [
    (BASE + "  parameters: {mass_scal: {range: [0.9, 1.1]}}\n", "uncertainty.parameters.mass_scal",
     "did you mean 'mass_scale'"),
    (BASE + "  parameters: {friction: {nominal: 0.5, range: [0.4, 0.8]}}\n", "uncertainty.parameters.friction.nominal",
     ""),
    (BASE + "  parameters: {mass_scale: {range: [1.05, 1.1]}}\n", "uncertainty.parameters.mass_scale.range", ""),
    ("uncertainty:\n  nodes: [Lie, Stnd]\n  search: 0\n  runs: 0\n", "uncertainty.nodes.1", "did you mean 'Stand'"),
    (BASE + "  assertions:\n    - edge: {from: Stand, to: Walk(fast)}\n", "uncertainty.assertions.0.edge.to", ""),
    (BASE + "  disturbance: {inputs: [tau_FL_hip_joint], bound: 1}\n", "uncertainty.disturbance.inputs", ""),
])
def test_rigid_uncertainty_names_are_checked_with_located_errors(tmp_path, block, key, hint):
    spec = load_project(_a1_with(tmp_path, block))
    with pytest.raises(SpecErrors) as ei:
        check_uncertainty(spec)
    err = ei.value.errors[0]
    assert err.key.startswith(key) and err.location.line > 0 and str(err.location.file).endswith("project.yaml")
    assert hint in err.hint


def test_push_frame_and_node_kinds_are_checked_once_compiled(tmp_path, built):
    spec = load_project(_a1_with(tmp_path, BASE + "  disturbance: {force: {frame: trunkk, bound: [5, 5, 0]}}\n"))
    with pytest.raises(SpecErrors) as ei:
        check_uncertainty_compiled(spec, built[0].prims)
    err = ei.value.errors[0]
    assert err.key == "uncertainty.disturbance.force.frame" and "did you mean 'trunk'" in err.hint
    assert err.location.line > 0


@pytest.mark.parametrize("block, what", [
    ("uncertainty:\n  disturbance: {force: {frame: trunk, bound: [0, 0, 0]}}\n", "at least one axis"),
    ("uncertainty:\n  disturbance: {force: {frame: trunk, bound: [5, 5]}}\n", "bound"),
    ("uncertainty:\n  disturbance: {force: {frame: trunk, bound: [5, 5, 0]}, bound: 3}\n", "inside force"),
    ("uncertainty:\n  disturbance: {segments: 3}\n", "either inputs"),
])
def test_force_structure_errors(tmp_path, block, what):
    with pytest.raises(SpecErrors) as ei:
        load_project(_a1_with(tmp_path, block))
    text = ei.value.errors[0].format()
    assert "uncertainty" in text and what in text and "project.yaml:" in text


def test_a_push_needs_a_rigid_body(tmp_path):
    dst = tmp_path / "pendulum"
    shutil.copytree(PEND, dst)
    text = (dst / "project.yaml").read_text()
    block = "uncertainty:\n  disturbance: {force: {frame: trunk, bound: [1, 0, 0]}}\n"
    (dst / "project.yaml").write_text(text[: text.index("uncertainty:")] + block)
    with pytest.raises(SpecErrors) as ei:
        check_uncertainty(load_project(dst / "project.yaml"))
    assert ei.value.errors[0].key == "uncertainty.disturbance.force"


def test_robust_h_keeps_every_other_row_without_the_nominal_dynamics(a1_pd_lie):
    """The robust step evaluates only the h rows the perturbed plant does not replace: the same
    values as the closed loop's, without the nominal contact dynamics (a fraction of its size)."""
    from mpgspec.robust.rigid import robust_h

    prim = a1_pd_lie[1]["Lie"]  # a continuous law: h of (x, t, s, x_sw)
    rows = no_slip_rows(prim)
    h_fn, kept = robust_h(prim, rows)
    assert rows and sorted(kept + list(rows)) == list(range(len(prim.h_names)))
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = prim.system.default_state() + 0.05 * rng.standard_normal(prim.system.nx)
        t, s = rng.uniform(0, 1, 2)
        full = np.array(prim.loop_raw(x, t, s, x)[1]).ravel()
        np.testing.assert_array_equal(np.array(h_fn(x, t, s, x)).ravel(), full[kept])
    assert h_fn.n_nodes() < prim.loop_raw.n_nodes() / 5
