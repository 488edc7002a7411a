"""Hostile specs from pull requests: paths confined to the project folder, bounded reads, YAML limits.

Every case must end in a located spec error (file:line:col, code, key, expected, found) and no
error text may contain anything of the file a spec points at: a secret string written next to
the project (or an environment variable, for /proc/self/environ) must never show up.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from mpgspec.api import compile_project, verify
from mpgspec.cli import main
from mpgspec.errors import SpecError, SpecErrors
from mpgspec.spec.loader import load_project
from mpgspec.spec.paths import MAX_FILE_BYTES
from mpgspec.spec.yamlpos import MAX_DEPTH, format_context_text

SECRET = "TOPSECRET-7f3a9c"

SYSTEM = """\
name: integrator
kind: analytic
states: [x]
inputs: [u]
dynamics: {f: [0], g: [[1]]}
input_bounds: {u: [-2, 2]}
"""

PRIMITIVE = """\
name: Hold
class: fixed
setpoint: {expr: [0]}
controller: {type: expression, u: ["-2*(x - x_star)"]}
roa: {radius: 0.05}
"""


def project_text(*, name: str = "conf", system: str | None = None, primitives: str | None = None,
                 setpoint: str = "{expr: [0]}") -> str:
    """A small project; `system` / `primitives` replace the inline parts (one line each)."""
    sys_part = f"system: {system}\n" if system is not None else "system:\n" + "".join(
        f"  {ln}\n" for ln in SYSTEM.splitlines())
    if primitives is None:
        primitives = ("\n  - name: Hold\n    class: fixed\n    setpoint: " + setpoint
                      + "\n    controller: {type: expression, u: [\"-2*(x - x_star)\"]}\n    roa: {radius: 0.05}")
    return f"project: {name}\n{sys_part}primitives: {primitives}\n"


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A folder next to the project holding files that contain SECRET."""
    d = tmp_path / "outside"
    d.mkdir()
    (d / "secret.yaml").write_text(f"# {SECRET}\n{SYSTEM}secret: {SECRET}\n")
    (d / "secret.csv").write_text(f"t,x\n0,0\n1,1\n# {SECRET}\n")
    (d / "secret.urdf").write_text(f"<robot name='{SECRET}'/>\n")
    return d


@pytest.fixture
def proj(tmp_path: Path) -> Path:
    d = tmp_path / "proj"
    d.mkdir()
    return d


def write(proj: Path, text: str) -> Path:
    path = proj / "project.yaml"
    path.write_text(text)
    return path


def errors_of(path: Path, **kw) -> list[SpecError]:
    """The errors load_project raises (YAML errors come alone, as a SpecError)."""
    with pytest.raises((SpecErrors, SpecError)) as info:
        load_project(path, **kw)
    return info.value.errors if isinstance(info.value, SpecErrors) else [info.value]


def only_error(path: Path, **kw) -> SpecError:
    errs = errors_of(path, **kw)
    assert len(errs) == 1, [e.format() for e in errs]
    return errs[0]


def assert_no_leak(*texts: str, secret: str = SECRET) -> None:
    for text in texts:
        assert secret not in text
        assert "Traceback" not in text


def line_of(text: str, needle: str) -> int:
    return next(i for i, ln in enumerate(text.splitlines(), start=1) if needle in ln)


def assert_confined(err: SpecError, path: Path, text: str, needle: str, key: str, written: str) -> None:
    """MPG305 at the key naming the file, with the project folder expected and the path as written."""
    assert err.code == "MPG305"
    assert err.location.file == str(path)
    assert err.location.line == line_of(text, needle) and err.location.column > 0
    assert err.key == key
    assert err.expected.startswith("a path inside the project folder ")
    assert str(path.parent.resolve()) in err.expected
    assert err.found == repr(written)
    assert_no_leak(err.format(), str(err.to_dict()))


# ----------------------------------------------------------------------------- confinement


def test_absolute_system_path_outside_project(proj, outside):
    target = str(outside / "secret.yaml")
    text = project_text(system=target)
    err = only_error(write(proj, text))
    assert_confined(err, proj / "project.yaml", text, "system:", "system", target)
    assert (err.location.line, err.location.column) == (2, 1)


