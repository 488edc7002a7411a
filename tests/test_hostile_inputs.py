"""Hostile and broken inputs, table-driven: each case edits a copy of the tiny CLI fixture project
(or the command line), runs `mpgspec verify`, and checks the exit code and the shape of the
message. No case may produce a traceback or an internal error, and no case may echo the content
of a file outside the project.

Kinds: yaml (the document itself), schema (keys, types, ranges), expr (safety functions, laws),
files (paths a spec names), output (where and how reports are written), cli (options), numeric
(values that could make a check pass by accident).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import pytest

from mpgspec.cli import main

TINY = Path(__file__).parent / "fixtures" / "cli_tiny" / "project.yaml"
SECRET = "TOP-SECRET-0xC0FFEE"
BASE = TINY.read_text()


@dataclass
class Case:
    name: str
    kind: str
    edit: Callable[[Path], list] | None  # edits the project folder; returns extra CLI arguments
    rc: int
    shape: str = ""  # regex the output must contain
    extra: list = field(default_factory=list)


def sub(old: str, new: str, count: int = 1):
    """An edit replacing text of project.yaml."""
    def edit(d: Path) -> list:
        text = (d / "project.yaml").read_text()
        assert old in text, old
        (d / "project.yaml").write_text(text.replace(old, new, count))
        return []
    return edit


def whole(text: str):
    def edit(d: Path) -> list:
        (d / "project.yaml").write_text(text)
        return []
    return edit


def with_file(name: str, content: bytes | str, old: str, new: str):
    """Write an extra file next to (or outside) the project, then edit project.yaml to name it."""
    def edit(d: Path) -> list:
        path = (d / name)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        return sub(old, new)(d)
    return edit


def outside_secret(old: str, new_fmt: str):
    """A secret file outside the project folder, named by the spec."""
    def edit(d: Path) -> list:
        secret = d.parent / "outside" / "secret.yaml"
        secret.parent.mkdir(exist_ok=True)
        secret.write_text(f"{SECRET}: 1\nname: {SECRET}\n")
        return sub(old, new_fmt.format(path=secret, rel="../outside/secret.yaml"))(d)
    return edit


def symlink_out(old: str, new: str):
    def edit(d: Path) -> list:
        secret = d.parent / "outside" / "secret.csv"
        secret.parent.mkdir(exist_ok=True)
        secret.write_text(f"t,x\n0,{SECRET}\n")
        (d / "link.csv").symlink_to(secret)
        return sub(old, new)(d)
    return edit


SETPOINT_LEFT = "setpoint: {expr: [0]}"
H_LEFT = 'h: "1.5 - x"'
BILLION_LAUGHS = "a: &a [x,x,x,x,x,x,x,x,x,x]\n" + "".join(
    f"{c}: &{c} [*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))

CASES = [
    # yaml
    Case("empty file", "yaml", whole(""), 2, r"project\.yaml"),
    Case("not a mapping", "yaml", whole("- 1\n- 2\n"), 2, r"project\.yaml:\d+"),
    Case("syntax error", "yaml", whole("project: [unclosed\n"), 2, r"project\.yaml:\d+"),
    Case("tab indentation", "yaml", whole("project: a\n\tsystem: x\n"), 2, r"project\.yaml:\d+"),
    Case("billion laughs", "yaml", whole(BILLION_LAUGHS), 2, r"alias|project\.yaml"),
    Case("deep nesting", "yaml", whole("project: " + "[" * 5000 + "]" * 5000 + "\n"), 2, r"project\.yaml"),
    Case("merge key on a scalar", "yaml", sub("project: tiny", "<<: 5\nproject: tiny"), 2, r"project\.yaml:\d+"),
    Case("duplicate key", "yaml", sub("project: tiny", "project: tiny\nproject: other"), 2, r"project"),
    Case("python tag", "yaml", sub("project: tiny", "project: !!python/object/apply:os.system ['touch /tmp/mpgspec_pwned_marker']"), 2,
         r"project\.yaml:\d+"),
    Case("non-UTF-8 bytes", "yaml", lambda d: ((d / "project.yaml").write_bytes(BASE.encode() + b"\n# \xff\xfe\n"), [])[1],
         2, r"project\.yaml"),
    Case("huge line", "yaml", sub("project: tiny", "project: tiny\ndescription: " + "y" * 2_000_000), 2, r"project\.yaml"),
    # schema
    Case("unknown top-level key", "schema", sub("project: tiny", "project: tiny\nprojekt: x"), 2, r"projekt"),
    Case("primitives is a number", "schema", sub("primitives:\n", "primitives: 5\nignored:\n"), 2, r"primitives"),
    Case("no primitives", "schema", lambda d: ((d / "project.yaml").write_text(
        BASE[:BASE.index("primitives:")] + "primitives: []\n"), [])[1], 2, r"primitives"),
    Case("text field given a list", "schema", sub("project: tiny", "project: tiny\ndescription: [a, b]"), 2,
         r"description"),
    Case("name given a list", "schema", sub("  - name: Left", "  - name: [Left]"), 2, r"name"),
    Case("negative grid", "schema", sub("  accuracy: low", "  accuracy: low\n  grid: {t_A: -1, t_B: 4}"), 2, r"t_A"),
    Case("grid of a million", "schema", sub("  accuracy: low", "  accuracy: low\n  grid: {t_A: 1000000, t_B: 4}"), 2,
         r"t_A"),
    Case("infinite horizon", "schema", sub("horizon: 3.0", "horizon: .inf"), 2, r"horizon"),
    Case("infinite dt", "schema", sub("dt: 0.02", "dt: .inf"), 2, r"dt"),
    Case("NaN dt", "schema", sub("dt: 0.02", "dt: .nan"), 2, r"dt"),
    Case("zero dt", "schema", sub("dt: 0.02", "dt: 0"), 2, r"dt"),
    Case("infinite h tolerance", "schema", sub("  accuracy: low", "  accuracy: low\n  h_tolerance: .inf"), 2,
         r"h_tolerance"),
    Case("horizon over dt too many steps", "schema", sub("dt: 0.02", "dt: 0.0000001"), 2, r"dt|horizon|steps"),
    Case("NaN input bound", "schema", sub("u: [-2, 2]", "u: [.nan, 2]"), 2, r"input_bounds"),
    Case("misspelled roa method", "schema", sub("roa: {radius: 0.05}", "roa: {radius: 0.05, method: lyapnov}"), 2,
         r"lyapunov"),
    Case("unknown verifier option", "schema",
         sub("roa: {radius: 0.05}", "roa: {radius: 0.05, method: sampling, options: {QQ: 1}}"), 2, r"QQ"),
    Case("unknown oracle method", "schema", sub("  accuracy: low", "  accuracy: low\n  method: rk5"), 2, r"rk4|rk5"),
    Case("unknown accuracy", "schema", sub("accuracy: low", "accuracy: ultra"), 2, r"accuracy"),
    Case("edge to an unknown primitive", "schema", sub("edge: {from: Left, to: Mid, class: 1}",
                                                       "edge: {from: Left, to: Middle, class: 1}"), 2, r"Middle"),
    Case("transient next is itself", "schema", sub(
        "  - name: Mid\n    class: fixed", "  - name: Mid\n    class: transient\n    domain: [0, 1]\n    next: Mid"), 2,
        r"next"),
    Case("let shadows a state", "schema", sub("    class: fixed\n    setpoint: {expr: [0]}",
                                               "    class: fixed\n    let: {x: 3}\n    setpoint: {expr: [0]}"), 2,
         r"let|shadow|x"),
    Case("let overrides pi", "schema", sub("    class: fixed\n    setpoint: {expr: [0]}",
                                            "    class: fixed\n    let: {pi: 3}\n    setpoint: {expr: [0]}"), 2,
         r"pi"),
    Case("bad project name ../x", "schema", sub("project: tiny", "project: ../x"), 2, r"project"),
    Case("bad project name /abs", "schema", sub("project: tiny", "project: /tmp/evil"), 2, r"project"),
    Case("empty project name", "schema", sub("project: tiny", "project: ''"), 2, r"project"),
    Case("negative argument value", "schema", sub(
        "  - name: Mid\n    class: fixed\n    setpoint: {expr: [0.6]}",
        "  - name: Mid\n    class: fixed\n    arguments: {a: [-1.0, 0.5]}\n    setpoint: {expr: [a]}"), None, r""),
    # expressions
    Case("boolean safety function", "expr", sub(H_LEFT, "h: true"), 2, r"h"),
    Case("comparison as a safety function", "expr", sub(H_LEFT, 'h: "x < 1.5"'), 2, r"number"),
    Case("unknown name", "expr", sub(H_LEFT, 'h: "1.5 - y"'), 2, r"\by\b"),
    Case("unknown function", "expr", sub(H_LEFT, 'h: "exec(1)"'), 2, r"exec"),
    Case("attribute access", "expr", sub(H_LEFT, 'h: "x.__class__"'), 2, r"project\.yaml:\d+"),
    Case("import attempt", "expr", sub(H_LEFT, 'h: "__import__(\'os\').system(\'touch /tmp/mpgspec_pwned_marker\')"'), 2,
         r"project\.yaml:\d+"),
    Case("unbalanced parentheses", "expr", sub(H_LEFT, 'h: "(1.5 - x"'), 2, r"project\.yaml:\d+"),
    Case("500 nested parentheses", "expr", sub(H_LEFT, 'h: "' + "(" * 500 + "x" + ")" * 500 + '"'), None, r""),
    Case("sum of 1000 terms", "expr", sub(H_LEFT, 'h: "' + "+".join(["x"] * 1000) + '"'), None, r""),
    Case("wrong arity", "expr", sub(H_LEFT, 'h: "sin(x, x)"'), 2, r"sin"),
    Case("setpoint of wrong length", "expr", sub(SETPOINT_LEFT, "setpoint: {expr: [0, 1]}"), 2, r"setpoint"),
    Case("law with a string number", "expr", sub('u: ["-2*(x - x_star)"]', 'u: ["-2*(x - x_star)", "1"]'), 2, r"u"),
    # files
    Case("system file outside the project", "files", outside_secret(
        "system:\n  name: integrator", "system: {path}\nignored:\n  name: integrator"), 2, r"outside|project folder"),
    Case("primitive include with ../", "files", outside_secret(
        "primitives:\n", "primitives:\n  - {rel}\n"), 2, r"project folder|outside"),
    Case("setpoint file /etc/passwd", "files", sub(SETPOINT_LEFT, "setpoint: {file: /etc/passwd}"), 2,
         r"setpoint"),
    Case("setpoint file /proc/self/environ", "files", sub(SETPOINT_LEFT, "setpoint: {file: /proc/self/environ}"), 2,
         r"setpoint"),
    Case("setpoint file /dev/zero", "files", sub(SETPOINT_LEFT, "setpoint: {file: /dev/zero}"), 2, r"setpoint"),
    Case("setpoint file is a directory", "files", with_file("tables/keep", "", SETPOINT_LEFT,
                                                           "setpoint: {file: tables}"), 2, r"setpoint"),
    Case("setpoint file missing", "files", sub(SETPOINT_LEFT, "setpoint: {file: nowhere.csv}"), 2, r"nowhere"),
    Case("setpoint symlink escaping", "files", symlink_out(SETPOINT_LEFT, "setpoint: {file: link.csv}"), 2,
         r"setpoint"),
    Case("setpoint CSV with NaN", "files", with_file("sp.csv", "t,x\n0,nan\n1,0\n", SETPOINT_LEFT,
                                                    "setpoint: {file: sp.csv}"), 2, r"sp\.csv"),
    Case("setpoint CSV not UTF-8", "files", with_file("sp.csv", b"t,x\n0,\xff\n", SETPOINT_LEFT,
                                                     "setpoint: {file: sp.csv}"), 2, r"sp\.csv"),
    Case("setpoint CSV empty", "files", with_file("sp.csv", "", SETPOINT_LEFT, "setpoint: {file: sp.csv}"), 2,
         r"sp\.csv"),
    # output
    Case("--out is a file", "output", lambda d: ((d / "out").write_text("x"), ["--out", str(d / "out")])[1], 2,
         r"out"),
    Case("--out is read-only", "output", lambda d: ((d / "ro").mkdir(), os.chmod(d / "ro", 0o500),
                                                     ["--out", str(d / "ro")])[2], 2, r"ro|permission|write"),
    Case("newline in a message, github format", "output", sub("project: tiny", 'project: tiny\ndescription: "a\\n::error::x"'),
         0, r"PASS", ["--format", "github"]),
    # cli
    Case("--jobs 0", "cli", None, 2, r"jobs", ["-j", "0"]),
    Case("--jobs -3", "cli", None, 2, r"jobs", ["-j", "-3"]),
    Case("--jobs 100000", "cli", None, 2, r"jobs", ["-j", "100000"]),
    Case("unknown backend option", "cli", None, 2, r"rk5|method", ["--method", "rk5"]),
    Case("unknown format", "cli", None, 2, r"format", ["--format", "xml"]),
    # numeric
    Case("stiff loop is not a safety violation", "numeric", sub(
        'u: ["-2*(x - x_star)"]', 'u: ["-100000*(x - x_star)"]'), None, r"", ["--format", "json"]),
]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hostile_input(case: Case, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MPGSPEC_SECRET_PROBE", SECRET)
    d = tmp_path / "proj"
    d.mkdir()
    (d / "project.yaml").write_text(BASE)
    extra = case.edit(d) if case.edit else []
    argv = ["verify", str(d), "--no-cache", "-q", *extra, *case.extra]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "reports")]
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as err:  # argparse usage errors
        rc = err.code
    out, err = capsys.readouterr()
    text = out + err
    assert "Traceback" not in text and "MPG900" not in text and "internal error" not in text, text[-2000:]
    assert SECRET not in text  # neither a file outside the project nor the environment is echoed
    assert not Path("/tmp/mpgspec_pwned_marker").exists()  # nothing in a spec is executed
    if "json" in case.extra:  # stdout is one compact JSON document: no string in it may echo a long line
        def strings(v):
            if isinstance(v, str):
                yield v
            elif isinstance(v, dict):
                for k, x in v.items():
                    yield k
                    yield from strings(x)
            elif isinstance(v, list):
                for x in v:
                    yield from strings(x)
        import json

        assert max(map(len, strings(json.loads(out))), default=0) < 5000, "a long input line was echoed in full"
        text = err
    assert len(max(text.splitlines() or [""], key=len)) < 5000, "a long input line was echoed in full"
    if case.rc is not None:
        assert rc == case.rc, text[-2000:]
    else:
        assert rc in (0, 1, 2), text[-2000:]
    if case.shape:
        assert re.search(case.shape, text), text[-2000:]
    # nothing is ever written outside --out
    assert not (tmp_path / "x").exists() and not Path("/tmp/evil").exists()


def test_the_table_is_large_enough():
    assert len(CASES) >= 60 and len({c.kind for c in CASES}) == 7
