"""Vibrations in on-machine series: spectra in time and along the surface, aliasing, phase lag.

Aliasing (004 §"Mid-to-high frequency"): a vibration at f sampled at fs appears at
    f_a = |f − fs · NINT(f / fs)|          (NINT rounds half up; 680 Hz at 1 kHz → 320 Hz)
Phase lag of y behind u from their analytic signals (Hilbert transform, 004 Fig. 9d):
    φ(t) = arg H[u](t) − arg H[y](t), unwrapped; the median over the middle 80 % of the series.
Advice (seed 000 §3.1): sample at least twice the highest vibration frequency present, and choose the
scan speed so that the vibrations that remain fall at spatial periods the map does not need.
"""
from __future__ import annotations

import numpy as np


def aliased_frequency(f_hz, fs_hz: float):
    f = np.asarray(f_hz, dtype=np.float64)
    return np.abs(f - fs_hz * np.floor(f / fs_hz + 0.5))


def psd_time(v, fs: float):
    """(f Hz, PSD mm²/Hz) by Welch (Hann, linear detrend)."""
    from scipy.signal import welch

    v = np.asarray(v, dtype=np.float64)
    return welch(v, fs=fs, nperseg=min(len(v), 8192), detrend="linear")


def psd_space(x, y, v):
    """(spatial frequency 1/mm, PSD mm²·mm) along the scan path: v resampled at the mean step of
    the path length s = Σ |Δ(x, y)|, then Welch."""
    from scipy.signal import welch

    s = np.r_[0.0, np.cumsum(np.hypot(np.diff(x), np.diff(y)))]
    ds = s[-1] / max(len(s) - 1, 1)
    if ds <= 0:
        return np.array([0.0]), np.array([0.0])
    keep = np.r_[True, np.diff(s) > 0]
    su = np.arange(0.0, s[-1], ds)
    vu = np.interp(su, s[keep], np.asarray(v, dtype=np.float64)[keep])
    return welch(vu, fs=1.0 / ds, nperseg=min(len(vu), 8192), detrend="linear")


