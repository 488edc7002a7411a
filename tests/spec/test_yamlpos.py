"""YAML loading with source positions, duplicate keys and syntax errors."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from mpgspec.errors import Location, SpecError, UsageError
from mpgspec.spec.yamlpos import format_context, format_context_text, format_path, load_yaml

SPEC = """\
robot:
  name: r1
  mass: 1.5
  limits:
    v_max: 2
prims:
  - name: walk
    guard: "x > 1 +"
    dt: 1e-3
  - name: run
    dyn: |
      x +
        y $ z
  -   plain: a + ) b
"""


@pytest.fixture()
def loaded():
    return load_yaml(SPEC, filename="spec.yaml")


def test_data_is_plain(loaded) -> None:
    data, _ = loaded
    assert data == {
        "robot": {"name": "r1", "mass": 1.5, "limits": {"v_max": 2}},
        "prims": [{"name": "walk", "guard": "x > 1 +", "dt": 0.001},
                  {"name": "run", "dyn": "x +\n  y $ z\n"}, {"plain": "a + ) b"}],
    }
    assert type(data) is dict and type(data["prims"]) is list


@pytest.mark.parametrize("path, line, column", [
    ((), 1, 1),
    (("robot",), 1, 1),
    (("robot", "mass"), 3, 3),
    (("robot", "limits", "v_max"), 5, 5),
    (("prims", 0), 7, 5),
    (("prims", 0, "guard"), 8, 5),
    (("prims", 1, "dyn"), 11, 5),
    (("prims", 2), 14, 7),
    (("robot", "missing"), 1, 1),  # missing key: the parent's key
    (("robot", "limits", "missing", "deeper"), 4, 3),
    (("prims", 9, "name"), 6, 1),
    (("nothing",), 1, 1),
])
def test_locate(loaded, path, line, column) -> None:
    _, positions = loaded
    assert positions.locate(path) == Location("spec.yaml", line, column)


@pytest.mark.parametrize("path, line, column", [
    (("robot",), 2, 3),
    (("robot", "mass"), 3, 9),
    (("prims", 0, "guard"), 8, 12),
    (("prims", 1, "dyn"), 11, 10),
    (("robot", "missing"), 1, 1),
])
def test_locate_value(loaded, path, line, column) -> None:
    _, positions = loaded
    assert positions.locate_value(path) == Location("spec.yaml", line, column)


def test_locate_in_value(loaded) -> None:
    _, positions = loaded
    assert positions.locate_in_value(("prims", 0, "guard"), 6) == Location("spec.yaml", 8, 19)
    assert positions.locate_in_value(("prims", 2, "plain"), 4) == Location("spec.yaml", 14, 18)
    assert positions.locate_in_value(("prims", 1, "dyn"), 10) == Location("spec.yaml", 13, 13)
    assert positions.locate_in_value(("prims", 1, "dyn"), 0) == Location("spec.yaml", 12, 7)
    assert positions.locate_in_value(("robot", "nope"), 3) == Location("spec.yaml", 1, 1)


def test_contains(loaded) -> None:
    _, positions = loaded
    assert ("prims", 1, "dyn") in positions and ("prims", 1, "x") not in positions


def test_duplicate_key() -> None:
    with pytest.raises(SpecError) as info:
        load_yaml("a: 1\nb:\n  c: 1\n  d: 2\n  c: 3\n", filename="d.yaml")
    err = info.value
    assert err.code == "MPG101"
    assert err.location == Location("d.yaml", 5, 3)
    assert err.key == "b.c" and "line 3" in err.hint


def test_duplicate_key_in_flow_mapping_and_list() -> None:
    with pytest.raises(SpecError) as info:
        load_yaml("items:\n  - {x: 1, x: 2}\n")
    assert info.value.code == "MPG101" and info.value.key == "items[0].x"
    assert (info.value.location.line, info.value.location.column) == (2, 12)


def test_merge_keys_are_not_duplicates() -> None:
    data, positions = load_yaml("base: &b {k: 1, j: 2}\nder:\n  <<: *b\n  k: 5\n")
    assert data["der"] == {"k": 5, "j": 2}
    assert positions.locate(("der", "k")).line == 4


@pytest.mark.parametrize("text, line, column, words", [
    ("a: [1, 2\nb: 3\n", 2, 2, "expected ',' or ']'"),
    ("a: b: c\n", 1, 5, "mapping values are not allowed"),
    ("a:\n\t- 1\n", 2, 1, "'\\t'"),
    ("a: 'unclosed\n", 2, 1, "unexpected end of stream"),
    ("--- 1\n--- 2\n", 2, 1, "expected a single document"),
])
def test_syntax_errors(text, line, column, words) -> None:
    with pytest.raises(SpecError) as info:
        load_yaml(text, filename="bad.yaml")
    err = info.value
    assert err.code == "MPG100"
    assert err.location == Location("bad.yaml", line, column)
    assert words in err.message
    assert f"> {line} |" in err.context


def test_tab_hint() -> None:
    with pytest.raises(SpecError) as info:
        load_yaml("a:\n\t- 1\n")
    assert "tabs" in info.value.hint


@pytest.mark.parametrize("text, value", [
    ("1e-3", 0.001), ("-2.5E2", -250.0), ("1.", 1.0), (".5", 0.5), ("7", 7), ("-3", -3),
    ("0x1F", 31), ("0o17", 15), ("012", 12), ("true", True), ("False", False), ("on", "on"),
    ("yes", "yes"), ("~", None), ("null", None), ("", None), ("1:30", "1:30"),
    ("2024-01-01", "2024-01-01"), ("'1.5'", "1.5"), ("!!float 2", 2.0), ("!!str 2", "2"),
    ("1_000", "1_000"),
])
def test_scalar_schema(text, value) -> None:
    data, _ = load_yaml(f"v: {text}\n")
    assert data["v"] == value and type(data["v"]) is type(value)


def test_special_floats() -> None:
    data, _ = load_yaml("a: .inf\nb: -.Inf\nc: .nan\n")
    assert data["a"] == math.inf and data["b"] == -math.inf and math.isnan(data["c"])


@pytest.mark.parametrize("text, words", [
    ("a: !!python/object:os.system x\n", "unsupported YAML tag"),
    ("a: !custom {b: 1}\n", "unsupported YAML tag"),
    ("a: !!int abc\n", "invalid !!int"),
    ("? [a, b]\n: 1\n", "mapping keys must be plain values"),
    ("a: &x [1, *x]\n", "recursive"),
])
def test_unsafe_or_unsupported(text, words) -> None:
    with pytest.raises(SpecError) as info:
        load_yaml(text)
    assert info.value.code == "MPG100" and words in info.value.message


def test_empty_document() -> None:
    data, positions = load_yaml("# nothing\n")
    assert data is None and positions.locate(("a",)) == Location("<string>")


def test_load_from_path(tmp_path: Path) -> None:
    path = tmp_path / "spec.yaml"
    path.write_text(SPEC)
    for source in (path, str(path)):
        data, positions = load_yaml(source)
        assert data["robot"]["mass"] == 1.5
        assert positions.locate(("robot", "mass")) == Location(str(path), 3, 3)
    _, positions = load_yaml(path, filename="nice.yaml")
    assert positions.file == "nice.yaml"


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(UsageError):
        load_yaml(tmp_path / "nope.yaml")
    with pytest.raises(UsageError):
        load_yaml(str(tmp_path / "nope.yml"))


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "bin.yaml"
    path.write_bytes(b"a: \xff\xfe\n")
    with pytest.raises(SpecError) as info:
        load_yaml(path)
    assert info.value.code == "MPG100" and "UTF-8" in info.value.message


def test_format_path() -> None:
    assert format_path(("prims", 0, "guard")) == "prims[0].guard"
    assert format_path(()) == ""


def test_format_context(tmp_path: Path) -> None:
    path = tmp_path / "spec.yaml"
    path.write_text(SPEC)
    text = format_context(path, 8, column=19)
    assert text.splitlines() == [
        "   6 | prims:",
        "   7 |   - name: walk",
        ">  8 |     guard: \"x > 1 +\"",
        "     |                   ^",
        "   9 |     dt: 1e-3",
        "  10 |   - name: run",
    ]
    assert format_context(path, 1, radius=0) == "> 1 | robot:"
    assert format_context(tmp_path / "missing.yaml", 1) == ""
    assert format_context_text("a\nb\n", 99) == ""
