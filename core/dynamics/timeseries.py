"""Time stamps of on-machine series: strictly increasing, evenly sampled (a recursive filter assumes
one sampling interval; a changing rate would silently mistime every correction)."""
from __future__ import annotations

import numpy as np

from ..errors import InputError

#: largest relative deviation of a sampling interval from the median one
RATE_TOLERANCE = 0.01


def sampling_rate(t, what: str = "data", row_offset: int = 0) -> float:
    """The sampling rate (Hz) of time stamps t (s); InputError naming the first bad row otherwise.
    ``row_offset`` turns array positions into the file's row numbers in messages."""
    t = np.asarray(t, dtype=np.float64)
    if t.size < 3:
        raise InputError(f"{what}: {t.size} samples — too few for a time series")
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(f"{what}: line {i + row_offset}: time stamp is not a number")
    dt = np.diff(t)
    if np.any(dt == 0):
        i = int(np.flatnonzero(dt == 0)[0]) + 1
        raise InputError(f"{what}: line {i + row_offset}: duplicated time stamp (the same as the "
                         "line before)")
    if np.any(dt < 0):
        i = int(np.flatnonzero(dt < 0)[0]) + 1
        raise InputError(f"{what}: line {i + row_offset}: time goes backwards (earlier than the line "
                         "before); time stamps must increase")
    med = float(np.median(dt))
    off = np.abs(dt - med) > RATE_TOLERANCE * med
    if np.any(off):
        i = int(np.flatnonzero(off)[0]) + 1
        raise InputError(f"{what}: line {i + row_offset}: the sampling interval changes "
                         f"({dt[i - 1] * 1e3:.6g} ms instead of {med * 1e3:.6g} ms, "
                         f"{int(off.sum())} such intervals); the dynamic model needs one sampling rate "
                         "— resample or split the file")
    return float((t.size - 1) / (t[-1] - t[0]))  # the mean interval: exact for evenly spaced stamps
