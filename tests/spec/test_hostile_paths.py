"""Smaller findings of the hostile-input review, each a located error (file:line, key, expected,
found) with exit code 2 and no traceback: gait errors in the gait file (not `<string>`), a setpoint
column named twice, non-UTF-8 spec files placed by line and column, a project without primitives,
and an included system file that holds no mapping.

Each case edits a tmp_path copy of specs/pendulum (the smallest example) or of the tiny CLI fixture.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from mpgspec.api import compile_project
from mpgspec.cli import main
from mpgspec.errors import SpecError, SpecErrors
from mpgspec.robots.quadruped.gait.library import generate
from mpgspec.spec.loader import load_project

ROOT = Path(__file__).parents[2]
PENDULUM = ROOT / "specs" / "pendulum"
TINY = ROOT / "tests" / "fixtures" / "cli_tiny" / "project.yaml"


@pytest.fixture
def pendulum(tmp_path: Path) -> Path:
    shutil.copytree(PENDULUM, tmp_path / "pendulum")
    return tmp_path / "pendulum"


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    d = tmp_path / "tiny"
    d.mkdir()
    shutil.copy(TINY, d / "project.yaml")
    return d / "project.yaml"


def cli(capsys, *argv) -> tuple[int, str]:
    """Exit code and stdout + stderr of the command line."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    text = out + err
    assert "Traceback" not in text and "MPG900" not in text, text
    return rc, text


def verify(capsys, project: Path) -> tuple[int, str]:
    return cli(capsys, "verify", project, "--no-write", "-q", "--no-cache")


def only_error(path: Path) -> SpecError:
    with pytest.raises((SpecErrors, SpecError)) as info:
        load_project(path)
    errs = info.value.errors if isinstance(info.value, SpecErrors) else [info.value]
    assert len(errs) == 1, [e.format() for e in errs]
    return errs[0]


def line_of(path: Path, needle: str) -> int:
    return next(i for i, ln in enumerate(path.read_text().splitlines(), start=1) if needle in ln)


# ----------------------------------------------------------------------------- gait files


def write_gaits(folder: Path, text: str) -> Path:
    path = folder / "gaits.yaml"
    path.write_text(text)
    return path


def test_an_unknown_gait_primitive_is_located_in_the_gait_file(pendulum, capsys):
    gaits = write_gaits(pendulum, "project: project.yaml\nprimitive: Nope\ndt: 0.001\n")
    with pytest.raises(SpecError) as info:
        generate(gaits, progress=lambda m: None)
    err = info.value
    assert (err.location.file, err.location.line, err.location.column) == (str(gaits), 2, 12)
    assert err.key == "primitive" and err.found == "Nope" and "controller type trot" in err.expected
    rc, text = cli(capsys, "gait", gaits, "-q")
    assert rc == 2 and f"{gaits}:2:12 MPG104 primitive: no trot primitive" in text
    assert "<string>" not in text


def test_an_invalid_gait_file_value_is_located(pendulum, capsys):
    gaits = write_gaits(pendulum, "project: project.yaml\nprimitive: Walk\ndt: -1\n")
    rc, text = cli(capsys, "gait", gaits, "-q")
    assert rc == 2 and f"{gaits}:3:1 MPG104 dt: invalid gait file" in text


def test_a_non_utf8_gait_file_is_placed_by_line_and_column(pendulum, capsys):
    gaits = pendulum / "gaits.yaml"
    gaits.write_bytes(b"project: project.yaml\nprimitive: W\xffalk\n")
    rc, text = cli(capsys, "gait", gaits, "-q")
    assert rc == 2 and f"{gaits}:2:13 MPG100 gait file: file is not UTF-8 text;" in text
    assert "byte 0xff at line 2, column 13" in text


# ----------------------------------------------------------------------------- setpoint tables


def hang_from_table(pendulum: Path, table: str) -> Path:
    """The pendulum's Hang with its setpoint read from primitives/hang.csv holding `table`."""
    (pendulum / "primitives" / "hang.csv").write_text(table)
    hang = pendulum / "primitives" / "hang.yaml"
    hang.write_text(hang.read_text().replace("setpoint: {expr: [0, 0]}", "setpoint: {file: hang.csv}"))
    return pendulum / "project.yaml"


