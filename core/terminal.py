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


class BatchProgress:
    """One overall line for inputs run by workers (a process pool, Dask), where no per-step bar can
    reach this process: done and failed counts of the total and the time left.

    On a TTY a tqdm bar (redrawn in place, ETA from the inputs done so far); otherwise one plain line
    per finished input (logs, CI, pipes). Lines the batch prints meanwhile go through ``write`` so
    they never tear the bar."""

    def __init__(self, total: int, stream=None, label: str = "inputs"):
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.total, self.done, self.failed = int(total), 0, 0
        self.label = label
        self._t0 = time.monotonic()
        self.bar = None
        if self.tty:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, file=self.stream, unit="input", dynamic_ncols=True,
                            desc=label, bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| "
                            "{postfix} [{elapsed}<{remaining}]")
            self.bar.set_postfix_str(self._counts(), refresh=True)

    def _counts(self) -> str:
        return f"{self.done} done, {self.failed} failed"

    def advance(self, ok: bool, name: str = "") -> None:
        """One input finished (``ok`` or failed)."""
        self.done += bool(ok)
        self.failed += not ok
        if self.bar is not None:
            self.bar.set_postfix_str(self._counts(), refresh=False)
            self.bar.update(1)
            return
        k = self.done + self.failed
        elapsed = time.monotonic() - self._t0
        left = self.total - k
        eta = f", about {_duration(elapsed / k * left)} left" if left and k else ""
        self.stream.write(f"[{k}/{self.total}] {self._counts()}{eta}"
                          + (f" — {name} {'ok' if ok else 'failed'}" if name else "") + "\n")
        self.stream.flush()

    def write(self, text: str, file=None) -> None:
        """``text`` on its own line of ``file`` (stdout by default) without tearing the bar."""
        file = file or sys.stdout
        if self.bar is not None:
            self.bar.write(text, file=file)
        else:
            file.write(text + "\n")
            file.flush()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _duration(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s} s" if s < 60 else f"{s // 60} min {s % 60:02d} s" if s < 3600 else \
        f"{s // 3600} h {s % 3600 // 60:02d} min"
