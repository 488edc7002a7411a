"""The A1's ID-QP under sample-and-hold (compile/hold.py, oracle/integrator.py): the held law tends
to the continuous one as the control period shrinks, the input is held for whole control periods,
a rate that is not a whole number of oracle steps is a spec error, and Lie -> Stand stays class 1."""
from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from mpgspec.api import compile_project, compile_stage, settings_for
from mpgspec.cli import main
from mpgspec.graph.build import build_graph
from mpgspec.graph.transition import TransitionClass
from mpgspec.oracle.integrator import build_chunk, hold_size
from mpgspec.spec.loader import load_project

SPEC = Path(__file__).parents[2] / "specs" / "a1"


def lie_and_stand(dst: Path, rate: str | None = None) -> Path:
    """specs/a1 with Lie and Stand only (no walks, assertions or sequence); Stand at `rate` Hz and without its
    integral action (the hold is what this module tests; _with_integral puts it back)."""
    shutil.copytree(SPEC, dst, ignore=shutil.ignore_patterns("gaits", "gaits.yaml", "walk*.yaml"))
    proj = yaml.safe_load((dst / "project.yaml").read_text())
    proj["primitives"] = ["primitives/lie.yaml", "primitives/stand.yaml"]
    proj.pop("assertions", None)
    proj.pop("sequence", None)
    proj.pop("uncertainty", None)  # its robust assertions name the walks, Jump and Land
    proj.pop("crosscheck", None)  # replays the sequence, which is gone
    (dst / "project.yaml").write_text(yaml.safe_dump(proj, sort_keys=False))
    stand = dst / "primitives" / "stand.yaml"
    text, n = re.subn(r"\n  ki(?:_limit)?: [^\n]*", "", stand.read_text())
    assert n == 2
    stand.write_text(text)
    if rate is not None:
        stand = dst / "primitives" / "stand.yaml"
        text, n = re.subn(r"(\n  rate:) *[^ \n#]+", rf"\1 {rate}", stand.read_text())
        assert n == 1
        stand.write_text(text)
    return dst / "project.yaml"


@pytest.fixture(scope="module")
def a1(tmp_path_factory):
    spec = load_project(lie_and_stand(tmp_path_factory.mktemp("a1") / "a1"))
    return spec, compile_project(spec), settings_for(spec)


def _states(prim, x0, dt: float, T: float, every: float) -> np.ndarray:
    """States of an uncompiled rollout from x0 over [0, T], sampled every `every` seconds."""
    ch = build_chunk(prim, dt, 50, jit=False, with_state=True, boundaries=False)
    z, cols, n = ch.start(x0[None], [0.0]), [], round(T / dt) + 1
    while sum(c.shape[1] for c in cols) < n:
        z, out = ch.run(z)
        cols.append(out[ch.rows.x, 0, :])
    return np.concatenate(cols, axis=1)[:, :n:round(every / dt)]


def test_held_input_tends_to_the_continuous_law(a1):
    """Stand from Lie's setpoint over the first 0.2 s (the CoM profile at its fastest): the law held
    over each step of dt against the law solved at every RK4 stage at dt/4 (whose own integration
    error, below 1e-10 here, is negligible). A zero-order hold of period T delays the input by T/2
    on average, so the difference is first order in T: it must halve with T, and at the A1's 1 kHz
    stay below 1e-2 (in rad/s, the largest difference being in a joint velocity of about 2 rad/s)."""
    _, prims, _ = a1
    stand, x0 = prims["Stand"], prims["Lie"].x_star(0.0)
    per_step = dataclasses.replace(stand, sampled=dataclasses.replace(stand.sampled, period=None), cache={})
    continuous = dataclasses.replace(stand, sampled=None, loop_u=None, cache={})
    ref = _states(continuous, x0, 0.00025, 0.2, 0.002)
    err = {dt: np.abs(_states(per_step, x0, dt, 0.2, 0.002) - ref).max() for dt in (0.002, 0.001, 0.0005)}
    assert err[0.001] < 1e-2, err
    assert 1.8 < err[0.002] / err[0.001] < 2.2, err
    assert 1.8 < err[0.001] / err[0.0005] < 2.2, err


