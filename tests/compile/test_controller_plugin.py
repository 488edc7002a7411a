"""A controller kind defined outside mpgspec (here), registered in this process through the
entry-point mechanism (an EntryPoint of the group `mpgspec.controllers`, as an installed package
would declare it), named by a spec and verified through `mpgspec.api`."""
from __future__ import annotations

from importlib.metadata import EntryPoint
from typing import Literal

import casadi as ca
import pytest

from mpgspec import api
from mpgspec.compile.laws.kind import ControllerKind, Setup
from mpgspec.compile.laws.registry import controller_kinds, register, unregister
from mpgspec.spec.base import Strict
from mpgspec.spec.primitive import Primitive


class StateFeedback(Strict):
    """u = u_ff - K (x - x*(t)): full state feedback around the setpoint with a constant feedforward."""

    type: Literal["state_feedback"]
    K: list[list[float]]
    feedforward: list[float]


def state_feedback_setup(inst, sys, ec, consts) -> Setup:
    """Checks the gain's shape against the system and records it in the primitive's info."""
    c = inst.spec.controller
    if len(c.K) != sys.nu or any(len(row) != sys.nx for row in c.K):
        raise ValueError("K must be inputs x states")
    return Setup(info={"state_feedback": {"K": c.K}})


def state_feedback_law(c: StateFeedback, ctx):
    sys = ctx.sys
    return ca.DM(c.feedforward) - ca.mtimes(ca.DM(c.K), sys.wrapped_error(sys.x - ctx.x_star))


STATE_FEEDBACK = ControllerKind(StateFeedback, law=f"{__name__}:state_feedback_law",
                                setup=f"{__name__}:state_feedback_setup")

PROJECT = """
project: plugin_pendulum
system:
  name: pendulum
  kind: analytic
  states: [theta, omega]
  inputs: [tau]
  parameters: {m: 1.0, l: 1.0, g: 9.81, b: 0.1}
  dynamics:
    f: [omega, "-g/l*sin(theta) - b/(m*l^2)*omega"]
    g: [[0], ["1/(m*l^2)"]]
  input_bounds: {tau: [-8, 8]}
primitives:
  - name: Hang
    class: fixed
    setpoint: {expr: [0, 0]}
    controller: {type: state_feedback, K: [[10, 4]], feedforward: [0]}
    safe_set:
      - {name: speed_limit, h: "6 - abs(omega)"}
    roa: {radius: 0.1}
  - name: Tilt
    class: fixed
    setpoint: {expr: [0.5, 0]}
    controller: {type: state_feedback, K: [[10, 4]], feedforward: [4.703182]}   # m g l sin(0.5)
    safe_set:
      - {name: speed_limit, h: "6 - abs(omega)"}
    roa: {radius: 0.1}
oracle:
  horizon: 4.0
  dt: 0.01
  accuracy: low
assertions:
  - edge: {from: Hang, to: Tilt}
  - edge: {from: Tilt, to: Hang}
"""


@pytest.fixture
def state_feedback_kind():
    register(EntryPoint(name="state_feedback", value=f"{__name__}:STATE_FEEDBACK", group="mpgspec.controllers"))
    yield
    unregister("state_feedback")


def test_a_registered_kind_is_verified_in_a_graph(state_feedback_kind, tmp_path):
    assert controller_kinds()["state_feedback"] is STATE_FEEDBACK
    (tmp_path / "project.yaml").write_text(PROJECT)
    result = api.verify(tmp_path)
    project = result["plugin_pendulum"]
    assert result.exit_code == api.EXIT_OK and project.status == "pass", project.errors
    assert {("Hang", "Tilt"), ("Tilt", "Hang")} <= set(project.graph.edges)
    assert project.compiled.prims["Tilt"].info["state_feedback"] == {"K": [[10.0, 4.0]]}


def test_the_spec_union_follows_the_registry(state_feedback_kind):
    schema = Primitive.model_json_schema()
    assert "StateFeedback" in schema["$defs"]
    unregister("state_feedback")
    assert "StateFeedback" not in Primitive.model_json_schema()["$defs"]
    assert "state_feedback" not in controller_kinds()


def test_the_spec_layer_loads_every_kind_without_casadi():
    import subprocess
    import sys

    code = ("import sys, mpgspec.spec.models; "
            "from mpgspec.spec.kinds import controller_models; assert len(controller_models()) >= 6; "
            "sys.exit('casadi' in sys.modules or 'cvxpy' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
