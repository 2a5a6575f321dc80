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
        import signal

        try:
            os.kill(self.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        os.close(self._read)
        os.waitpid(self.pid, 0)
        self.pid = None


def _can_fork() -> bool:
    from ..parallel import thread_count

    return hasattr(os, "fork") and threading.active_count() == 1 and thread_count() > 1
