"""Every error code the source can report has an entry (`mpgspec explain`), the entries are all
used, and docs/error-codes.md is the table as written from them."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from mpgspec.cli import main
from mpgspec.codes import CODES, markdown

ROOT = Path(__file__).resolve().parent.parent
CODE = re.compile(r"MPG\d{3}")


def _used() -> set[str]:
    found = set()
    for f in (ROOT / "mpgspec").rglob("*.py"):
        if f.name != "codes.py":
            found |= set(CODE.findall(f.read_text(encoding="utf-8")))
    return found


def test_every_code_in_the_source_is_explained_and_every_entry_used():
    used = _used()
    assert used, "no codes found: the scan is broken"
    assert used - set(CODES) == set(), "codes without an entry in mpgspec/codes.py"
    assert set(CODES) - used == set(), "entries for codes the source never reports"


def test_the_docs_page_is_the_table():
    assert (ROOT / "docs" / "error-codes.md").read_text(encoding="utf-8") == markdown(), \
        "docs/error-codes.md is stale: write it from mpgspec.codes.markdown()"


@pytest.mark.parametrize("arg", ["MPG204", "mpg204", "204"])
def test_explain_prints_the_entry(capsys, arg):
    assert main(["explain", arg]) == 0
    out = capsys.readouterr().out
    assert out.startswith("MPG204: unknown name") and CODES["MPG204"][1] in out


def test_explain_lists_all_and_refuses_an_unknown_code(capsys):
    assert main(["explain"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == len(CODES)
    assert main(["explain", "MPG999"]) == 2
    err = capsys.readouterr().err
    assert "unknown error code" in err and "Traceback" not in err
