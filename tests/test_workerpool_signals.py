"""A signal that arrives while a pool worker is spawned acts once the worker is held
(core/parallel.py ``interrupts_deferred``, used by core/workerpool.py): the child then never reads a pipe its parent closed."""
import os
import signal

import pytest

from pointspro.core.parallel import interrupts_deferred as _signals_deferred


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


def _slow_start(seconds):
    import time

    time.sleep(seconds)


def _pid():
    return os.getpid()


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="POSIX signal masks")
def test_a_workers_sigint_while_it_starts_and_works_is_ignored(capfd):
    """A terminal's Ctrl-C reaches the whole process group: a worker still starting printed a
    KeyboardInterrupt traceback (the batch's own process stops the workers itself). The worker
    starts with SIGINT blocked and then ignores it: it lives on, silent, and answers."""
    import time

    from pointspro.core.workerpool import WorkerPool

    pool = WorkerPool(1, initializer=_slow_start, initargs=(1.5,))
    try:
        worker = pool._workers[0].process
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.2:  # while its interpreter starts and its initializer runs
            os.kill(worker.pid, signal.SIGINT)
            time.sleep(0.02)
        got = list(pool.map_unordered(_pid, [()], lost=lambda task, why: why))
        assert got == [worker.pid] and worker.is_alive()
        os.kill(worker.pid, signal.SIGINT)  # and once it has started
        assert list(pool.map_unordered(_pid, [()], lost=lambda task, why: why)) == [worker.pid]
    finally:
        pool.terminate()
    err = capfd.readouterr().err
    assert "KeyboardInterrupt" not in err and "Traceback" not in err, err
    assert signal.getsignal(signal.SIGINT) is not signal.SIG_IGN  # this process's own is untouched
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())  # nor blocked here
