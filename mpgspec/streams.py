"""Keep stdout for mpgspec's own result: what others print while the pipeline runs goes to stderr."""
from __future__ import annotations

import os
import sys
import threading
from contextlib import contextmanager

_quiet_lock = threading.Lock()
_quiet_depth = 0
_quiet_saved: int | None = None
_quiet_stdout = None


def _flush_stdout() -> None:
    try:
        sys.stdout.flush()
    except (OSError, ValueError, AttributeError):
        pass


@contextmanager
def stdout_to_stderr():
    """Point sys.stdout and file descriptor 1 at stderr (fd 1 at /dev/null when there is no stderr)
    while a solver runs, so that its prints, from Python, C or Rust, never reach stdout (where
    `mpgspec verify --format json` writes its one JSON document). Nests, and is shared by the
    threads of a process: stdout comes back when the last one leaves."""
    global _quiet_depth, _quiet_saved, _quiet_stdout
    with _quiet_lock:
        if _quiet_depth == 0:
            _flush_stdout()
            _quiet_stdout, sys.stdout = sys.stdout, sys.stderr
            try:
                saved = os.dup(1)
            except OSError:  # no stdout at all: nothing to protect
                saved = None
            if saved is not None:
                try:
                    os.dup2(2, 1)
                except OSError:
                    null = os.open(os.devnull, os.O_WRONLY)
                    os.dup2(null, 1)
                    os.close(null)
            _quiet_saved = saved
        _quiet_depth += 1
    try:
        yield
    finally:
        with _quiet_lock:
            _quiet_depth -= 1
            if _quiet_depth == 0:
                _flush_stdout()
                sys.stdout, _quiet_stdout = _quiet_stdout, None
                if _quiet_saved is not None:
                    os.dup2(_quiet_saved, 1)
                    os.close(_quiet_saved)
                    _quiet_saved = None


@contextmanager
def native_stderr_discarded():
    """Point file descriptor 2 at /dev/null while a native parser reads a file outside the project
    folder: its own messages (urdfdom names the joints and links of the file it rejects) must not
    reach CI logs. sys.stderr is flushed first and writes to the real stderr again afterwards."""
    try:
        sys.stderr.flush()
    except (OSError, ValueError, AttributeError):
        pass
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing can leak
        saved = None
    null = os.open(os.devnull, os.O_WRONLY) if saved is not None else None
    try:
        if null is not None:
            os.dup2(null, 2)
        yield
    finally:
        if saved is not None:
            os.dup2(saved, 2)
            os.close(saved)
            os.close(null)
