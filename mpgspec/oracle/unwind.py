"""Handlers that turn SIGTERM/SIGHUP into an exception that unwinds the process (every finally-block
runs), safe across fork.

A raising handler must not fire inside the interpreter's fork hooks (logging's lock release, for
one): an exception raised there is printed with its traceback and ignored, and the process goes on.
So while a fork is under way the handler sends the signal again from a short-lived thread instead,
to be acted on once the hooks have returned; and a child forked from the process, which inherits
the handler until it sets its own, exits at once with 128 + the signal number.
"""
from __future__ import annotations

import logging
import os
import threading
from typing import Callable

_ENCLOSED = (logging,)
"""Imported first: their fork hooks are registered before ours, so ours run around them."""
_forking = [False]


def _before_fork() -> None:
    _forking[0] = True


def _after_fork() -> None:
    _forking[0] = False


os.register_at_fork(before=_before_fork, after_in_parent=_after_fork, after_in_child=_after_fork)


def unwinding(exc: Callable[[int], BaseException]) -> Callable:
    """A signal handler for this process that raises exc(128 + signum), deferred past a fork in
    progress; in a forked child, os._exit(128 + signum)."""
    owner = os.getpid()

    def on_signal(signum, frame):
        if os.getpid() != owner:
            os._exit(128 + signum)
        if _forking[0]:
            again = threading.Timer(0.01, os.kill, (owner, signum))
            again.daemon = True
            again.start()
            return
        raise exc(128 + signum)

    return on_signal
