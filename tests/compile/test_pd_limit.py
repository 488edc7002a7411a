"""A PD law's own bound (controller.limit): u clamped to [-limit, limit] per input, a guard where it binds."""
import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.spec.loader import load_project

PROJECT = """\
project: limited
system:
  name: cart
  states: [p, v]
  inputs: [a, b]
  dynamics: {f: [v, 0], g: [[1, 0], [0, 1]]}
primitives:
  - name: Hold
    class: fixed
    setpoint: {expr: [0, 0]}
    controller: {type: pd, outputs: [p, v], kp: [4, 2], kd: [1, 1], LIMIT}
    roa: {radius: 0.1}
"""


def _hold(tmp_path, limit: str):
    (tmp_path / "project.yaml").write_text(PROJECT.replace("LIMIT", limit))
    return compile_project(load_project(tmp_path / "project.yaml"))["Hold"]


def test_the_law_is_clamped_per_input_and_unchanged_inside(tmp_path):
    free = _hold(tmp_path, "feedforward: [0, 0]")
    one = _hold(tmp_path, "limit: 0.5")
    each = _hold(tmp_path, "limit: [0.5, 3]")
    for x in ([0.05, 0.0], [1.0, -0.2], [-2.0, 0.4]):
        x = np.array(x)
        u = np.array(free.control(x, 0, 0, x)[0]).ravel()
        assert np.array(one.control(x, 0, 0, x)[0]).ravel() == pytest.approx(np.clip(u, -0.5, 0.5), abs=0)
        assert np.array(each.control(x, 0, 0, x)[0]).ravel() == pytest.approx(np.clip(u, [-0.5, -3], [0.5, 3]), abs=0)
    # where the bound binds the loop kinks: a guard the oracle integrates up to
    assert len(one.guards) > len(free.guards)


def test_a_limit_of_the_wrong_length_or_sign_is_a_located_spec_error(tmp_path, capsys):
    from mpgspec.cli import main

    for limit, found in (("limit: [1, 2, 3]", "3 values"), ("limit: -1", "-1")):
        (tmp_path / "project.yaml").write_text(PROJECT.replace("LIMIT", limit))
        assert main(["verify", str(tmp_path / "project.yaml"), "--no-write"]) == 2
        err = capsys.readouterr().err
        assert "project.yaml:" in err and "limit" in err and found in err and "Traceback" not in err
