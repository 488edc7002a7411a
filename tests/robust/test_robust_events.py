"""Robust rollouts of the A1's contact-switching primitives: a trot under a contact schedule, and
Land with contact events and windows anchored on them. At the nominal scenario a robust step is the
oracle's step (the same flow, state for state); a push and a mass error act as Newton says; the
no-slip functions take the scenario's friction only for the feet held."""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from mpgspec.execute.sequence import simulate_sequence
from mpgspec.oracle.flow import switched_flow
from mpgspec.robust.rigid import no_slip_rows, plant_feet, rigid_step, robust_plant
from mpgspec.robust.sequence import sequence_under_uncertainty
from mpgspec.spec.project import Sequence

NAMES = ["mass_scale", "friction"]
G = 9.81


@pytest.fixture(scope="module")
def a1(a1_project):
    spec, prims, settings = a1_project
    return spec, prims, dataclasses.replace(settings, jit=False)


def _steps(prim, x0, t0, theta, F, n, dt):
    """States (nx, n + 1) and outputs (n, nh + 1) of n robust steps from x0 at clock t0."""
    step, *_ = rigid_step(prim, robust_plant(prim, "trunk"), NAMES, "trunk", True, dt)
    nx = prim.system.nx
    z = np.concatenate([x0, [t0, 0.0], x0, theta])
    X, out = [x0], []
    for _ in range(n):
        zn, o = step(z, F)
        z = np.array(zn).ravel()
        X.append(z[:nx])
        out.append(np.array(o).ravel())
    return np.array(X).T, np.array(out)


@pytest.mark.parametrize("name, source, t_A, t0, n", [
    ("Walk(in_place)", "Walk(in_place)", 0.0, 0.0, 400),  # a full stride: swing, touchdown, the other pair
    ("Land", "Jump", 0.25, 0.0, 300),                    # flight, touchdown by event, the delay window
])
def test_the_nominal_scenario_is_the_oracles_flow(a1, name, source, t_A, t0, n):
    _, prims, settings = a1
    prim, dt = prims[name], settings.dt
    x0 = prims[source].x_star(t_A)
    X, out = _steps(prim, x0, t0, [1.0, 0.6], np.zeros(3), n, dt)
    ref = switched_flow(prim, x0, t0, dt, n)
    assert np.abs(X - ref).max() < 1e-9
    margins = np.array([float(prim.roa_margin(ref[:, k], t0 + k * dt)) for k in range(1, n + 1)])
    assert np.allclose(out[:, -1], margins, atol=1e-9)
    sys = prim.system
    flags = ref[sys.model.nq + sys.model.nv:sys.model.nq + sys.model.nv + 4]
    assert np.ptp(flags, axis=1).max() == 1.0  # the contact set changed along the way


def test_a_push_in_flight_accelerates_the_centre_of_mass_by_F_over_km(a1):
    _, prims, settings = a1
    land, dt = prims["Land"], settings.dt
    sys = land.system
    F, k = np.array([6.0, -4.0, 0.0]), 1.1
    X, _ = _steps(land, prims["Jump"].x_star(0.25), 0.0, [k, 0.6], F, 60, dt)
    flags = X[sys.model.nq + sys.model.nv:sys.model.nq + sys.model.nv + 4]
    air = np.flatnonzero(flags.sum(axis=0) == 0)
    air = air[(air > 0) & (air < air.max())][:40]
    assert len(air) == 40  # still in flight
    com = ca.Function("com", [sys.x], [ca.vertcat(*[sys.extra_env[f"com_{a}"] for a in "xyz"])])
    C = np.array(com.map(X.shape[1])(X))
    acc = (C[:, air + 1] - 2 * C[:, air] + C[:, air - 1]) / dt**2
    expected = F / (k * sys.model.total_mass) + np.array([0.0, 0.0, -G])
    assert np.abs(acc - expected[:, None]).max() < 0.02


def test_friction_binds_the_held_feet_only(a1):
    _, prims, _ = a1
    walk = prims["Walk(in_place)"]
    _, first, *_ = rigid_step(walk, robust_plant(walk, "trunk"), NAMES, "trunk", True, 0.001)
    feet, rows = plant_feet(walk), no_slip_rows(walk)
    assert len(rows) == 2 * len(feet)
    for t in (0.0, 0.1):  # double support, then mid-swing (two feet up)
        x = walk.x_star(t)
        y = {mu: np.array(first(x, t, 0.0, [1.0, mu], np.zeros(3))[0]).ravel() for mu in (0.4, 0.8)}
        held = walk.system.contact_mode(x)
        for j, (i, kind) in rows.items():
            if feet[i] in held:
                assert y[0.8][j] > y[0.4][j] if kind else y[0.8][j] == y[0.4][j]
            else:
                assert y[0.4][j] == y[0.8][j] == 1e3  # a foot in the air has no force to bound
        assert (t == 0.0) == (len(held) == 4)


