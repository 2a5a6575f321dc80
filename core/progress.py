"""Progress and cancellation handed to steps as ``ctx.progress`` (core/step.py).

A step calls ``update(fraction, message)``, ``sub(start, end)`` for a slice of the bar given to a
sub-task, and ``check()`` wherever stopping is safe; ``check()`` raises `Cancelled` once the user
cancelled. The sink is any callable ``(fraction, message)`` — a terminal bar, a Qt signal emitted by
the GUI worker, or nothing: a step cannot tell the difference.
"""
from __future__ import annotations

import threading
from typing import Callable

from .errors import Cancelled

Sink = Callable[[float, str], None]


class CancelToken:
    """Thread-safe flag set by whoever may cancel (a GUI button, a signal handler)."""

    def __init__(self):
        self._event = threading.Event()

    def cancel(self):
        self._event.set()

    @property
    def cancelled(self) -> bool:
        return self._event.is_set()


class Progress:
    def __init__(self, sink: Sink | None = None, token: CancelToken | None = None,
                 start: float = 0.0, end: float = 1.0):
        self._sink = sink
        self.token = token or CancelToken()
        self._start, self._end = float(start), float(end)

    def update(self, fraction: float, message: str = "") -> None:
        self.check()
        if self._sink is not None:
            f = min(max(float(fraction), 0.0), 1.0)
            self._sink(self._start + f * (self._end - self._start), message)

    def sub(self, start: float, end: float) -> "Progress":
        """A progress for a sub-task that owns [start, end] of this one's range."""
        span = self._end - self._start
        return Progress(self._sink, self.token, self._start + start * span, self._start + end * span)

    def check(self) -> None:
        if self.token.cancelled:
            raise Cancelled("cancelled by the user")
