"""A pool of worker processes that survives a worker's death (the night batch: core/executors.py).

multiprocessing.Pool replaces a worker that dies (the kernel's out-of-memory killer on a huge input,
a crash in a C library) but loses the task it was running: ``imap_unordered`` then waits for it
forever and the whole batch hangs — measured: 4 inputs on 2 workers, one worker killed with SIGKILL,
3 inputs done and the command waiting until it was killed itself. concurrent.futures' pool fails
every pending task instead (BrokenProcessPool). Here the parent hands one task at a time to each
worker over its own pipe, so it knows what each worker holds: a worker that ends without answering
makes that one task ``lost`` (the caller turns it into a failed outcome naming the signal) and is
replaced by a fresh worker; the other tasks go on.

Workers are spawned (no inherited threads or locks), run ``initializer(*initargs)`` once and then
answer ``(fn, args)`` messages with ``(True, fn(*args))`` or ``(False, exception)``; ``fn`` must be
importable (a module-level function), as with multiprocessing.Pool.
"""
from __future__ import annotations

import multiprocessing
import signal
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

from .parallel import interrupts_deferred


def _worker_main(conn, initializer, initargs) -> None:
    """A worker: its initializer, then one task after the other until told to stop (None) or the
    parent's end of the pipe closes. SIGINT is ignored (``_interrupt_blocked``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a SIGINT pending since the start is dropped …
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # … as it is unblocked
    if initializer is not None:
        initializer(*initargs)
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        fn, args = msg
        try:
            reply = (True, fn(*args))
        except BaseException as e:  # noqa: BLE001 — raised again in the parent
            reply = (False, e)
        try:
            conn.send(reply)
        except Exception as e:  # noqa: BLE001 — e.g. an exception or result that does not pickle
            conn.send((False, RuntimeError(f"{type(e).__name__}: {e} (sending {fn.__name__}'s result)")))


class _interrupt_blocked:
    """Context: SIGINT blocked in this thread, so that a worker started inside it starts with SIGINT
    blocked (the signal mask outlives fork and exec); the worker then ignores it (``_worker_main``).
    A terminal's Ctrl-C signals the whole process group: a worker still starting (its interpreter
    importing, before any handler of ours) printed a KeyboardInterrupt traceback on the terminal
    beside the batch's own line. The batch's process, which the Ctrl-C reaches too, stops the
    workers itself (SIGTERM). A SIGINT that arrives here meanwhile is delivered as the block ends."""

    def __enter__(self):
        self._old = (signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
                     if hasattr(signal, "pthread_sigmask") else None)
        return self

    def __exit__(self, *exc):
        if self._old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, self._old)
        return False


@dataclass(eq=False)
class _Worker:
    process: Any
    conn: Any


def death_reason(exitcode: int | None) -> str:
    """Words for how a worker process ended, after "the worker process": "was killed by SIGKILL",
    "exited with status 3"."""
    if exitcode is None:
        return "ended"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"was killed by {name}"
    return f"exited with status {exitcode}"


class WorkerPool:
    """``workers`` spawned processes (module doc). ``env``: variables set while they start (they copy
    the environment then), e.g. one BLAS thread each."""

    def __init__(self, workers: int, initializer: Callable | None = None, initargs: tuple = (),
                 env: dict[str, str] | None = None):
        self._ctx = multiprocessing.get_context("spawn")
        self._init = (initializer, tuple(initargs))
        self._env = dict(env or {})
        self._workers: list[_Worker] = []
        try:
            for _ in range(max(1, int(workers))):
                with interrupts_deferred():  # the worker is held (and stopped with the others) first
                    self._workers.append(self._spawn())
        except BaseException:
            self.terminate()
            raise

    def _spawn(self) -> _Worker:
        """A started worker; the environment holds ``env`` while it starts (the child copies it)."""
        import os

        parent, child = self._ctx.Pipe()
        p = self._ctx.Process(target=_worker_main, args=(child, *self._init), daemon=True)
        saved = {k: os.environ.get(k) for k in self._env}
        os.environ.update(self._env)
        try:
            # multiprocessing starts its resource tracker at the first spawn and unblocks SIGINT
            # after it (resource_tracker.ensure_running): started before the block, not inside it
            from multiprocessing import resource_tracker

            resource_tracker.ensure_running()
            with _interrupt_blocked():
                p.start()
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        child.close()
        return _Worker(p, parent)

    def _replace(self, w: _Worker) -> _Worker:
        """A fresh worker instead of ``w`` (which ended or is ended here)."""
        self._stop(w)
        with interrupts_deferred():
            new = self._spawn()
            self._workers[self._workers.index(w)] = new
        return new

    @staticmethod
    def _stop(w: _Worker, timeout: float = 5.0) -> None:
        if w.process.is_alive():
            w.process.terminate()
            w.process.join(timeout)
            if w.process.is_alive():
                w.process.kill()
        w.process.join()
        w.conn.close()

    def map_unordered(self, fn: Callable, tasks: Iterable[tuple],
                      lost: Callable[[tuple, str], Any]) -> Iterator[Any]:
        """``fn(*task)`` for every task, yielded in completion order, one task at a time per worker in
        the order given. A worker that ends without answering yields ``lost(task, reason)`` for the
        task it held (``death_reason``) and is replaced; an exception raised by ``fn`` is raised here."""
        from multiprocessing.connection import wait

        pending = deque(tasks)
        idle = list(self._workers)
        busy: dict[_Worker, tuple] = {}
        while pending or busy:
            while idle and pending:
                w = idle.pop()
                if not w.process.is_alive():  # ended while idle (killed): never handed a task
                    idle.append(self._replace(w))
                    continue
                task = pending.popleft()
                try:
                    w.conn.send((fn, task))
                except (BrokenPipeError, EOFError, OSError):  # it died while idle: a fresh one
                    pending.appendleft(task)
                    idle.append(self._replace(w))
                    continue
                busy[w] = task
            by_handle = {}
            for w in busy:
                by_handle[w.conn] = w
                by_handle[w.process.sentinel] = w
            for w in {by_handle[h] for h in wait(list(by_handle))}:
                task = busy.pop(w)
                try:
                    ok, value = w.conn.recv() if w.conn.poll() else (None, None)
                except (EOFError, OSError):
                    ok = None
                if ok is None:  # ended without an answer: the task is lost, the worker replaced
                    w.process.join(5.0)
                    reason = death_reason(w.process.exitcode)
                    idle.append(self._replace(w))
                    yield lost(task, reason)
                    continue
                idle.append(w)
                if not ok:
                    raise value
                yield value

    def apply(self, fn: Callable, *args) -> Any:
        """``fn(*args)`` on one worker (tests); RuntimeError when that worker ends without answering."""
        def lost(_task, reason):
            raise RuntimeError(f"the worker process {reason}")

        return next(iter(self.map_unordered(fn, [args], lost)))

    def close(self) -> None:
        """Ask every worker to stop after its task (idle ones stop at once)."""
        for w in self._workers:
            try:
                w.conn.send(None)
            except (BrokenPipeError, EOFError, OSError):
                pass

    def terminate(self) -> None:
        """Stop every worker now (SIGTERM, then SIGKILL after 5 s)."""
        for w in self._workers:
            if w.process.is_alive():
                w.process.terminate()
        for w in self._workers:
            self._stop(w)

    def join(self) -> None:
        for w in self._workers:
            w.process.join()

    @property
    def pids(self) -> list[int]:
        return [w.process.pid for w in self._workers]