def test_dotdot_primitive_include(proj, outside):
    text = project_text(primitives="[../outside/secret.yaml]")
    err = only_error(write(proj, text))
    assert_confined(err, proj / "project.yaml", text, "primitives:", "primitives.0", "../outside/secret.yaml")


def test_etc_passwd_as_primitive_include(proj):
    text = project_text(primitives="[/etc/passwd]")
    err = only_error(write(proj, text))
    assert_confined(err, proj / "project.yaml", text, "primitives:", "primitives.0", "/etc/passwd")
    assert_no_leak(err.format(), secret="root:")


def test_symlink_pointing_outside(proj, outside):
    (proj / "system.yaml").symlink_to(outside / "secret.yaml")
    text = project_text(system="system.yaml")
    err = only_error(write(proj, text))
    assert_confined(err, proj / "project.yaml", text, "system:", "system", "system.yaml")


def test_symlinked_project_file_outside(proj, outside):
    (proj / "project.yaml").symlink_to(outside / "secret.yaml")
    err = only_error(proj / "project.yaml")
    assert err.code == "MPG305" and err.location.file == str(proj / "project.yaml")
    assert_no_leak(err.format())


def test_symlink_inside_project_is_fine(proj):
    (proj / "parts").mkdir()
    (proj / "parts" / "real.yaml").write_text(SYSTEM)
    (proj / "system.yaml").symlink_to(proj / "parts" / "real.yaml")
    spec = load_project(write(proj, project_text(system="system.yaml")))
    assert spec.system.name == "integrator"


def test_allow_paths_admits_an_outside_folder(proj, outside):
    (outside / "ok.yaml").write_text(SYSTEM)
    path = write(proj, project_text(system=str(outside / "ok.yaml")))
    assert only_error(path).code == "MPG305"
    spec = load_project(path, allow_paths=[outside])
    assert spec.system.name == "integrator" and outside.resolve() in spec.roots


def test_allow_paths_through_the_api(proj, outside):
    (outside / "ok.yaml").write_text(SYSTEM)
    path = write(proj, project_text(system=str(outside / "ok.yaml")))
    res = verify([path], out_dir=None)
    assert res.exit_code == 2 and res.projects[0].errors[0]["code"] == "MPG305"
    res = verify([path], out_dir=None, allow_paths=[str(outside)])
    assert all(e.get("code") != "MPG305" for e in res.projects[0].errors)


def test_setpoint_file_proc_self_environ_does_not_leak(proj, monkeypatch, capsys):
    monkeypatch.setenv("MPG_CONF_SECRET", SECRET)
    text = project_text(setpoint="{file: /proc/self/environ}")
    path = write(proj, text)
    err = only_error(path)
    assert_confined(err, path, text, "file:", "primitive 'Hold': setpoint.file", "/proc/self/environ")
    assert main(["verify", str(path), "--no-write", "-q"]) == 2
    out, errtext = capsys.readouterr()
    assert "MPG305" in errtext
    assert_no_leak(out, errtext)


def test_setpoint_file_dotdot(proj, outside):
    text = project_text(setpoint="{file: ../outside/secret.csv}")
    path = write(proj, text)
    err = only_error(path)
    assert_confined(err, path, text, "file:", "primitive 'Hold': setpoint.file", "../outside/secret.csv")


@pytest.mark.parametrize("urdf", ["share:../../outside/secret.urdf", "share:..", "share:/etc/passwd",
                                  "share:example-robot-data/../../../../../../etc/passwd"])
def test_share_paths_stay_in_the_package_data_folder(proj, outside, urdf):
    text = (f"project: rb\nsystem:\n  kind: rigid_body\n  name: r\n  urdf: '{urdf}'\n"
            f"primitives: [{{name: A, class: fixed, setpoint: {{expr: [0]}}, controller: {{type: expression, "
            f"u: []}}, roa: {{radius: 0.1}}}}]\n")
    path = write(proj, text)
    err = only_error(path)
    assert err.code == "MPG305" and err.key == "system.urdf"
    assert err.location == type(err.location)(str(path), 5, 3)
    assert err.found == repr(urdf)
    assert_no_leak(err.format(), secret="root:")
    assert_no_leak(err.format())


