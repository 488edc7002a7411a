"""SIGTERM and SIGHUP end a command the way Ctrl-C does: every finally-block runs."""
from __future__ import annotations

import contextlib
import signal

from ..oracle.unwind import unwinding


class Terminated(SystemExit):
    """SIGTERM (or SIGHUP) arrived: raised in the main thread so that every finally-block runs (report
    temporaries removed, worker processes terminated); exits with 128 + the signal number."""


@contextlib.contextmanager
def _signal_handlers():
    """SIGTERM/SIGHUP raise Terminated while the command runs (Ctrl-C already raises KeyboardInterrupt)."""
    saved = {}
    for s in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if s is None:
            continue
        try:
            saved[s] = signal.signal(s, unwinding(Terminated))
        except (ValueError, OSError):  # not the main thread: leave signals alone
            pass
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
