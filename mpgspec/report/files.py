"""Write one project's report set as a unit: JSON (the source of truth), HTML from it, the graph as
DOT/GraphML and the lookup table.

Everything is rendered first (from the report with inf/NaN turned into null, so the files agree),
then written into a temporary folder inside the report folder (--out) and moved into place as a
whole: an older report folder of the project is renamed aside, the new one moved in, the old one
deleted. Readers never see half a report set, a failure leaves the older set in place, and no
temporary folder is left behind (one left by a killed run is removed by the next run). The
project's folder must lie inside the report folder once both are resolved; a project name like
'../x' is refused.
"""
from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import tempfile
import threading
import time
from pathlib import Path

from ..errors import MpgError
from ..graph.transition import MotionPrimitiveGraph
from .build import finite_json
from .export import to_dot, to_graphml
from .html import render_html
from .trust import integrity_record
from .write import json_text, write_new

FORMATS = ("json", "html", "dot", "graphml")
FILE_NAMES = {"json": "report.json", "lookup_table": "lookup_table.json", "html": "report.html",
              "dot": "graph.dot", "graphml": "graph.graphml", "playback": "playback.html"}
TMP_PREFIX = ".mpgspec-tmp."   # + host.pid.random: a report set being written
OLD_PREFIX = ".mpgspec-old."   # + host.pid.random: an older report set on its way out
STALE_AFTER_S = 3600.0         # a leftover of another host (shared folder) is removed after this long
_active: set[str] = set()      # temporary folders this process is writing now


class ReportWriteError(MpgError):
    """The report files of a project could not be written (or would land outside the report folder)."""

    code = "MPG400"


def _tag() -> str:
    return f"{socket.gethostname() or 'host'}.{os.getpid()}"


def project_folder(out_dir, name) -> tuple[Path, Path]:
    """(resolved out_dir, resolved out_dir/name); refuses a name whose folder is not inside out_dir."""
    if not isinstance(name, str) or not name.strip() or "\0" in name:
        raise ReportWriteError(f"refusing to write reports: the project name {name!r} is not a folder name")
    root = Path(out_dir)
    try:
        root_r = root.resolve()
        target = (root / name).resolve()
    except (OSError, RuntimeError, ValueError) as e:
        raise ReportWriteError(f"cannot resolve the report folder {root / name}: {e}") from e
    if root_r not in target.parents:
        raise ReportWriteError(f"refusing to write reports of project {name!r}: its folder {target} is not "
                               f"inside the report folder {root_r}")
    return root_r, target


def render_reports(report: dict, formats=FORMATS) -> dict[str, str]:
    """format -> file text; all from the same report with non-finite numbers as null."""
    data = finite_json(report)
    texts = {}
    if "json" in formats:
        texts["json"] = sealed_text(data)
        texts["lookup_table"] = json_text(data.get("lookup_table", {}))
    if "html" in formats:
        texts["html"] = render_html(data)
    if "dot" in formats:
        texts["dot"] = to_dot(data)
    if "graphml" in formats:
        texts["graphml"] = to_graphml(data)
    return texts


def sealed_text(data: dict) -> str:
    """report.json's text: the report's compact JSON with its integrity record
    (trust.integrity_record) as the last key, taken over exactly that content (read back from the
    text). The record is appended to the text rather than the report dumped again: the same bytes,
    one JSON pass fewer over a report of megabytes."""
    text = json_text(data, compact=True)
    record = json.dumps(integrity_record(json.loads(text)), separators=(",", ":"))
    body = text.rstrip()
    return body[:-1] + ("," if body != "{}" else "") + f'"integrity":{record}}}' + "\n"


def write_project_reports(report: dict, out_dir, name: str | None = None, formats=FORMATS,
                          pages: dict[str, str] | None = None) -> dict[str, str]:
    """Write the report set of one project to out_dir/name as a unit; returns format -> path.
    pages: further files of the set rendered elsewhere (key of FILE_NAMES -> text: the playback).

    Raises ReportWriteError when the folder is outside out_dir or anything cannot be written
    (read-only or missing permissions, out_dir a file, a full disk...)."""
    name = report.get("project", {}).get("name") if name is None else name
    root, target = project_folder(out_dir, name)
    texts = render_reports(report, formats)
    texts.update({k: v for k, v in (pages or {}).items() if k in FILE_NAMES and k not in texts})
    where = Path(out_dir) / name
    if root.exists() and not root.is_dir():
        raise ReportWriteError(f"cannot write reports into {out_dir}: it is not a folder")
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ReportWriteError(f"cannot create the report folder {out_dir}: {_why(e)}") from e
    if not _writable(root):
        raise ReportWriteError(f"cannot write reports into {out_dir}: the folder is read-only")
    remove_stale(root)
    try:
        tmp = _make_temp_dir(root)
    except OSError as e:
        raise ReportWriteError(f"cannot write reports into {out_dir}: {_why(e)}") from e
    _active.add(str(tmp))
    try:
        for k, text in texts.items():
            write_new(tmp / FILE_NAMES[k], text)
        _swap(tmp, target, root)
    except OSError as e:
        raise ReportWriteError(f"cannot write the reports of project {name!r} to {where}: {_why(e)}") from e
    finally:
        with _SignalsDeferred():
            _remove(tmp)
            _active.discard(str(tmp))
    return {k: str(where / FILE_NAMES[k]) for k in texts}