def phase_lag_hilbert_deg(u, y) -> float:
    """Median phase lag (deg) of y behind u from their analytic signals (both detrended)."""
    from scipy.signal import detrend, hilbert

    pu = np.unwrap(np.angle(hilbert(detrend(np.asarray(u, dtype=np.float64)))))
    py = np.unwrap(np.angle(hilbert(detrend(np.asarray(y, dtype=np.float64)))))
    n = len(pu)
    mid = slice(n // 10, n - n // 10)
    return float(np.degrees(np.median(pu[mid] - py[mid])))


def dominant_peaks(f, p, count: int = 3, fmin: float = 0.0) -> list[float]:
    """Frequencies of the largest local maxima of a spectrum above fmin."""
    from scipy.signal import find_peaks

    keep = f > fmin
    f, p = f[keep], p[keep]
    if p.size < 3:
        return []
    idx, _ = find_peaks(p)
    idx = idx[np.argsort(p[idx])[::-1][:count]]
    return [float(f[i]) for i in sorted(idx)]


#: a line of the encoder's spectrum is the scan's dominant frequency when its power stands this many
#: times above the spectrum's median (its floor): white noise's largest of N/2 bins stands ~ln(N/2)/ln 2
#: times above its median (≈ 20 for 10⁶ samples), a spindle's line thousands of times
LINE_ABOVE_FLOOR = 100.0
#: … and when the record holds at least this many of its periods (below, a linear trend's remainder)
MIN_PERIODS = 3.0
#: the trend removed before the spectrum: a polynomial of this degree in time
TREND_DEGREE = 3


def dominant_frequency(v, fs: float) -> tuple[float | None, str]:
    """The frequency (Hz) of the largest line of v's spectrum — a periodogram of the whole record (Hann,
    a cubic trend removed), its bin 1/T, so that a spindle at 0.14–15 rpm (004 Table 1: 2.3 mHz–0.25 Hz)
    is resolved where Welch's 8192-sample segments at 1 kHz cut below ~0.25 Hz — interpolated between
    bins; with the reason when there is none: the largest bin from MIN_PERIODS periods in the record up
    is no true local maximum (above the bin below it and not below the bin above), or does not stand
    LINE_ABOVE_FLOOR times above the floor (a constant feed: "3.33 Hz" was quoted from its rounding
    noise). A smooth motion with no repeating content (a spiral on a rotationally symmetric part, an
    accelerating axis) leaves a steep spectrum whose largest bin is the first allowed: it read as a line
    at exactly MIN_PERIODS/T (a review: 0.0118 Hz on a sphere's spiral, 0.15 Hz on an axis at constant
    acceleration). The cubic trend (a linear one before) takes the part's sag off a spiral, so that a
    1/rev line of a tilted part on it is found."""
    from scipy.signal import periodogram

    v = np.asarray(v, dtype=np.float64)
    n = v.size
    if n < 16:
        return None, "too few samples for a spectrum"
    P = np.polynomial.polynomial
    s = np.linspace(-1.0, 1.0, n)  # scaled time: the cubic is well conditioned at any length
    r = v - P.polyval(s, P.polyfit(s, v, TREND_DEGREE))
    if not np.std(r) > 1e-12 * max(float(np.max(np.abs(v))), 1.0):  # rounding: 4e-13 mm at 2 m
        return None, ("the encoder moves at a constant feed or a smooth acceleration (nothing beyond a cubic "
                      "trend): no dominant frequency to quote the model's lag at")
    f, p = periodogram(r, fs=fs, window="hann", detrend=False)
    k0 = max(int(np.ceil(MIN_PERIODS)), 1)  # bin k holds k periods of the record
    if p.size < k0 + 3:
        return None, "too few samples for a spectrum"
    q = p[k0:-1]
    k = int(np.argmax(q)) + k0
    floor = float(np.median(q))
    if not (p[k] > p[k - 1] and p[k] >= p[k + 1]):
        return None, ("the encoder's spectrum has no line: its power falls from the lowest frequencies "
                      "(a smooth motion with no repeating content, as a spiral on a rotationally symmetric "
                      "part or an accelerating axis): no dominant frequency to quote the model's lag at")
    if not p[k] > 0 or (floor > 0 and p[k] < LINE_ABOVE_FLOOR * floor):
        return None, ("no line of the encoder's spectrum stands clearly above its floor (a motion with no "
                      "repeating content): no dominant frequency to quote the model's lag at")
    a, b, c = (np.log(max(x, 1e-300)) for x in p[k - 1:k + 2])
    den = a - 2 * b + c
    shift = 0.5 * (a - c) / den if den < 0 else 0.0
    return float((k + float(np.clip(shift, -0.5, 0.5))) * f[1]), ""


def advice(fs: float, vibrations_hz, speed_mm_s: float) -> list[str]:
    """Seed 000 §3.1 for each known vibration frequency (> 0 Hz): aliased or not, and the spatial
    period it marks the map with at the scan's speed. A vibration at a multiple of fs aliases to 0 Hz:
    a constant offset or a slow drift, no period (it read "inf µm")."""
    out = []
    for f in vibrations_hz:
        fa = float(aliased_frequency(f, fs))
        if f > fs / 2:
            alias = (f"it appears at {fa:g} Hz, i.e. a false spatial period of {speed_mm_s / fa * 1e3:.3g} µm at "
                     f"{speed_mm_s:.3g} mm/s" if fa > 1e-9 * fs else
                     "it is a multiple of the sampling rate and appears as a constant offset or a slow drift "
                     "(0 Hz)")
            out.append(f"vibration at {f:g} Hz is above the Nyquist frequency ({fs / 2:g} Hz): {alias} — "
                       f"sample at ≥ {2 * f:g} Hz or low-pass the sensor")
        else:
            period = speed_mm_s / f * 1e3
            out.append(f"vibration at {f:g} Hz is sampled correctly; it marks the map with a spatial "
                       f"period of {period:.3g} µm at {speed_mm_s:.3g} mm/s — change the scan speed to "
                       "move it away from the periods of interest")
    return out