def test_input_is_held_for_whole_control_periods(a1):
    """At 500 Hz and 1 ms steps the law is solved every second step, from its own last solution
    (carried in the augmented state), and the step-doubling companion keeps its own."""
    _, prims, st = a1
    stand, x0 = prims["Stand"], prims["Lie"].x_star(0.0)
    slow = dataclasses.replace(stand, sampled=dataclasses.replace(stand.sampled, period=0.002), cache={})
    for error in ("local", "doubling"):
        ch = build_chunk(slow, st.dt, 8, jit=False, error=error)
        z0 = ch.start(x0[None], [0.0])
        assert z0.shape[0] == (3 if error == "doubling" else 2) * len(x0) + 2 + hold_size(slow, error == "doubling")
        zf, out = ch.run(z0)
        U = out[ch.rows.u_raw, 0, :]
        assert np.array_equal(U[:, 0::2], U[:, 1::2])
        assert np.abs(np.diff(U[:, 0::2], axis=1)).min(axis=0).max() > 0  # a new solve every period
        assert np.allclose(U[:, 0], np.array(stand.control(x0, 0.0, 0.0, x0)[0]).ravel(), atol=1e-6)
        w = zf[-hold_size(slow, error == "doubling"):]
        assert np.isfinite(w).all() and np.abs(w).max() > 0  # the warm start rides along


@pytest.mark.parametrize("rate", ["300", "2000"])
def test_rate_not_a_whole_number_of_steps_is_a_spec_error(tmp_path, capsys, rate):
    """1/300 s is 3.33 oracle steps of 1 ms, 1/2000 s half of one: exit 2, located at the rate."""
    path = lie_and_stand(tmp_path / "a1", rate)
    rc = main(["verify", str(path), "--no-write", "-q"])
    err = capsys.readouterr().err
    stand = tmp_path / "a1" / "primitives" / "stand.yaml"
    line = 1 + stand.read_text().splitlines().index(f"  rate: {rate}             # Hz: solved every 1 ms "
                                                     "(warm-started), the torques held in between")
    assert rc == 2, err
    assert f"{stand}:{line}" in err and "MPG104" in err and "controller.rate" in err, err
    assert "whole number of oracle steps" in err and "Traceback" not in err


def test_a_design_friction_above_the_systems_is_a_spec_error(tmp_path, capsys):
    """An ID-QP designing its forces for more friction than C judges would plan them outside the cone:
    exit 2, located at controller.friction, no traceback."""
    path = lie_and_stand(tmp_path / "a1")
    stand = tmp_path / "a1" / "primitives" / "stand.yaml"
    text = stand.read_text()
    assert text.count("\n  friction: 0.35\n") == 1
    stand.write_text(text.replace("\n  friction: 0.35\n", "\n  friction: 0.7\n"))
    rc = main(["verify", str(path), "--no-write", "-q"])
    err = capsys.readouterr().err
    line = 1 + stand.read_text().splitlines().index("  friction: 0.7")
    assert rc == 2, err
    assert f"{stand}:{line}" in err and "MPG104" in err and "controller.friction" in err, err
    assert "at most the system's friction 0.6" in err and "Traceback" not in err


def test_rate_a_multiple_of_the_step_is_accepted(tmp_path):
    spec = load_project(lie_and_stand(tmp_path / "a1", "250"))
    prims = compile_project(spec)
    assert prims["Stand"].sampled.steps(settings_for(spec).dt) == 4
    assert prims["Stand"].sampled.steps(settings_for(spec).dt / 2) == 8  # refined rollouts hold 8 steps


@pytest.mark.slow
def test_lie_to_stand_is_class_1_with_the_held_idqp(a1):
    spec, _, st = a1
    cp = compile_stage(spec, st)
    assert cp.prims["Stand"].info["id_qp"]["control_rate"] == "1000 Hz"
    g = build_graph(cp.prims, st, 1, 1)
    edge = g.edge("Lie", "Stand")
    assert edge is not None and edge.cls is TransitionClass.CLASS_1


def _with_integral(path: Path, ki: str = "[300, 300, 2700]", limit: str = "8") -> Path:
    """The project at `path` with Stand's ID-QP given integral action (ki, ki_limit)."""
    stand = path.parent / "primitives" / "stand.yaml"
    text, n = re.subn(r"\n  rate:", f"\n  ki: {ki}\n  ki_limit: {limit}\n  rate:", stand.read_text())
    assert n == 1
    stand.write_text(text)
    return path


