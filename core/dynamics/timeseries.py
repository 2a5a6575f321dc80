"""Time stamps of on-machine series: strictly increasing, evenly sampled (a recursive filter assumes
one sampling interval; a changing rate would silently mistime every correction)."""
from __future__ import annotations

import numpy as np

from ..errors import InputError

#: largest relative deviation of a sampling interval from the median one
RATE_TOLERANCE = 0.01


def sampling_rate(t, what: str = "data", row_offset: int = 0, lines=None,
                  missing: str = "not in the series") -> float:
    """The sampling rate (Hz) of time stamps t (s); InputError naming the first bad row otherwise.
    ``row_offset`` turns array positions into the file's row numbers in messages; ``lines`` (one per
    sample) gives them instead where rows were dropped (a NaN row dropped on reading: positions are
    not lines then), and an interval whose two samples are not on neighbouring lines is said to span
    the lines between, which ``missing`` explains."""
    t = np.asarray(t, dtype=np.float64)
    ln = (np.arange(t.size) + row_offset) if lines is None else np.asarray(lines, dtype=np.int64)

    def gap(i: int) -> str:
        """What lies between samples i − 1 and i when they are not neighbouring lines."""
        a, b = int(ln[i - 1]), int(ln[i])
        if b - a <= 1:
            return ""
        span = f"line {a + 1}" if b - a == 2 else f"lines {a + 1}–{b - 1}"
        return f": {span} {'was' if b - a == 2 else 'were'} {missing}"

    if t.size < 3:
        raise InputError(f"{what}: {t.size} samples — too few for a time series")
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(f"{what}: line {ln[i]}: time stamp is not a number")
    dt = np.diff(t)
    if np.any(dt == 0):
        i = int(np.flatnonzero(dt == 0)[0]) + 1
        before = "the line before" if ln[i] - ln[i - 1] <= 1 else f"line {ln[i - 1]}"
        raise InputError(f"{what}: line {ln[i]}: duplicated time stamp (the same as {before})")
    if np.any(dt < 0):
        i = int(np.flatnonzero(dt < 0)[0]) + 1
        before = "the line before" if ln[i] - ln[i - 1] <= 1 else f"line {ln[i - 1]}"
        raise InputError(f"{what}: line {ln[i]}: time goes backwards (earlier than {before}); time "
                         "stamps must increase")
    med = float(np.median(dt))
    off = np.abs(dt - med) > RATE_TOLERANCE * med
    if np.any(off):
        i = int(np.flatnonzero(off)[0]) + 1
        raise InputError(f"{what}: line {ln[i]}: the sampling interval changes "
                         f"({dt[i - 1] * 1e3:.6g} ms instead of {med * 1e3:.6g} ms, "
                         f"{int(off.sum())} such intervals){gap(i)}; the dynamic model needs one sampling "
                         f"rate — {'repair the missing row(s) (interpolate them)' if gap(i) else 'resample'} "
                         "or split the file")
    return float((t.size - 1) / (t[-1] - t[0]))  # the mean interval: exact for evenly spaced stamps