def test_a_setpoint_column_named_twice_is_refused(pendulum, capsys):
    project = hang_from_table(pendulum, "t,theta,theta\n0,0,0\n1,0,0.5\n")
    with pytest.raises(SpecError) as info:
        compile_project(load_project(project))
    err = info.value
    table = str((pendulum / "primitives" / "hang.csv").resolve())
    assert err.code == "MPG110" and (err.location.file, err.location.line) == (table, 1)
    assert err.key == "primitive 'Hang': setpoint.file"
    assert err.expected == "each state in one column at most" and err.found == "'theta' in columns 2 and 3"
    rc, text = verify(capsys, project)
    assert rc == 2 and f"{table}:1:1 MPG110 primitive 'Hang': setpoint.file: a column is named twice" in text


def test_distinct_setpoint_columns_are_accepted(pendulum):
    project = hang_from_table(pendulum, "t,theta,omega\n0,0,0\n1,0,0\n")
    compile_project(load_project(project))


def test_a_non_utf8_setpoint_table_is_placed_by_line_and_column(pendulum):
    project = hang_from_table(pendulum, "")
    (pendulum / "primitives" / "hang.csv").write_bytes(b"t,theta\n0,0\n1,\xff\n")
    with pytest.raises(SpecError) as info:
        compile_project(load_project(project))
    err = info.value
    hang = pendulum / "primitives" / "hang.yaml"
    assert err.code == "MPG110" and (err.location.file, err.location.line) == (str(hang), line_of(hang, "setpoint:"))
    assert "byte 0xff at line 3, column 3, byte offset 14" in err.found


# ----------------------------------------------------------------------------- project files


def test_a_non_utf8_project_file_is_placed_by_line_and_column(tiny, capsys):
    lines = tiny.read_text().splitlines(keepends=True)
    lines[5] = "sys\xe9m:\n"  # written as Latin-1 below: é is byte 0xe9 at line 6, column 4
    tiny.write_bytes("".join(lines).encode("latin-1"))
    err = only_error(tiny)
    assert err.code == "MPG100" and (err.location.file, err.location.line, err.location.column) == (str(tiny), 6, 4)
    assert err.key == "project file" and err.expected == "UTF-8 text" and "line 6, column 4" in err.found
    rc, text = verify(capsys, tiny)
    assert rc == 2 and f"{tiny}:6:4 MPG100 project file: file is not UTF-8 text" in text


def test_a_non_utf8_included_file_is_placed_by_line_and_column(pendulum, capsys):
    (pendulum / "system.yaml").write_bytes(b"name: pendulum\nkind: analytic\nstates: [th\xc3\xa9ta, \xffomega]\n")
    project = pendulum / "project.yaml"
    err = only_error(project)
    assert err.code == "MPG301" and err.key == "system" and err.location.line == line_of(project, "system:")
    assert "byte 0xff at line 3, column 17" in err.found  # columns count characters (é is one)
    rc, text = verify(capsys, project)
    assert rc == 2 and "line 3, column 17" in text


def test_a_project_without_primitives_names_the_project_file(tiny, capsys):
    text = tiny.read_text()
    start, end = text.index("primitives:\n"), text.index("oracle:\n")
    tiny.write_text(text[:start] + text[end:])
    err = only_error(tiny)
    assert err.code == "MPG103" and err.key == "primitives" and err.message == "required key is missing"
    assert err.location.file == str(tiny) and err.location.line > 0
    assert "list of primitive" in err.expected and "project file" in err.found
    rc, out = verify(capsys, tiny)
    assert rc == 2 and f"{tiny}:{err.location.line}:{err.location.column} MPG103 primitives: required key" in out


def test_primitives_null_is_not_an_empty_list(tiny):
    text = tiny.read_text()
    start, end = text.index("primitives:\n"), text.index("oracle:\n")
    tiny.write_text(text[:start] + "primitives:\n" + text[end:])
    err = only_error(tiny)
    assert err.code == "MPG104" and err.key == "primitives" and err.found == "null"
    assert (err.location.file, err.location.line) == (str(tiny), line_of(tiny, "primitives:"))


def test_an_included_system_file_holding_a_string(pendulum, capsys):
    (pendulum / "system.yaml").write_text("just some text\n")
    project = pendulum / "project.yaml"
    err = only_error(project)
    assert err.code == "MPG104" and err.key == "system" and err.found == "str"
    assert (err.location.file, err.location.line) == (str(project), line_of(project, "system:"))
    rc, text = verify(capsys, project)
    assert rc == 2 and "an included system file must hold a mapping" in text
