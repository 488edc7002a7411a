"""Output of the command line: result marks, error lines with their spec context, GitHub workflow
annotations, numbers, and the JSON document of `verify --format json`."""
from __future__ import annotations

import json
import os
import sys
from typing import TYPE_CHECKING

from ..errors import EXIT_USAGE, gh_command, gh_plain
from ..spec.yamlpos import format_context

MARK = {"pass": "PASS", "fail": "FAIL", "error": "ERROR", "warn": "WARN", "info": "INFO"}

if TYPE_CHECKING:
    from ..pipeline.results import VerifyResult


def _line(text: str, fmt: str) -> str:
    """A plain output line; with --format github, one that cannot start a workflow command."""
    return gh_plain(text) if fmt == "github" else text


def _progress(stream, fmt: str = "human"):
    """Phases with elapsed time: live on a terminal (human format), plain lines otherwise."""
    from ..progress import Display

    return Display(stream, live=None if fmt == "human" else False, line=lambda text: _line(text, fmt))


def _print_errors(errors: list[dict], fmt: str):
    """Each error's line, with the spec lines around it unless its file lies outside the project
    folder (quote false: nothing of such a file is shown)."""
    for e in errors:
        if fmt == "github":
            print(_annotation("error", e.get("text", e.get("message")), e, e.get("code", "") or None))
            continue
        print(e.get("text", e.get("message")), file=sys.stderr)
        if e.get("line") and e.get("quote", True):
            try:
                print(format_context(e["file"], e["line"], column=e.get("column", 0)), file=sys.stderr)
            except OSError:
                pass


def _rel(path) -> str:
    """A path relative to the working folder when it lies below it (how GitHub names files)."""
    try:
        return os.path.relpath(path) if not os.path.relpath(path).startswith("..") else str(path)
    except (ValueError, OSError):
        return str(path)


def _annotation(kind: str, message, where: dict | None, title: str | None = None, file=None) -> str:
    """A GitHub workflow command; file, line and col only where they are known (never line=0)."""
    where = where or {}
    f = where.get("file") or file
    line = where.get("line") or None
    return gh_command(kind, message, file=_rel(f) if f else None, line=line,
                      col=(where.get("column") or None) if line else None, title=title)


def append_step_summary(text: str) -> None:
    """text appended to $GITHUB_STEP_SUMMARY when it is set; a file that cannot be written is said
    on stderr, not an error of the command."""
    path = os.environ.get("GITHUB_STEP_SUMMARY")
    if not path:
        return
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write(text)
    except OSError as e:
        print(f"mpgspec: cannot write the step summary {path}: {e}", file=sys.stderr)


def _num(v, spec: str = ".3g") -> str:
    try:
        return format(float(v), spec)
    except (TypeError, ValueError):
        return "?"


def _json_doc(res: VerifyResult | None, errors=(), code: int = EXIT_USAGE) -> str:
    from ..report.build import finite_json

    doc = {"exit_code": res.exit_code if res is not None else code, "projects": [] if res is None else [
        {"path": str(p.path), "name": p.name, "status": p.status, "errors": p.errors, "files": p.files,
         "assertions": p.report["assertions"] if p.report else [], "report": p.report} for p in res.projects]}
    if errors:
        doc["errors"] = list(errors)
    return json.dumps(finite_json(doc), separators=(",", ":"), allow_nan=False, default=str)
