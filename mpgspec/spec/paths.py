"""Paths named in specs: confined to the project folder, read with a size bound.

`mpgspec verify` runs in CI on specs from pull requests, so a spec must not be able to make it
read (and echo in an error) a file outside its project: every path a spec names (`system:` and
`primitives:` includes, `setpoint.file`, `urdf:`) must resolve, after symlinks, inside the
project folder (the folder of project.yaml), inside the data folder of a `share:` package, or
inside a folder the caller allowed explicitly (`allow_paths`). Every file is read with a size
bound, only if it is a regular file, and must be UTF-8 text; a problem is a located SpecError
that never contains the file's content. Errors about the content of a file outside the project
folder (admitted by `allow_paths` or `share:`) show neither its lines nor its values
(`Location.quote`, `shown`).
"""
from __future__ import annotations

import os
import re
import stat
import sysconfig
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..errors import HIDDEN, Location, SpecError

MAX_FILE_BYTES = 10_000_000
"""Largest spec, CSV or URDF file read (bytes)."""

MAX_ECHO = 200
"""Longest piece of a spec (a line, a value, a key) echoed in an error message."""

CONFINEMENT_CODE = "MPG305"

_SAFE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")
MAX_NAME = 100


def clip(text: str, limit: int = MAX_ECHO) -> str:
    """text cut to at most `limit` characters, with an ellipsis when cut."""
    text = str(text)
    return text if len(text) <= limit else text[: max(limit - 1, 0)] + "…"


def clip_repr(value, limit: int = MAX_ECHO) -> str:
    return clip(repr(value), limit)


def size_text(n: int) -> str:
    return f"{n} bytes ({n / 1e6:.1f} MB)" if n >= 1_000_000 else f"{n} bytes"


def name_problem(name) -> str:
    """Why `name` is not a safe identifier for a project or package name ('' if it is one)."""
    if not isinstance(name, str):
        return "not a string"
    if not name:
        return "empty"
    if len(name) > MAX_NAME:
        return f"longer than {MAX_NAME} characters"
    if name.startswith("."):
        return "starts with '.'"
    if "/" in name or "\\" in name:
        return "contains a path separator"
    if not _SAFE_NAME.match(name):
        return "contains characters other than letters, digits, '_', '-' and '.'"
    return ""


SAFE_NAME_TEXT = (f"a name of letters, digits, '_', '-' and '.' (at most {MAX_NAME} characters, "
                  "not starting with '.')")


# ----------------------------------------------------------------------------- confinement


def project_root(project_file: str | Path) -> Path:
    """The project folder: the folder of project.yaml, symlinks resolved."""
    return Path(project_file).absolute().parent.resolve()


def resolve_roots(project_dir: Path, allow_paths: Iterable[str | Path] | None = None) -> tuple[Path, ...]:
    """The project folder and the explicitly allowed folders, resolved."""
    roots = [Path(project_dir).resolve()]
    for p in allow_paths or ():
        r = Path(p).absolute().resolve()
        if r not in roots:
            roots.append(r)
    return tuple(roots)


def _inside(target: Path, roots: Sequence[Path]) -> bool:
    return any(target == r or target.is_relative_to(r) for r in roots)


def _outside_error(raw, where: Location, key: str, project_dir: Path, message: str = "") -> SpecError:
    return SpecError(message or "path outside the project folder", location=where, key=key,
                     expected=f"a path inside the project folder {project_dir}",
                     found=clip_repr(raw), code=CONFINEMENT_CODE,
                     hint="paths are relative to the spec and may not leave the project folder, "
                          "also not through a symlink; allow another folder with --allow-path (allow_paths in the API)")


def confine(raw, base: Path, roots: Sequence[Path], *, where: Location, key: str) -> Path:
    """`raw` (as written in a spec, relative to `base`) resolved; a SpecError unless it lies in a root.

    roots[0] is the project folder (named in the error). The file itself need not exist.
    """
    project_dir = roots[0]
    if not isinstance(raw, str) or not raw or "\x00" in raw:
        raise _outside_error(raw, where, key, project_dir, "not a usable path")
    try:
        target = (Path(base) / raw).resolve()
    except (OSError, RuntimeError, ValueError):  # a symlink loop, a name too long...
        raise _outside_error(raw, where, key, project_dir, "path cannot be resolved") from None
    if not _inside(target, roots):
        raise _outside_error(raw, where, key, project_dir)
    return target


def in_project(path: str | Path, roots: Sequence[Path]) -> bool:
    """Whether `path` (symlinks resolved) lies in the project folder roots[0]; True when no
    project folder is known (an instance built without the loader)."""
    if not roots:
        return True
    try:
        return _inside(Path(path).resolve(), roots[:1])
    except (OSError, RuntimeError, ValueError):
        return False


def shown(text: str, path: str | Path, roots: Sequence[Path]) -> str:
    """`text` read from the file at `path` as it may appear in an error: itself for a file in the
    project folder, a note saying it is not shown for any other."""
    return text if in_project(path, roots) else HIDDEN


def share_dirs() -> list[Path]:
    """The cmeel `share` folders of the site directories (where example-robot-data lives)."""
    roots = {sysconfig.get_paths()[k] for k in ("purelib", "platlib")}
    return [Path(r) / "cmeel.prefix" / "share" for r in sorted(roots)]


