"""The oracle's short first steps (oracle.flow.RAMP): a flow that starts at rest 10 um above its
safe set's boundary and accelerates away from it at 1,000 m/s^2, as a released swing foot does,
is judged safe; with whole steps the bound between samples (the steepest end rate over the step)
dips under the boundary at the first step and the call is inconclusive, its evidence naming the
function in doubt with that function's own margin."""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.oracle import SafetyOracle, flow
from mpgspec.settings import OracleSettings
from mpgspec.spec.loader import load_project

SPEC = """\
project: unit
system:
  name: lift
  kind: analytic
  states: [p, v]
  inputs: [u]
  dynamics: {f: ["v", "0"], g: [[0], [1]]}
  input_bounds: {u: [-1e6, 1e6]}
primitives:
  - name: Lift
    class: fixed
    setpoint: {expr: [0.01, 0]}
    controller: {type: expression, u: ["1e5*(0.01 - p) - 632*v"]}
    safe_set:
      - {name: floor, h: "p"}
    roa: {radius: 0.004}
"""
START = np.array([1e-5, 0.0])  # at rest, 10 um up: the law pulls it up at 1e5 * 0.01 = 1,000 m/s^2


def _lift(tmp_path, ramp: float, monkeypatch):
    monkeypatch.setattr(flow, "RAMP", ramp)  # read where the oracle builds its step
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / "project.yaml"
    path.write_text(textwrap.dedent(SPEC))
    (prim,) = compile_project(load_project(path)).values()
    return prim


@pytest.mark.parametrize("error", ["local", "doubling"])
def test_a_flow_leaving_its_boundary_hard_is_safe_with_short_first_steps(tmp_path, monkeypatch, error):
    settings = OracleSettings(horizon=1.0, dt=1e-3, refinements=0, jit=False, error=error)
    e = SafetyOracle(_lift(tmp_path / "ramp", flow.RAMP, monkeypatch), settings)(START, 0.0)
    assert e.violated is None and 0 < e.lower_bounds["floor"] <= 1e-5, e
    # step doubling enters E beyond doubt; the summed local estimate, far larger on this stiff loop
    # (omega dt = 0.32), leaves E's entry in doubt at the horizon, but C is never in doubt
    assert e.status == ("safe" if error == "doubling" else "inconclusive"), e
    whole = SafetyOracle(_lift(tmp_path / "whole", 1.0, monkeypatch), settings)(START, 0.0)
    assert (whole.status, whole.violated, whole.t_stop) == ("inconclusive", "floor", 0.0), whole
    assert whole.lower_bounds["floor"] < -1e-4  # about a dt^2 / 4 under the 10 um


def test_the_first_dt_is_taken_in_growing_steps(tmp_path, monkeypatch):
    from mpgspec.oracle.integrator import build_chunk, initial_state

    prim = _lift(tmp_path, flow.RAMP, monkeypatch)
    ch = build_chunk(prim, 1e-3, 8, jit=False)
    _, out = ch.run(initial_state(prim, START, 0.0)[:, None])
    h = out[ch.rows.dt, 0]
    growing = [1e-3 * flow.RAMP * 2 ** max(k - 1, 0) for k in range(flow.RAMP_STEPS + 1)]  # dt/16, dt/16, dt/8, ...
    assert h[:flow.RAMP_STEPS + 2] == pytest.approx(growing + [1e-3])


def test_a_doubt_reports_the_doubted_functions_own_margin(tmp_path, monkeypatch):
    """Whole steps: `floor` (least sample 1e-5) is in doubt at the first step while `near` keeps a
    smaller sampled value, 5e-6, beyond doubt; the evidence names `floor` with floor's own margin and
    error, whose difference is the least lower bound of all."""
    monkeypatch.setattr(flow, "RAMP", 1.0)
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "project.yaml").write_text(SPEC.replace('      - {name: floor, h: "p"}\n',
                                                        '      - {name: floor, h: "p"}\n'
                                                        '      - {name: near, h: "5e-6 + 0*v"}\n'))
    (prim,) = compile_project(load_project(tmp_path / "project.yaml")).values()
    settings = OracleSettings(horizon=1.0, dt=1e-3, refinements=0, jit=False, error="doubling")
    e = SafetyOracle(prim, settings)(START, 0.0)
    assert (e.status, e.violated) == ("inconclusive", "floor"), e
    assert e.min_margins["near"] == pytest.approx(5e-6) and e.margin == pytest.approx(e.min_margins["floor"])
    assert e.margin - e.error_bound == pytest.approx(min(e.lower_bounds.values()))
