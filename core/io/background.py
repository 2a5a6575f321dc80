"""A file written by a forked child process while this one goes on (cloud.csv beside the figures).

Writing the cloud as CSV is bound by formatting floats (``repr``: shortest round-trip decimals,
~0.5 µs a value, one core): 4–5 s for 10⁶ points × 8 columns, as long as drawing all the figures. On
a machine with a free core the child formats and writes the file while the parent draws; the parent
waits for it before the output folder is renamed into place, so a folder is still complete or absent.

The child is a ``fork`` of this process: it sees the arrays without copying or pickling them (pages
are shared copy-on-write), runs only numpy, Python string formatting and file writes, and leaves with
``os._exit``. It is used only where that is safe and useful — POSIX, a single-threaded process (the
batch's main process, which asks for it; not the window, whose Qt and worker threads a fork would copy mid-flight) and
more than one core in this process's budget (core.parallel: a pool worker has one, so it writes
inline) — otherwise the function runs here, inline, with the same result.
"""
from __future__ import annotations

import os
import threading


class BackgroundWrite:
    """``fn(*args)`` started in a forked child (``forked`` True) or already run inline; ``wait()``
    returns when it is done and raises its error as an OSError naming the file. ``fork=False``: always
    inline (the caller knows its process must not fork: the window, with Qt's native threads that
    ``threading`` does not count)."""

    def __init__(self, fn, *args, what: str = "a file", fork: bool = True):
        self.what = what
        self.pid = None
        self._read = None
        if not (fork and _can_fork()):
            fn(*args)
            return
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: run, report an error's one line through the pipe, never return
            code = 0
            try:
                _die_on_interrupt()
                os.close(r)
                fn(*args)
            except BaseException as e:  # noqa: BLE001 — reported to the parent, which raises it
                code = 1
                try:
                    os.write(w, f"{type(e).__name__}: {e}".encode("utf-8", "replace")[:4000])
                except OSError:
                    pass
            finally:
                os._exit(code)
        os.close(w)
        self.pid, self._read = pid, r

    @property
    def forked(self) -> bool:
        return self.pid is not None

    def wait(self) -> None:
        if self.pid is None:
            return
        msg = b""
        try:
            while chunk := os.read(self._read, 4096):
                msg += chunk
        finally:
            os.close(self._read)
            _, status = os.waitpid(self.pid, 0)
            self.pid = None
        code = os.waitstatus_to_exitcode(status)
        if code != 0:
            raise OSError(f"writing {self.what} failed: "
                          + (msg.decode("utf-8", "replace") or f"the writer process ended with {code}"))

    def cancel(self) -> None:
        """Stop the child (the caller failed meanwhile and removes the folder)."""
        if self.pid is None:
            return
        _kill(self.pid, self._read)
        self.pid = None


def _die_on_interrupt() -> None:
    """In a forked child: SIGINT and SIGTERM end it at once, as they do a process that set no
    handler. A terminal's Ctrl-C and `timeout` signal the whole process group; the child had the
    batch's SIGTERM handler (raise KeyboardInterrupt) and Python's SIGINT one, and sent back
    "KeyboardInterrupt: " as its error — a line a review saw printed once. The batch itself gets the
    signal too and stops the inputs; a child ended so leaves only its temporary file, which the
    batch removes with the input's temporary folder."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:  # a batch started with it ignored (nohup, `&`)
            signal.signal(sig, signal.SIG_DFL)           # keeps its writers through it (a review)


def _can_fork() -> bool:
    from ..parallel import thread_count

    return hasattr(os, "fork") and threading.active_count() == 1 and thread_count() > 1


def share_out(tasks, *, workers: int, fork: bool = True) -> dict[str, float]:
    """Run ``tasks`` — (name, fn) pairs, each writing its own file — on this process and up to
    ``workers − 1`` forked children (the figures of one input: issue 17). Returns the seconds each
    task took, by name.

    A queue without a lock: the task numbers are written into a pipe before forking, and every
    process reads the next one (a one-byte read of a pipe is atomic) until the pipe is empty — a
    long figure does not hold the others up, whoever is free takes the next. A child sends back its
    tasks' seconds, or the first error's one line, and leaves with ``os._exit``. An error in a child
    is raised here as an OSError naming the task (after the other processes have finished); an error
    here stops the children first. The tasks run in list order when nothing is forked (``fork`` False,
    one core, threads running), with the same files as a result."""
    import json
    import time

    tasks = list(tasks)
    workers = max(1, min(int(workers), len(tasks)))
    seconds: dict[str, float] = {}
    if workers == 1 or len(tasks) > 255 or not (fork and _can_fork()):
        for name, fn in tasks:
            t0 = time.perf_counter()
            fn()
            seconds[name] = time.perf_counter() - t0
        return seconds

    queue_r, queue_w = os.pipe()
    os.write(queue_w, bytes(range(len(tasks))))     # one byte a task (≤ 255, else inline above)
    os.close(queue_w)

    def drain(report, in_child):
        while (b := os.read(queue_r, 1)):
            name, fn = tasks[b[0]]
            t0 = time.perf_counter()
            try:
                fn()
            except BaseException as e:  # noqa: BLE001 — a child names the task; here it is raised as is
                if in_child:
                    raise _TaskError(name, e) from e
                raise
            report[name] = time.perf_counter() - t0

    children = []
    try:
        for _ in range(workers - 1):
            r, w = os.pipe()
            pid = os.fork()
            if pid == 0:  # a child: its share of the queue; its seconds or its error back; never return
                code, mine = 0, {}
                try:
                    _die_on_interrupt()
                    os.close(r)
                    drain(mine, True)
                    msg = json.dumps(mine)
                except BaseException as e:  # noqa: BLE001
                    code = 1
                    msg = str(e)
                try:
                    os.write(w, msg.encode("utf-8", "replace")[:60000])
                finally:
                    os._exit(code)
            os.close(w)
            children.append((pid, r))
        drain(seconds, False)
    except BaseException:
        for pid, r in children:
            _kill(pid, r)
        os.close(queue_r)
        raise
    os.close(queue_r)
    failed = None
    for pid, r in children:
        msg = b""
        try:
            while chunk := os.read(r, 65536):
                msg += chunk
        finally:
            os.close(r)
            _, status = os.waitpid(pid, 0)
        text = msg.decode("utf-8", "replace")
        if os.waitstatus_to_exitcode(status) == 0:
            seconds.update(json.loads(text or "{}"))
        elif failed is None:
            failed = text or f"a writer process ended with {os.waitstatus_to_exitcode(status)}"
    if failed is not None:
        raise OSError(failed)
    return seconds


class _TaskError(Exception):
    def __init__(self, name, error):
        super().__init__(f"writing {name} failed: {type(error).__name__}: {error}")
        self.name = name


def _kill(pid, fd) -> None:
    """Stop the child ``pid`` (SIGKILL), close its pipe ``fd`` and reap it."""
    import signal

    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    os.close(fd)
    os.waitpid(pid, 0)