def test_urdf_outside_project(proj, outside):
    target = str(outside / "secret.urdf")
    text = f"project: rb\nsystem:\n  kind: rigid_body\n  name: r\n  urdf: {target}\nprimitives: [p.yaml]\n"
    (proj / "p.yaml").write_text(PRIMITIVE)
    path = write(proj, text)
    err = only_error(path)
    assert_confined(err, path, text, "urdf:", "system.urdf", target)


# ----------------------------------------------------------------------------- bounded reads


def test_directory_as_included_file(proj):
    (proj / "sub").mkdir()
    text = project_text(system="sub")
    err = only_error(write(proj, text))
    assert err.code == "MPG301" and err.location.line == 2 and "directory" in err.message


def test_dev_zero_returns_quickly(proj):
    t0 = time.perf_counter()
    text = project_text(system="/dev/zero")
    path = write(proj, text)
    assert only_error(path).code == "MPG305"
    err = only_error(path, allow_paths=["/dev"])  # allowed, but not a regular file
    assert err.code == "MPG301" and "not a regular file" in err.message and err.location.line == 2
    spec = load_project(write(proj, project_text(setpoint="{file: /dev/zero}")), allow_paths=["/dev"])
    with pytest.raises(SpecError) as info:
        compile_project(spec)
    assert info.value.code == "MPG110" and "not a regular file" in info.value.message
    assert time.perf_counter() - t0 < 2.0


def test_too_large_included_file(proj):
    with open(proj / "big.yaml", "wb") as f:
        f.write(b"#" * (MAX_FILE_BYTES + 1))
    text = project_text(primitives="[big.yaml]")
    err = only_error(write(proj, text))
    assert err.code == "MPG301" and "too large" in err.message and err.key == "primitives.0"
    assert f"{MAX_FILE_BYTES} bytes" in err.expected and err.location.line == line_of(text, "primitives:")


def test_empty_included_file(proj):
    (proj / "empty.yaml").write_text("")
    text = project_text(primitives="[empty.yaml]")
    err = only_error(write(proj, text))
    assert err.code == "MPG301" and "empty" in err.message and err.location.line == line_of(text, "primitives:")


def test_non_utf8_included_file(proj):
    (proj / "bin.yaml").write_bytes(b"name: \xff\xfe" + SECRET.encode())
    err = only_error(write(proj, project_text(system="bin.yaml")))
    assert err.code == "MPG301" and "UTF-8" in err.message
    assert_no_leak(err.format())


CSV_PROJECT = project_text(setpoint="{file: table.csv}")
SETPOINT_LINE = line_of(CSV_PROJECT, "setpoint:")


def _csv_error(proj: Path, data: bytes) -> SpecError:
    (proj / "table.csv").write_bytes(data)
    spec = load_project(write(proj, CSV_PROJECT))
    with pytest.raises(SpecError) as info:
        compile_project(spec)
    assert info.value.code == "MPG110"
    return info.value


def test_non_utf8_csv(proj):
    err = _csv_error(proj, b"t,x\n0,0\n1,\xff\n")
    assert "UTF-8" in err.message and err.location.line == SETPOINT_LINE  # the key naming the file
    assert err.location.file == str(proj / "project.yaml")


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e400"])
def test_csv_with_non_finite_values(proj, value):
    err = _csv_error(proj, f"t,x\n0,0\n1,{value}\n2,0\n".encode())
    assert "finite" in err.message
    assert err.location.file.endswith("table.csv") and err.location.line == 3


def test_empty_csv(proj):
    err = _csv_error(proj, b"")
    assert "empty" in err.message and err.location.line == SETPOINT_LINE


# ----------------------------------------------------------------------------- YAML limits


