"""SIGTERM turned into an exception never fires inside the interpreter's fork hooks (where it would
be printed and ignored): it is sent again once the fork is over; a forked child exits quietly."""
import os
import signal
import time

import pytest

from mpgspec.oracle import unwind


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_signal_during_a_fork_unwinds_after_it_and_a_child_exits_quietly():
    seen = []
    old = signal.signal(signal.SIGTERM, unwind.unwinding(lambda code: SystemExit(code)))
    try:
        unwind._before_fork()  # a fork under way: the handler defers
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(10):
            time.sleep(0.001)  # the handler runs and defers, raising nothing here
        unwind._after_fork()
        with pytest.raises(SystemExit) as err:
            for _ in range(500):
                time.sleep(0.01)  # the signal sent again arrives
        seen.append(err.value.code)
        pid = os.fork()
        if pid == 0:  # the child inherits the handler: it exits at once, no unwinding
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
            os._exit(0)
        _, status = os.waitpid(pid, 0)
        seen.append(os.waitstatus_to_exitcode(status))
    finally:
        signal.signal(signal.SIGTERM, old)
    assert seen == [128 + signal.SIGTERM] * 2