def write_reports(report: dict, graph: MotionPrimitiveGraph | None, folder: Path,
                  formats=FORMATS, pages: dict[str, str] | None = None) -> dict[str, str]:
    """Write the requested formats into folder (the report folder joined with the project name, as
    mpgspec.api does); returns format -> path. See write_project_reports."""
    folder = Path(folder)
    name = report.get("project", {}).get("name")
    if isinstance(name, str):
        parts = Path(name).parts
        if not parts:  # '' or '.': folder would be the report folder itself
            raise ReportWriteError(f"refusing to write reports: the project name {name!r} is not a folder name")
        if folder.parts[-len(parts):] == parts:
            root = Path(*folder.parts[:-len(parts)]) if len(folder.parts) > len(parts) else Path(".")
            return write_project_reports(report, root, name, formats, pages)
    return write_project_reports(report, folder.parent, folder.name, formats, pages)


# ----------------------------------------------------------------------------- the pieces
def _why(e: OSError) -> str:
    return f"{e.strerror} ({e.filename})" if e.strerror and e.filename else (e.strerror or str(e))


def _writable(folder: Path) -> bool:
    """Whether we may create files in folder: its permissions (a read-only file system included) and,
    for root, who is never refused by them, whether anybody has a write bit: a folder marked read-only
    stays read-only."""
    if not os.access(folder, os.W_OK | os.X_OK):
        return False
    try:
        return not (hasattr(os, "geteuid") and os.geteuid() == 0 and not folder.stat().st_mode & 0o222)
    except OSError:
        return False


def _make_temp_dir(root: Path) -> Path:
    tmp = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{_tag()}.", dir=root))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # as an ordinary folder would be, not mkdtemp's 0700
    return tmp


def _swap(tmp: Path, target: Path, root: Path) -> None:
    """Move tmp to target; an existing target is renamed aside first and deleted once tmp is in place
    (and put back if that fails). Signals wait until the folders are consistent again."""
    with _SignalsDeferred():
        target.parent.mkdir(parents=True, exist_ok=True)
        old = None
        if os.path.lexists(target):
            old = root / f"{OLD_PREFIX}{_tag()}.{secrets.token_hex(4)}"
            os.replace(target, old)
        try:
            os.replace(tmp, target)
        except BaseException:
            if old is not None:
                os.replace(old, target)
            raise
        if old is not None:
            _remove(old)


def _remove(path: Path) -> None:
    try:
        if path.is_symlink() or path.is_file():
            path.unlink()
        elif path.exists():
            shutil.rmtree(path, ignore_errors=True)
    except OSError:
        pass  # left for the next run's remove_stale


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # e.g. another user's process
        return True
    return True


def _is_stale(entry: Path) -> bool:
    rest = entry.name[len(TMP_PREFIX if entry.name.startswith(TMP_PREFIX) else OLD_PREFIX):]
    host, _, tail = rest.rpartition(".")  # host.pid . random
    host, _, pid = host.rpartition(".")
    if host == (socket.gethostname() or "host") and pid.isdigit():
        if int(pid) == os.getpid():
            return str(entry) not in _active
        return not _alive(int(pid))
    try:
        return time.time() - entry.lstat().st_mtime > STALE_AFTER_S
    except OSError:
        return False


def remove_stale(root: Path) -> list[str]:
    """Remove temporary and set-aside folders left in root by runs that were killed; returns their names."""
    removed = []
    try:
        entries = list(Path(root).iterdir())
    except OSError:
        return removed
    for entry in entries:
        if entry.name.startswith((TMP_PREFIX, OLD_PREFIX)) and _is_stale(entry):
            _remove(entry)
            removed.append(entry.name)
    return removed


class _SignalsDeferred:
    """SIGTERM and SIGINT received inside the block are acted on at its end (main thread only), so
    that a rename pair or a clean-up is not cut in half."""

    SIGNALS = (signal.SIGTERM, signal.SIGINT)

    def __enter__(self):
        self.saved, self.got = {}, []
        if threading.current_thread() is not threading.main_thread():
            return self
        for s in self.SIGNALS:
            try:
                h = signal.getsignal(s)
                if h is None:  # installed outside Python: leave it alone
                    continue
                signal.signal(s, lambda n, f: self.got.append(n))
                self.saved[s] = h
            except (ValueError, OSError):
                pass
        return self

    def __exit__(self, *exc):
        for s, h in self.saved.items():
            signal.signal(s, h)
        if self.got:
            signal.raise_signal(self.got[0])
        return False