def test_billion_laughs_fails_fast(proj):
    lines = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, 10):
        prev, cur = chr(ord("a") + i - 1), chr(ord("a") + i)
        lines.append(f"{cur}: &{cur} [" + ",".join([f"*{prev}"] * 9) + "]")
    text = "project: laughs\n" + "\n".join(lines) + "\n" + project_text().split("\n", 1)[1]
    path = write(proj, text)
    t0 = time.perf_counter()
    err = only_error(path)
    assert time.perf_counter() - t0 < 2.0
    assert err.code == "MPG100" and "expand to too many nodes" in err.message
    assert err.location.file == str(path) and err.location.line > 0


def test_merge_key_doubling_fails_fast(proj):
    lines = ["m0: &m0 {x: 1}"] + [f"m{i}: &m{i} {{<<: [*m{i - 1}, *m{i - 1}]}}" for i in range(1, 60)]
    path = write(proj, "\n".join(lines) + "\n" + project_text())
    t0 = time.perf_counter()
    err = only_error(path)
    assert time.perf_counter() - t0 < 2.0
    assert err.code == "MPG100" and err.location.line > 0


def test_deep_nesting(proj):
    depth = 5 * MAX_DEPTH
    path = write(proj, project_text() + "deep: " + "[" * depth + "]" * depth + "\n")
    err = only_error(path)
    assert err.code == "MPG100" and "nesting deeper than" in err.message
    assert err.location.line == line_of(path.read_text(), "deep:") and err.location.column > 0


def test_merge_key_on_a_scalar(proj):
    text = project_text() + "oracle:\n  <<: 5\n"
    err = only_error(write(proj, text))
    assert err.code == "MPG100" and "merge key" in err.message
    assert (err.location.line, err.location.column) == (line_of(text, "<<"), 3)


def test_primitives_not_a_list(proj):
    text = project_text(primitives="5")
    err = only_error(write(proj, text))
    assert err.code == "MPG104" and err.key == "primitives" and err.found == "int"
    assert (err.location.line, err.location.column) == (line_of(text, "primitives:"), 1)


def test_included_system_file_as_primitive_echoes_no_long_lines(proj, capsys):
    long_value = "x" * 5000 + SECRET
    (proj / "sys.yaml").write_text(SYSTEM + f"description_of_robot_{'y' * 900}: {long_value}\n")
    path = write(proj, project_text(primitives="[sys.yaml]"))
    errs = errors_of(path)
    assert errs and all(e.code in ("MPG102", "MPG103", "MPG104") for e in errs)
    assert all(len(e.found) <= 200 and len(e.key) <= 200 for e in errs)
    assert main(["verify", str(path), "--no-write", "-q"]) == 2
    out, err = capsys.readouterr()
    assert all(len(ln) < 700 for ln in err.splitlines()), max(len(ln) for ln in err.splitlines())
    assert_no_leak(out, err)


def test_context_lines_are_cut():
    text = "a: 1\nb: " + "z" * 1000 + SECRET + "\n"
    ctx = format_context_text(text, 2, 3)
    assert all(len(ln) <= 220 for ln in ctx.splitlines()) and "…" in ctx and SECRET not in ctx
    ctx = format_context_text(text, 2, 1000)  # the caret stays under the column
    caret = next(ln for ln in ctx.splitlines() if ln.rstrip().endswith("^"))
    assert all(len(ln) <= 220 for ln in ctx.splitlines())
    assert ctx.splitlines()[1][caret.index("^")] == "z"


# ----------------------------------------------------------------------------- project names


@pytest.mark.parametrize("name", ["'../x'", "''", "/abs", "a/b", ".hidden", "'..'", "a" * 101, "'a b'"])
def test_bad_project_names(proj, name):
    text = project_text(name=name)
    err = only_error(write(proj, text))
    assert err.code == "MPG104" and err.key == "project"
    assert (err.location.line, err.location.column) == (1, 1)
    assert "letters, digits" in err.expected


@pytest.mark.parametrize("name", ["a1", "my-project.v2", "Pendulum_3"])
def test_good_project_names(proj, name):
    assert load_project(write(proj, project_text(name=name))).name == name