def test_integral_action_needs_a_rate(tmp_path, capsys):
    """Stand's integral advances once per solve: without a rate it is a spec error located at controller.ki."""
    path = _with_integral(lie_and_stand(tmp_path / "a1"))
    stand = tmp_path / "a1" / "primitives" / "stand.yaml"
    stand.write_text(re.sub(r"\n  rate:[^\n]*", "", stand.read_text()))
    rc = main(["verify", str(path), "--no-write", "-q"])
    err = capsys.readouterr().err
    line = 1 + stand.read_text().splitlines().index("  ki: [300, 300, 2700]")
    assert rc == 2, err
    assert f"{stand}:{line}" in err and "MPG104" in err and "integral action needs a control rate" in err, err
    assert "Traceback" not in err


def _settled(prim, settings, theta: tuple, T: float = 2.5) -> tuple[float, np.ndarray]:
    """(CoM height minus x*'s, the state) after T s of prim's own flow from x* under (mass, friction, torque) scale."""
    import casadi as ca

    from mpgspec.robust.rigid import RigidRobustRollout

    names = ["mass_scale", "friction", "torque_scale"]
    rr = RigidRobustRollout(prim, names, "trunk", False, 1, settings, T, None, False, 0)
    got = {}
    run = rr._call

    def keep(fn, n, args):
        out = run(fn, n, args)
        if fn is rr.chunk:
            got["z"] = out[:rr.nz].copy()
        return out

    rr._call = keep
    x0 = np.asarray(prim.x_star(0.0), float).ravel()
    rr.run(x0[None], np.zeros(1), np.array([theta], float), np.zeros((1, 0, 1)), tol=1.0, until_entry=False)
    x = got["z"][:prim.system.nx, 0]
    com_z = ca.Function("com_z", [prim.system.x], [prim.system.extra_env["com_z"]])
    return float(com_z(x)) - float(com_z(x0)), x


def test_integral_action_settles_the_stance_under_a_motor_and_mass_error(a1, tmp_path):
    """Known answer: with every link 10 % heavier on motors giving 90 % of their command, Stand's stiff ID-QP alone
    sags its CoM by about 2 mm; a law with integral action settles at the setpoint's height (its error's integral
    carried in the law's memory, advanced once per solve). At the nominal model both stay at x*: the integral
    starts at 0 and the error there is 0."""
    spec, prims, st = a1
    plain = prims["Stand"]
    spec_i = load_project(_with_integral(lie_and_stand(tmp_path / "a1i")))
    with_i = compile_project(spec_i)["Stand"]
    assert with_i.sampled.nw == plain.sampled.nw + 3 and with_i.info["id_qp"]["integral_gain"] == [300, 300, 2700]
    sag, x_plain = _settled(plain, st, (1.1, 0.6, 0.9))
    held, x = _settled(with_i, st, (1.1, 0.6, 0.9))
    assert sag < -1.5e-3, sag
    assert abs(held) < 2e-4, held
    assert float(with_i.roa_margin(x, 0.0)) > float(plain.roa_margin(x_plain, 0.0))
    for p in (plain, with_i):
        dz, x_nom = _settled(p, st, (1.0, 0.6, 1.0), T=0.5)
        assert abs(dz) < 1e-6 and float(p.roa_margin(x_nom, 0.0)) > 0.99 * float(p.radius)


def test_the_integral_advances_once_per_solve_and_stops_at_its_limit(tmp_path):
    """One solve adds the CoM error times the control period to the integral; at ki_limit / ki it stops."""
    spec = load_project(_with_integral(lie_and_stand(tmp_path / "a1"), limit="3"))
    stand = compile_project(spec)["Stand"]
    law, nw = stand.sampled, stand.sampled.nw
    x = np.asarray(stand.x_star(0.0), float).ravel()
    low = x.copy()
    low[2] -= 0.01  # the base, and with it the CoM, 1 cm low (the feet then off the ground: only the law is read)
    s = 5.0  # after the CoM profile: the target is the setpoint's CoM
    w = np.zeros(nw)
    _, w1 = law.solve(low, 0.0, s, x, w)
    assert np.asarray(w1).ravel()[-3:] == pytest.approx([0.0, 0.0, 0.01 / 1000], abs=1e-9)
    _, w2 = law.solve(x, 0.0, s, x, w1)
    assert np.asarray(w2).ravel()[-3:] == pytest.approx(np.asarray(w1).ravel()[-3:], abs=1e-12)  # no error: kept
    w_cap = np.zeros(nw)
    w_cap[-1] = 3.0 / 2700
    _, w3 = law.solve(low, 0.0, s, x, w_cap)
    assert np.asarray(w3).ravel()[-1] == pytest.approx(3.0 / 2700, rel=1e-12)  # clipped at ki_limit / ki
