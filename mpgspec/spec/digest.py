"""A digest of a project's spec files, stored in its report so that `plan` and `simulate` can tell
whether the verified results on disk still belong to the specs."""
from __future__ import annotations

import hashlib
from pathlib import Path

MAX_FILES, MAX_BYTES = 5000, 64 * 1024 * 1024


def spec_digest(project_file: str | Path, settings: dict | None = None) -> str:
    """sha256 over every regular file below the project's folder (relative path and content, hidden
    entries skipped), mpgspec's version and the given settings; 'sha256:<hex>'."""
    from .. import __version__

    path = Path(project_file)
    root = path.parent if path.is_file() else path
    h = hashlib.sha256(f"mpgspec {__version__}\n{path.name}\n{sorted((settings or {}).items())!r}\n".encode())
    files, total = 0, 0
    for f in sorted(root.rglob("*")):
        rel = f.relative_to(root)
        if any(part.startswith(".") for part in rel.parts) or "__pycache__" in rel.parts or not f.is_file():
            continue
        files += 1
        if files > MAX_FILES or total > MAX_BYTES:
            h.update(b"...truncated")
            break
        data = f.read_bytes()
        total += len(data)
        h.update(f"{rel.as_posix()}\0{len(data)}\0".encode())
        h.update(data)
    return "sha256:" + h.hexdigest()