def _jump_sequence(spec, mass_scale: float, friction: float = 0.6):
    """Stand, then Jump at 0.05 s (Land takes over at its end), 1.5 s; the mass scale and friction
    fixed at the given values, no push."""
    P = spec.project.uncertainty.parameters
    unc = spec.project.uncertainty.model_copy(update={
        "parameters": {"mass_scale": P["mass_scale"].model_copy(update={"range": (mass_scale, mass_scale)}),
                       "friction": P["friction"].model_copy(update={"range": (friction, friction)})},
        "disturbance": None})
    seq = Sequence(start="Stand", duration=1.5, commands=[{"t": 0.05, "goal": "Jump"}])
    return dataclasses.replace(spec, project=spec.project.model_copy(update={"uncertainty": unc, "sequence": seq}))


def test_the_sequence_under_the_nominal_draw_is_the_nominal_run(a1):
    spec, prims, settings = a1
    s = _jump_sequence(spec, 1.0)
    stats = sequence_under_uncertainty(s, prims, settings, {}, 2, 0)
    naive = stats["modes"]["naive"]
    run = simulate_sequence(prims, None, {}, s.project.sequence, settings, "naive")
    assert run.safe and [w["to"] for w in run.switches] == ["Stand", "Jump", "Land"]
    assert naive["safe_runs"] == 2 and naive["final"] == ["Land", "Land"]
    assert naive["switches"] == [{"from": "Jump", "to": "Land", "count": 2}, {"from": "Stand", "to": "Jump", "count": 2}]


def _hard_jump(spec):
    """specs/a1 with its Jump asked 7 cm at 1.2 m/s (the project's own asks 6 cm at 1.0 m/s, and
    keeps the calves 0.076 rad inside q_max over its mass and torque box): with every link 10 %
    lighter this push-off swings a calf past q_max after takeoff. x*(0), the stance, is the same."""
    def harder(p):
        if p.name != "Jump":
            return p
        c = p.spec.controller.model_copy(update={"rise": 0.07, "takeoff_velocity": 1.2})
        return dataclasses.replace(p, spec=p.spec.model_copy(update={"controller": c}))
    return dataclasses.replace(spec, primitives=[harder(p) for p in spec.primitives])


def _calf_q_max(h: str) -> bool:
    return h.startswith("q_max[") and h.endswith("_calf_joint]")


def test_a_lighter_robot_overshoots_the_tuck(a1):
    """With every link 10 % lighter the harder jump's joint PD swings the calves past their limit
    after takeoff (the project's own jump keeps them inside); Stand -> Jump is still a robust edge,
    since Jump's E holds Stand's x* at the switch: the robust edge covers the flow up to E_B, the
    sequence runs cover the rest."""
    from mpgspec.api import compile_project

    spec, prims, settings = a1
    hard = _hard_jump(spec)
    hard_prims = {**prims, "Jump": compile_project(hard)["Jump"]}
    runs = {k: sequence_under_uncertainty(_jump_sequence(hard, k), hard_prims, settings, {}, 2, 0)["modes"]["naive"]
            for k in (0.9, 1.1)}
    own = sequence_under_uncertainty(_jump_sequence(spec, 0.9), prims, settings, {}, 2, 0)["modes"]["naive"]
    assert runs[1.1]["safe_runs"] == 2 and own["safe_runs"] == 2
    first = runs[0.9]["first_violation"]
    assert runs[0.9]["safe_runs"] == 0 and all(_calf_q_max(f["h"]) for f in first)
    T_t = prims["Jump"].info["jump"]["takeoff_time"]
    assert all(f["primitive"] == "Jump" and 0.05 + T_t < f["t"] <= 0.05 + 0.25 for f in first)


def test_an_edge_into_a_primitive_whose_own_flow_breaks_is_lost(a1):
    """Stand -> Jump is safe in every scenario up to E_Jump (it holds Stand's x* at the switch), but a
    10 % lighter robot overshoots the harder jump's tuck in Jump's own flow: the edge is nominal only
    and says why."""
    from mpgspec import api
    from mpgspec.robust.graph import robust_stage

    spec, _, settings = a1
    spec = _hard_jump(spec)
    P = spec.project.uncertainty.parameters
    unc = spec.project.uncertainty.model_copy(update={
        "parameters": {"mass_scale": P["mass_scale"]}, "disturbance": None, "samples": 0, "search": 0, "runs": 0,
        "assertions": [], "nodes": None})
    small = dataclasses.replace(spec, primitives=[p for p in spec.primitives if p.name in ("Stand", "Jump", "Land")],
                                project=spec.project.model_copy(update={"uncertainty": unc, "sequence": None,
                                                                        "assertions": [], "crosscheck": None}))
    cp, vg = api.build(small, settings)
    rob = robust_stage(cp, vg).to_dict()
    nodes = {n["node"]: n for n in rob["nodes"]}
    jump = nodes["Jump"]
    assert not jump["robust_safe"] and jump["worst_case"]["parameters"]["mass_scale"] == 0.9
    assert _calf_q_max(jump["worst_case"]["binding"]["h"])
    edge = {(e["from"], e["to"]): e for e in rob["edges"]}[("Stand", "Jump")]
    assert edge["worst_margin"] >= 0 and not edge["target_flow_safe"] and not edge["survives"]
    # Stand's own flow keeps C (in every scenario, or in the first wave when no edge into it depends on it)
    assert nodes["Stand"]["robust_safe"] is not False and nodes["Stand"]["worst_margin"] >= 0