def confine_share(raw: str, roots: Sequence[Path], *, where: Location, key: str) -> Path:
    """A `share:<package>/<path>` reference resolved inside the data folder of <package>.

    Candidates in every share folder are tried in order; the first existing file wins, else the
    first candidate (so that a missing file is reported by the reader). An allowed folder
    (roots) also admits the target.
    """
    project_dir = roots[0]
    rel = raw[len("share:"):] if raw.startswith("share:") else raw
    package = rel.split("/", 1)[0]
    if name_problem(package) or "\x00" in rel or "\\" in rel:
        raise SpecError("not a share: reference to an installed package", location=where, key=key,
                        expected="share:<package>/<path inside the package's data folder>",
                        found=clip_repr(raw), code=CONFINEMENT_CODE)
    candidates = []
    for share in share_dirs():
        try:
            root = (share / package).resolve()
            target = (share / rel).resolve()
        except (OSError, RuntimeError, ValueError):
            continue
        if not _inside(target, [root, *roots[1:]]):
            raise SpecError("path outside the data folder of the share package", location=where, key=key,
                            expected=f"a path inside the data folder of {package!r} ({root}) or inside "
                                     f"the project folder {project_dir}",
                            found=clip_repr(raw), code=CONFINEMENT_CODE)
        candidates.append(target)
    for c in candidates:
        if c.is_file():
            return c
    if not candidates:
        raise SpecError("share package not found", location=where, key=key,
                        expected="an installed package with data under cmeel.prefix/share",
                        found=clip_repr(raw), code=CONFINEMENT_CODE)
    return candidates[0]


# ----------------------------------------------------------------------------- bounded reads


class ReadProblem(Exception):
    """A file that cannot be read as spec input; never carries the file's content.

    line and column (1-based, 0 when unknown) place the problem in the file (a byte that is not
    UTF-8)."""

    def __init__(self, message: str, expected: str = "", found: str = "", missing: bool = False,
                 line: int = 0, column: int = 0):
        super().__init__(message)
        self.message, self.expected, self.found, self.missing = message, expected, found, missing
        self.line, self.column = line, column


def read_bytes_bounded(path: str | Path, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most `limit` bytes; ReadProblem otherwise.

    Directories, devices, FIFOs and sockets are refused before they are opened (a FIFO would
    block, /dev/zero never ends); files whose size the kernel does not report (/proc) are read
    only up to the limit.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ReadProblem("no such file", "an existing file", missing=True) from None
    except (OSError, ValueError) as err:
        raise ReadProblem("cannot read the file", "a readable file",
                          getattr(err, "strerror", None) or type(err).__name__) from None
    if stat.S_ISDIR(st.st_mode):
        raise ReadProblem("is a directory", "a file", "a directory")
    if not stat.S_ISREG(st.st_mode):
        raise ReadProblem("not a regular file", "a file", "a device, FIFO or socket")
    if st.st_size > limit:
        raise ReadProblem("file is too large", f"at most {size_text(limit)}", size_text(st.st_size))
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(path, flags)
    except OSError as err:
        raise ReadProblem("cannot read the file", "a readable file", err.strerror or type(err).__name__) from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # replaced between stat and open
            raise ReadProblem("not a regular file", "a file", "a device, FIFO or socket")
        chunks, total = [], 0
        while total <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    except OSError as err:
        raise ReadProblem("cannot read the file", "a readable file", err.strerror or type(err).__name__) from None
    finally:
        os.close(fd)
    if total > limit:
        raise ReadProblem("file is too large", f"at most {size_text(limit)}", f"more than {size_text(limit)}")
    return b"".join(chunks)


def read_text_bounded(path: str | Path, limit: int = MAX_FILE_BYTES, allow_empty: bool = False) -> str:
    """UTF-8 text of a regular file of at most `limit` bytes; ReadProblem otherwise."""
    data = read_bytes_bounded(path, limit)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _not_utf8(data, exc.start) from None
    if not allow_empty and not text.strip():
        raise ReadProblem("file is empty", "a non-empty file", "no content")
    return text


def _not_utf8(data: bytes, offset: int) -> ReadProblem:
    """The problem of a byte that starts no UTF-8 character, placed by line and column (characters
    before it on its line, 1-based) as well as by byte offset."""
    start = data.rfind(b"\n", 0, offset) + 1
    line = data.count(b"\n", 0, offset) + 1
    column = len(data[start:offset].decode("utf-8", errors="replace")) + 1
    return ReadProblem("file is not UTF-8 text", "UTF-8 text",
                       f"byte {data[offset]:#04x} at line {line}, column {column}, byte offset {offset}",
                       line=line, column=column)


def read_text(path: str | Path, *, where: Location, key: str = "", code: str, what: str = "file",
              limit: int = MAX_FILE_BYTES, allow_empty: bool = False) -> str:
    """read_text_bounded with problems raised as a SpecError at `where` (the key naming the file)."""
    try:
        return read_text_bounded(path, limit, allow_empty)
    except ReadProblem as p:
        raise SpecError(f"{what}: {p.message}", location=where, key=key, expected=p.expected,
                        found=p.found, code=code) from None
