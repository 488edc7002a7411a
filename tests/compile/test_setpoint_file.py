"""Setpoint tables from CSV files next to the spec (gait libraries)."""
import numpy as np
import pytest

from mpgspec.api import compile_project
from mpgspec.cli import main
from mpgspec.spec.loader import load_project

PROJECT = """\
project: table
system:
  name: cart
  states: [p, v]
  inputs: [a]
  dynamics: {f: [v, 0], g: [[0], [1]]}
primitives:
  - name: Loop
    class: periodic
    period: 2.0
    setpoint: {file: loop.csv, interpolation: linear}
    controller: {type: pd, outputs: [p], kp: [4], kd: [3]}
    roa: {radius: 0.1}
"""


def write(tmp_path, csv):
    (tmp_path / "project.yaml").write_text(PROJECT)
    (tmp_path / "loop.csv").write_text(csv)
    return tmp_path / "project.yaml"


def test_csv_columns_fill_named_states_and_defaults(tmp_path):
    path = write(tmp_path, "t,p\n0,0\n1,1\n2,0\n")
    p = compile_project(load_project(path))["Loop"]
    assert np.allclose(p.x_star(0.5), [0.5, 0.0])  # v has no column: its default 0
    assert np.allclose(p.x_star(2.5), [0.5, 0.0])  # wrapped into the period


@pytest.mark.parametrize("csv, line, text", [
    ("p,t\n0,0\n1,1\n", 1, "first column must be the time"),
    ("t,q\n0,0\n1,1\n", 1, "unknown state"),
    ("t,p\n0,0\n1,x\n", 3, "not a number"),
    ("t,p\n0,0\n1\n", 3, "wrong number of columns"),
])
def test_bad_tables_name_file_and_line(tmp_path, capsys, csv, line, text):
    path = write(tmp_path, csv)
    assert main(["verify", str(path), "--no-write", "-q"]) == 2
    err = capsys.readouterr().err
    assert f"loop.csv:{line}:" in err and "MPG110" in err and text in err and "Traceback" not in err


def test_missing_table_names_the_spec_line(tmp_path, capsys):
    (tmp_path / "project.yaml").write_text(PROJECT)
    assert main(["verify", str(tmp_path / "project.yaml"), "--no-write", "-q"]) == 2
    err = capsys.readouterr().err
    assert "project.yaml:11:16" in err and "cannot read the setpoint table" in err
