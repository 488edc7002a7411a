"""Table-driven invalid specs: every case of invalid_cases.yaml must fail `mpgspec verify` cleanly.

Each case is a whole single-file project (inline system and primitives). It is written to
tmp_path/project.yaml and run through the real CLI entry (`mpgspec.cli.main`); the run must exit
with 2, print `project.yaml:LINE:COLUMN CODE ... message` on stderr and never a traceback.

A case may carry `location_bug: <reason>`: its location test is then a strict xfail, for a known
package bug that puts the error on the wrong line (none at the moment).

Known package bug (mpgspec/spec/loader.py, `_validation_errors`): for an inline system or primitive
(the `Union[str, Model]` fields of Project), pydantic also reports the failed `str` branch, so every
mistake in them comes with a spurious `MPG104 system.str: Input should be a valid string`
(test_one_clean_error_for_one_mistake).
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from mpgspec.cli import main

CASES_FILE = Path(__file__).with_name("invalid_cases.yaml")
CASES: list[dict] = yaml.safe_load(CASES_FILE.read_text())

ALL_CODES = {"MPG100", "MPG101", "MPG102", "MPG103", "MPG104", "MPG105", "MPG106", "MPG107", "MPG108",
             "MPG201", "MPG202", "MPG203", "MPG204", "MPG301", "MPG302", "MPG303", "MPG304"}


def pytest_generate_tests(metafunc):
    if "case" in metafunc.fixturenames:
        metafunc.parametrize("case", [pytest.param(c, id=c["id"]) for c in CASES])
    if "located_case" in metafunc.fixturenames:
        params = []
        for c in CASES:
            marks = [pytest.mark.xfail(strict=True, reason=c["location_bug"])] if c.get("location_bug") else []
            params.append(pytest.param(c, id=c["id"], marks=marks))
        metafunc.parametrize("located_case", params)


def run_verify(text: str, tmp_path: Path, capsys) -> tuple[int, Path, str, str]:
    path = tmp_path / "project.yaml"
    path.write_text(text)
    rc = main(["verify", str(path), "--no-write", "-q"])
    out, err = capsys.readouterr()
    return rc, path, out, err


def error_lines(path: Path, err: str) -> list[str]:
    """The one-line error texts (file:line:col CODE ...), without the source context below them."""
    return [ln for ln in err.splitlines() if ln.startswith(f"{path}:")]


def test_case_table_is_well_formed():
    ids = [c["id"] for c in CASES]
    assert len(ids) == len(set(ids)), "case ids must be unique"
    assert len(CASES) >= 25
    for c in CASES:
        assert {"id", "code", "line", "message", "text"} <= set(c), c.get("id")
        assert 1 <= c["line"] <= len(c["text"].splitlines()) + 1, c["id"]
        yaml_ok = c["code"] in ("MPG100", "MPG101")
        if not yaml_ok:  # the text itself must be YAML; the error is in its meaning
            assert isinstance(yaml.safe_load(c["text"]), dict), c["id"]


def test_cases_cover_every_spec_error_code():
    assert {c["code"] for c in CASES} == ALL_CODES


def test_invalid_spec_is_reported(case, tmp_path, capsys):
    rc, path, out, err = run_verify(case["text"], tmp_path, capsys)
    assert rc == 2, out + err
    assert "Traceback" not in out + err
    lines = error_lines(path, err)
    assert lines, f"no file:line error on stderr:\n{err}"
    assert all("project.yaml:" in ln for ln in lines)
    matching = [ln for ln in lines if f" {case['code']} " in ln]
    assert matching, f"expected {case['code']}; got:\n" + "\n".join(lines)
    assert any(case["message"] in ln for ln in matching), "\n".join(matching)
    assert f"ERROR {path}" in out  # the project is named as failing on stdout


def test_invalid_spec_location(located_case, tmp_path, capsys):
    case = located_case
    rc, path, _, err = run_verify(case["text"], tmp_path, capsys)
    assert rc == 2
    where = f"{path}:{case['line']}:" + (f"{case['column']} " if "column" in case else "")
    hits = [ln for ln in error_lines(path, err) if ln.startswith(where) and f" {case['code']} " in ln]
    assert hits, f"expected {where}{case['code']}; got:\n{err}"
    # the source context under the error marks that line
    assert any(ln.startswith(">") and ln[1:].split("|")[0].strip() == str(case["line"]) for ln in err.splitlines())


def test_one_clean_error_for_one_mistake(tmp_path, capsys):
    case = next(c for c in CASES if c["id"] == "pd_gain_sizes")
    rc, path, _, err = run_verify(case["text"], tmp_path, capsys)
    lines = error_lines(path, err)
    assert rc == 2
    assert len(lines) == 1, "\n".join(lines)
    assert "function-after" not in err and "tagged-union" not in err
    assert "primitives.0.controller" in lines[0]


def test_errors_in_several_places_are_all_reported(tmp_path, capsys):
    """The loader collects every reference error of one pass, not only the first."""
    text = next(c for c in CASES if c["id"] == "unknown_primitive_in_sequence")["text"]
    text = text.replace("start: A", "start: Nowhere")
    rc, path, _, err = run_verify(text, tmp_path, capsys)
    lines = error_lines(path, err)
    assert rc == 2
    assert any(ln.startswith(f"{path}:17:") and "MPG304" in ln and "'Nowhere'" in ln for ln in lines)
    assert any(ln.startswith(f"{path}:21:") and "MPG304" in ln and "'B'" in ln for ln in lines)
