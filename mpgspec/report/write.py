"""Write report files atomically: a crash mid-write never leaves a half file behind."""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path


def write_atomic(path: Path, text: str) -> Path:
    """Write to a temporary file in the same folder, then rename it over the target."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # as an ordinary file would be, not mkstemp's 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_json(path: Path, data, compact: bool = False) -> Path:
    """JSON with no NaN; compact (no whitespace) for large machine-read files."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False) if compact else json.dumps(data, indent=1, allow_nan=False)
    return write_atomic(path, text + "\n")
