"""A signal that arrives while a pool worker is spawned acts once the worker is held
(core/workerpool.py ``_signals_deferred``): the child then never reads a pipe its parent closed."""
import os
import signal

import pytest

from pointspro.core.workerpool import _signals_deferred


def test_a_signal_inside_acts_as_the_context_closes_with_the_handler_it_would_have_met():
    seen = []

    def handler(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt  # as the batch's SIGTERM handler does

    old = signal.signal(signal.SIGTERM, handler)
    inside = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with _signals_deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(1000):  # Python runs handlers between bytecodes: plenty of chances
                    pass
                inside.append(list(seen))  # reached only if the handler has not run (it raises)
        assert inside == [[]]  # the handler had not run inside the context …
        assert seen == [signal.SIGTERM]  # … and ran as it closed
        assert signal.getsignal(signal.SIGTERM) is handler  # restored
    finally:
        signal.signal(signal.SIGTERM, old)


def test_an_ignored_signal_stays_ignored():
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with _signals_deferred():
            os.kill(os.getpid(), signal.SIGINT)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, old)
