"""Tabulated setpoints: samples interpolated linearly or by cubic splines, wrapped for periodic primitives."""
import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.spec.loader import load_project

PROJECT = """\
project: tab
system:
  name: cart
  states: [p, v]
  inputs: [a]
  dynamics: {f: [v, 0], g: [[0], [1]]}
primitives:
  - name: Loop
    class: periodic
    period: 2.0
    setpoint:
      times: [0, 0.5, 1.0, 1.5, 2.0]
      samples: [[0, 1], [0.5, 0], [0, -1], [-0.5, 0], [0, 1]]
      interpolation: INTERP
    controller: {type: pd, outputs: [p], kp: [4], kd: [3], feedforward: ["v_star_dot"]}
    roa: {radius: 0.1}
"""


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test_tabulated_setpoint_interpolates_and_wraps(tmp_path, interp):
    (tmp_path / "project.yaml").write_text(PROJECT.replace("INTERP", interp))
    p = compile_project(load_project(tmp_path / "project.yaml"))["Loop"]
    for t, expect in [(0.0, [0, 1]), (0.5, [0.5, 0]), (1.5, [-0.5, 0])]:
        assert np.allclose(p.x_star(t), expect, atol=1e-12)
    assert np.allclose(p.x_star(2.5), p.x_star(0.5))  # one period later
    if interp == "linear":
        assert np.allclose(p.x_star(0.25), [0.25, 0.5])
    else:
        assert not np.allclose(p.x_star(0.25), [0.25, 0.5])  # a spline, not the chord
