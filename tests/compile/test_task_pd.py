"""Task-space PD: u = J_y^T (-Kp (y - y_d) - Kd (ydot - ydot_d))."""
from pathlib import Path

import casadi as ca
import numpy as np

from mpgspec.api import compile_project
from mpgspec.spec.loader import load_project

PROJECT = """\
project: task
system:
  name: cart
  states: [p, v]
  inputs: [a]
  dynamics: {f: [v, 0], g: [[0], [1]]}
primitives:
  - name: Hold
    class: fixed
    setpoint: {expr: [0.5, 0]}
    controller: {type: pd, outputs: ["2*p"], kp: [3], kd: [1], input_map: jacobian_transpose}
    roa: {radius: 0.1}
"""


def test_task_space_pd_on_an_analytic_system(tmp_path):
    (tmp_path / "project.yaml").write_text(PROJECT)
    p = compile_project(load_project(tmp_path / "project.yaml"))["Hold"]
    x = np.array([0.2, -0.3])
    u = float(p.control(x, 0, 0, x)[0])
    # y = 2p, y_d = 1, ydot = 2v, J_y = 2: u = 2 (-3 (0.4 - 1) - 1 (-0.6))
    assert u == np.float64(2 * (-3 * (0.4 - 1) - 1 * (-0.6)))


def test_task_space_pd_on_the_a1(tmp_path, pd_lie):
    import shutil

    shutil.copytree(Path(__file__).parents[2] / "specs" / "a1", tmp_path / "a1")
    pd_lie(tmp_path / "a1")  # the paper's joint PD, made a task-space PD below
    lie = tmp_path / "a1" / "primitives" / "lie.yaml"
    text = lie.read_text()
    start = text.index("  outputs:")
    end = text.index("  gravity_compensation")
    lie.write_text(text[:start] + "  outputs: [com_x, com_y, com_z]\n  kp: [50, 50, 50]\n  kd: [5, 5, 5]\n"
                   "  input_map: jacobian_transpose\n" + text[end:])
    p = compile_project(load_project(tmp_path / "a1" / "project.yaml"))["Lie"]
    sys = p.system
    rng = np.random.default_rng(1)
    x = p.x_star(0.0) + np.r_[np.zeros(sys.model.nq), 0.1 * rng.normal(size=sys.model.nv),
                              np.zeros(sys.nx - sys.model.nq - sys.model.nv)]
    com = ca.vertcat(*[sys.extra_env[f"com_{a}"] for a in "xyz"])
    J = ca.jacobian(ca.jtimes(com, sys.x[:sys.model.nq], sys.xdot[:sys.model.nq]), sys.x[sys.model.nq + 6:sys.model.nq + sys.model.nv])
    fJ = ca.Function("f", [sys.x], [com, J, ca.mtimes(ca.jacobian(com, sys.x[:sys.model.nq]), sys.xdot[:sys.model.nq])])
    c, Jn, cd = (np.array(v) for v in fJ(x))
    c_star = np.array(fJ(p.x_star(0.0))[0])
    grav = np.array(ca.Function("g", [sys.x], [sys.static_torque(tuple(sys.model.contact_frames))])(x)).ravel()
    # at switch-in the profile starts at the output and its rate: no task torque, only gravity compensation
    u = np.array(p.control(x, 0.0, 0.0, x)[0]).ravel()
    assert np.allclose(u, grav, atol=1e-9)
    # after the profile, the error is the CoM offset from the setpoint's CoM
    u_late = np.array(p.control(x, 0.0, 5.0, x)[0]).ravel()
    expect = (Jn.T @ (-50 * (c - c_star).ravel() - 5 * cd.ravel())).ravel() + grav
    assert np.allclose(u_late, expect, atol=1e-8)


def test_a_fixed_target_does_not_read_the_setpoint(tmp_path):
    """`target` replaces y(x*(t)) (and the rates 0), so the law is the same whatever x* is."""
    laws = []
    for setpoint in ("[0.5, 0]", "[-2.0, 3.0]"):
        text = PROJECT.replace("setpoint: {expr: [0.5, 0]}", f"setpoint: {{expr: {setpoint}}}")
        text = text.replace("input_map: jacobian_transpose}", "input_map: jacobian_transpose, target: [1.0]}")
        (tmp_path / "project.yaml").write_text(text)
        p = compile_project(load_project(tmp_path / "project.yaml"))["Hold"]
        x = np.array([0.2, -0.3])
        laws.append(float(p.control(x, 0, 0, x)[0]))
    assert laws[0] == laws[1] == np.float64(2 * (-3 * (0.4 - 1) - 1 * (-0.6)))


def test_a_target_of_the_wrong_length_is_a_located_spec_error(tmp_path):
    from mpgspec.cli import main

    text = PROJECT.replace("input_map: jacobian_transpose}", "input_map: jacobian_transpose, target: [1.0, 2.0]}")
    (tmp_path / "project.yaml").write_text(text)
    assert main(["verify", str(tmp_path / "project.yaml"), "--no-write", "-q"]) == 2
