"""Progress on the terminal: a redrawn bar on a TTY, plain lines otherwise (logs, CI, pipes)."""
from __future__ import annotations

import sys
import time


class TerminalProgress:
    def __init__(self, stream=None, label: str = ""):
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.label = label
        self._last_msg = None
        self._last_draw = 0.0

    def __call__(self, fraction: float, message: str) -> None:
        if self.tty:
            now = time.monotonic()
            if now - self._last_draw < 0.05 and fraction < 1.0:
                return
            self._last_draw = now
            width = 30
            fill = int(round(fraction * width))
            self.stream.write(f"\r{self.label} [{'#' * fill}{'.' * (width - fill)}] "
                              f"{fraction * 100:5.1f}% {message[:40]:<40}")
            self.stream.flush()
        elif message and message != self._last_msg:
            self.stream.write(f"{self.label} {fraction * 100:5.1f}% {message}\n")
            self.stream.flush()
        self._last_msg = message

    def done(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
