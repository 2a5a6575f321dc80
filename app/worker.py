"""Long work off the event loop: a QThread running one function with the core's Progress.

The Progress sink emits a queued signal (the progress bar moves in the GUI thread); Cancel sets the
CancelToken the steps check between chunks. Errors come back as one message, never a traceback in a
dialog: PointsProError as written, anything else as an internal error naming its type.
"""
from __future__ import annotations

from typing import Callable

from PySide6 import QtCore


class _Job(QtCore.QObject):
    progressed = QtCore.Signal(float, str)
    finished = QtCore.Signal(object)
    failed = QtCore.Signal(str)

    def __init__(self, fn: Callable):
        super().__init__()
        from pointspro.core.progress import CancelToken

        self.fn, self.token = fn, CancelToken()

    @QtCore.Slot()
    def run(self):
        from pointspro.core.errors import Cancelled, PointsProError
        from pointspro.core.progress import Progress

        try:
            self.finished.emit(self.fn(Progress(lambda f, m: self.progressed.emit(f, m), self.token)))
        except Cancelled:
            self.failed.emit("cancelled")
        except PointsProError as e:
            self.failed.emit(str(e))
        except Exception as e:  # a bug: said in the log, the window stays
            self.failed.emit(f"internal error: {type(e).__name__}: {e}")


class Worker(QtCore.QObject):
    """One job at a time. ``busy`` tells whether a job runs; ``done(result)`` / ``failed(message)``
    arrive in the GUI thread after the thread has stopped."""

    progressed = QtCore.Signal(float, str)
    done = QtCore.Signal(object)
    failed = QtCore.Signal(str)

    def __init__(self, parent=None):
        super().__init__(parent)
        self._thread = None
        self._job = None

    @property
    def busy(self) -> bool:
        return self._thread is not None

    def start(self, fn: Callable) -> bool:
        if self._thread is not None:
            return False
        job = _Job(fn)
        thread = QtCore.QThread(self)
        job.moveToThread(thread)
        thread.started.connect(job.run)
        job.progressed.connect(self.progressed)
        # bound slots of this (GUI-thread) object: queued into the GUI thread, never run in the job's
        job.finished.connect(self._finished)
        job.failed.connect(self._failed)
        self._thread, self._job = thread, job
        thread.start()
        return True

    def cancel(self) -> None:
        if self._job is not None:
            self._job.token.cancel()

    @QtCore.Slot(object)
    def _finished(self, res):
        self._end(res, None)

    @QtCore.Slot(str)
    def _failed(self, msg):
        self._end(None, msg)

    def _end(self, res, err):
        self._thread.quit()
        self._thread.wait()
        self._thread = self._job = None
        if err is None:
            self.done.emit(res)
        else:
            self.failed.emit(err)
