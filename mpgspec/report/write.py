"""Write report files: strict JSON text, files made whole or not at all.

A project's report set is written as a unit by files.py (into a temporary folder, then moved into
place); write_atomic is for a single file on its own (temporary file in the same folder, renamed).
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from .build import finite_json


def write_atomic(path: Path, text: str) -> Path:
    """Write to a temporary file in the same folder, then rename it over the target."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # as an ordinary file would be, not mkstemp's 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_new(path: Path, text: str) -> Path:
    """Create path (it must not exist) with text, flushed to the disk so that a full disk is an
    error here and not a silently short file."""
    path = Path(path)
    with open(path, "x", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    return path


def json_text(data, compact: bool = False) -> str:
    """Strict JSON (no NaN or Infinity: non-finite numbers become null); compact (no whitespace) for
    large machine-read files."""
    data = finite_json(data)
    text = json.dumps(data, separators=(",", ":"), allow_nan=False) if compact else \
        json.dumps(data, indent=1, allow_nan=False)
    return text + "\n"


def write_json(path: Path, data, compact: bool = False) -> Path:
    """JSON with no NaN (non-finite numbers are written as null), written atomically."""
    return write_atomic(path, json_text(data, compact))