def test_cli_error_output_is_located_and_clean(proj, outside, capsys):
    text = project_text(system=str(outside / "secret.yaml"))
    path = write(proj, text)
    assert main(["verify", str(path), "--no-write", "-q"]) == 2
    out, err = capsys.readouterr()
    assert f"{path}:2:1 MPG305 system: path outside the project folder" in err
    assert_no_leak(out, err)
    assert os.path.exists(outside / "secret.yaml")


def test_overlong_value_is_a_located_error(proj, capsys):
    from mpgspec.spec.yamlpos import MAX_SCALAR

    text = project_text() + "description: " + "y" * (MAX_SCALAR + 1) + SECRET + "\n"
    path = write(proj, text)
    err = only_error(path)
    assert err.code == "MPG100" and "too long" in err.message
    assert (err.location.line, err.location.column) == (line_of(text, "description:"), 14)
    assert main(["verify", str(path), "--no-write", "-q"]) == 2
    out, errtext = capsys.readouterr()
    assert_no_leak(out, errtext)
    assert max(len(ln) for ln in errtext.splitlines()) < 400


# ----------------------------------------------------------------------------- allowed folders quote nothing


def cli(capfd, *argv) -> tuple[int, str]:
    """Exit code and everything written to stdout and stderr, also by native code (fd level)."""
    rc = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    return rc, out + err


def _csv_header(outside: Path) -> str:
    (outside / "header.csv").write_text(f"t,{SECRET}\n0,0\n1,0\n")
    return project_text(setpoint=f"{{file: {outside / 'header.csv'}}}")


def _csv_row(outside: Path) -> str:
    (outside / "row.csv").write_text(f"t,x\n0,0\n1,{SECRET}\n")
    return project_text(setpoint=f"{{file: {outside / 'row.csv'}}}")


def _system_value(outside: Path) -> str:
    (outside / "kind.yaml").write_text(SYSTEM.replace("kind: analytic", f"kind: {SECRET}"))
    return project_text(system=str(outside / "kind.yaml"))


def _system_alias(outside: Path) -> str:
    (outside / "alias.yaml").write_text(f"name: *{SECRET}\n")
    return project_text(system=str(outside / "alias.yaml"))


def _system_nul(outside: Path) -> str:
    (outside / "environ").write_bytes(f"TOKEN={SECRET}\0HOME=/root\0".encode())
    return project_text(system=str(outside / "environ"))


def _primitive_duplicate_key(outside: Path) -> str:
    (outside / "dup.yaml").write_text(f"{PRIMITIVE}{SECRET}: 1\n{SECRET}: 2\n")
    return project_text(primitives=f"[{outside / 'dup.yaml'}]")


def _urdf(outside: Path) -> str:
    (outside / "joint.urdf").write_text(
        f"<robot name='r'><link name='base'/><joint name='{SECRET}' type='revolute'><parent link='x'/>"
        "<child link='base'/><axis xyz='0 0 1'/></joint></robot>\n")
    return (f"project: rb\nsystem:\n  kind: rigid_body\n  name: r\n  urdf: {outside / 'joint.urdf'}\n"
            f"  floating_base: false\nprimitives: [{{name: A, class: fixed, setpoint: {{expr: [0]}}, "
            f"controller: {{type: expression, u: []}}, roa: {{radius: 0.1}}}}]\n")


ALLOWED_FILES = {"csv header": (_csv_header, "MPG110"), "csv row": (_csv_row, "MPG110"),
                 "system value": (_system_value, "MPG104"), "undefined alias": (_system_alias, "MPG100"),
                 "NUL bytes (an environ file)": (_system_nul, "MPG100"),
                 "duplicate key": (_primitive_duplicate_key, "MPG101"), "urdf parser message": (_urdf, "MPG109")}


@pytest.mark.parametrize("case", sorted(ALLOWED_FILES))
def test_errors_about_an_allowed_file_quote_none_of_it(proj, outside, capfd, case):
    """--allow-path admits a file, never its content into a message, its lines as context, nor
    the messages of a native parser reading it."""
    make, code = ALLOWED_FILES[case]
    path = write(proj, make(outside))
    rc, text = cli(capfd, "verify", path, "--no-write", "-q", "--no-cache", "--allow-path", outside)
    assert rc == 2 and code in text, text
    assert_no_leak(text)
    assert "MPG900" not in text
    lines = text.splitlines()
    for line, after in zip(lines, lines[1:]):  # an error located in the outside file shows no lines of it
        assert not (line.startswith(str(outside.resolve())) and " | " in after), text


