"""index.html of a report folder: one row per project whose report.json lies in a folder below it
(status, warnings, graph size, robust edges, inconclusive calls, when it was written, links to its
pages) and the environment the reports were written in (commit, Python, CasADi, Pinocchio...).

Rebuilt after every `mpgspec verify` that writes reports, from the report files on disk, so it also
lists projects verified by earlier runs into the same folder (with the time each was written).
A report that cannot be read is listed as unreadable, never skipped silently.
"""
from __future__ import annotations

import json
import platform
import subprocess
import sys
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import jinja2

from .. import __version__
from .findings import warning_count

PACKAGES = ("casadi", "pin", "numpy", "cvxpy", "networkx", "pydantic", "mujoco")
"""Distributions whose versions the environment table lists (when installed)."""


@lru_cache(maxsize=1)
def _template() -> jinja2.Template:
    env = jinja2.Environment(loader=jinja2.PackageLoader("mpgspec.report", "templates"), autoescape=True,
                             undefined=jinja2.StrictUndefined)
    return env.get_template("index.html.j2")


def _commit(folder: Path) -> str | None:
    """The git commit (with '+ changes' when the tree is dirty) of the repository holding folder."""
    try:
        head = subprocess.run(["git", "-C", str(folder), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                              text=True, timeout=5)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(folder), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5)
        return head.stdout.strip() + (" + changes" if dirty.returncode == 0 and dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


def environment(folder: Path | None = None) -> list[tuple[str, str]]:
    """(name, value) rows: mpgspec, the commit of the working folder's repository, Python, the
    packages of PACKAGES that are installed, and the platform."""
    rows = [("mpgspec", __version__)]
    commit = _commit(folder or Path.cwd())
    if commit:
        rows.append(("commit", commit))
    rows.append(("Python", platform.python_version()))
    for name in PACKAGES:
        try:
            rows.append(("pinocchio" if name == "pin" else name, metadata.version(name)))
        except metadata.PackageNotFoundError:
            continue
    rows.append(("platform", f"{platform.system()} {platform.machine()} ({sys.platform})"))
    return rows


def _row(folder: Path, root: Path) -> dict:
    rel = folder.relative_to(root).as_posix()
    row = {"folder": rel, "name": rel, "html": None, "playback": None}
    try:
        r = json.loads((folder / "report.json").read_text(encoding="utf-8"))
        if not isinstance(r, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as e:
        return {**row, "status": "unreadable", "why": str(e)[:200]}
    rob = r.get("robust") if isinstance(r.get("robust"), dict) else None
    edges = r.get("edges") or []
    v = r.get("verdicts") or {}
    return {**row, "name": str((r.get("project") or {}).get("name", rel)), "status": str(r.get("status", "?")),
            "warnings": warning_count(r), "primitives": len(r.get("primitives") or []), "edges": len(edges),
            "class2": sum(e.get("class") == 2 for e in edges if isinstance(e, dict)),
            "robust": (rob.get("summary") or {}).get("robust_edges") if rob else None,
            "calls": (r.get("timing") or {}).get("oracle_calls"), "inconclusive": v.get("inconclusive", 0),
            "failed": sum(a.get("status") == "fail" for a in r.get("assertions") or [] if isinstance(a, dict)),
            "assertions": len(r.get("assertions") or []), "generated": str(r.get("generated_at", "")),
            "html": f"{rel}/report.html" if (folder / "report.html").is_file() else None,
            "playback": f"{rel}/playback.html" if (folder / "playback.html").is_file() else None}


def index_html(root: Path, env_folder: Path | None = None) -> str:
    """The index page of the report folder root (its project folders found by their report.json)."""
    root = Path(root)
    folders = sorted({p.parent for pattern in ("*/report.json", "*/*/report.json") for p in root.glob(pattern)
                      if not any(part.startswith(".") for part in p.relative_to(root).parts)})
    rows = [_row(f, root) for f in folders]
    return _template().render(rows=rows, env=environment(env_folder))


def write_index(root, env_folder: Path | None = None) -> Path | None:
    """root/index.html written atomically; None (and nothing written) when root is not a folder or
    cannot be written: the index is a convenience, never the reason a run fails."""
    from .write import write_atomic

    root = Path(root)
    if not root.is_dir():
        return None
    try:
        return write_atomic(root / "index.html", index_html(root, env_folder))
    except OSError:
        return None