def test_an_allowed_csv_is_located_in_it_without_its_content(proj, outside):
    spec = load_project(write(proj, _csv_row(outside)), allow_paths=[outside])
    with pytest.raises(SpecError) as info:
        compile_project(spec)
    err = info.value
    assert (err.location.file, err.location.line) == (str((outside / "row.csv").resolve()), 3)
    assert not err.location.quote and not err.to_dict()["quote"]
    assert err.key == "primitive 'Hold': setpoint.file" and "not shown" in err.found
    assert_no_leak(err.format(), str(err.to_dict()))


def test_a_csv_inside_the_project_is_still_quoted(proj):
    err = _csv_error(proj, b"t,x\n0,0\n1,abc\n")
    assert err.location.quote and "abc" in err.found


@pytest.mark.parametrize("where", ["setpoint", "system"])
def test_proc_self_environ_with_allow_path_proc_does_not_leak(proj, where):
    """The reviewer's case: a secret in the environment of `mpgspec verify --allow-path /proc`."""
    import subprocess
    import sys

    text = project_text(setpoint="{file: /proc/self/environ}") if where == "setpoint" else \
        project_text(system="/proc/self/environ")
    path = write(proj, text)
    env = {**os.environ, "MPG_CONF_SECRET": SECRET}
    run = subprocess.run([sys.executable, "-m", "mpgspec", "verify", str(path), "--no-write", "-q", "--no-cache",
                          "--allow-path", "/proc"], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr
    assert_no_leak(run.stdout, run.stderr)
    assert "MPG110" in run.stderr if where == "setpoint" else "MPG100" in run.stderr


# ----------------------------------------------------------------------------- gait files


PENDULUM = Path(__file__).parents[2] / "specs" / "pendulum"


@pytest.fixture
def pendulum(tmp_path: Path) -> Path:
    import shutil

    shutil.copytree(PENDULUM, tmp_path / "pendulum")
    return tmp_path / "pendulum"


def gait_file(folder: Path, project: str) -> Path:
    path = folder / "gaits.yaml"
    path.write_text(f"project: {project}\nprimitive: Walk\ndt: 0.001\n")
    return path


def test_gait_project_etc_passwd_is_refused(pendulum, capfd):
    from mpgspec.robots.quadruped.gait.library import generate

    gaits = gait_file(pendulum, "../../../../../../../../etc/passwd")
    with pytest.raises(SpecError) as info:
        generate(gaits, progress=lambda m: None)
    err = info.value
    assert err.code == "MPG305" and err.key == "project" and err.found == repr("../../../../../../../../etc/passwd")
    assert (err.location.file, err.location.line, err.location.column) == (str(gaits), 1, 10)
    assert str(pendulum.resolve()) in err.expected
    rc, text = cli(capfd, "gait", gaits, "-q")
    assert rc == 2 and f"{gaits}:1:10 MPG305 project: path outside the project folder" in text
    assert_no_leak(text, secret="root:")


def test_gait_project_symlink_outside_is_refused(pendulum, outside, capfd):
    (pendulum / "elsewhere.yaml").symlink_to(outside / "secret.yaml")
    gaits = gait_file(pendulum, "elsewhere.yaml")
    rc, text = cli(capfd, "gait", gaits, "-q")
    assert rc == 2 and f"{gaits}:1:10 MPG305" in text
    assert_no_leak(text)


def test_gait_project_in_an_allowed_folder_is_read_but_not_quoted(pendulum, outside, capfd):
    gaits = gait_file(pendulum, str(outside / "secret.yaml"))
    rc, text = cli(capfd, "gait", gaits, "-q")
    assert rc == 2 and "MPG305" in text
    rc, text = cli(capfd, "gait", gaits, "-q", "--allow-path", outside)
    assert rc == 2 and "MPG305" not in text and "secret.yaml" in text
    assert_no_leak(text)
