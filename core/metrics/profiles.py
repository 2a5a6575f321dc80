"""Profiles and power spectral densities of a gridded form-error map (core.maps.MapGrid).

Profile at angle θ through a point: the map sampled by bilinear interpolation along the line, NaN
where the map has no value. Radial profile: the mean (and spread) of the map in rings of one grid
spacing — the azimuthal average an optician reads the rotationally symmetric zones from.

PSD (ISO 10110-8 / ISO 25178-2 conventions, one-sided in 1-D): with the Hann window w, of the
mean-removed heights, per unit length
    1-D:  PSD(f) = 2 Δx |Σ w z e^{−2πi f x}|² / (N Σw²/N)        (scipy.signal.periodogram's definition)
    2-D:  PSD(fx, fy) = Δx Δy |FFT2(w z)|² / (Nx Ny mean(w²))
so that ∫ PSD df = variance of z (Parseval; tested). Unmapped nodes count as zero after the mean is
removed and the density is divided by the mapped fraction (the usual correction for a circular
aperture inside the square grid). Units: z in mm, f in 1/mm, PSD in mm²·mm (1-D) and mm²·mm² (2-D).
"""
from __future__ import annotations

import numpy as np


def profile(grid, angle_deg: float = 0.0, through=(0.0, 0.0)):
    """(s, z): signed distance along the line (mm) and map value (mm) at steps of one spacing."""
    from scipy.interpolate import RegularGridInterpolator

    half = 0.5 * float(np.hypot(np.ptp(grid.xs), np.ptp(grid.ys))) + grid.spacing
    s = np.arange(-half, half + 1e-9, grid.spacing)
    t = np.deg2rad(angle_deg)
    px = through[0] + s * np.cos(t)
    py = through[1] + s * np.sin(t)
    f = RegularGridInterpolator((grid.ys, grid.xs), grid.z, bounds_error=False, fill_value=np.nan)
    z = f(np.column_stack([py, px]))
    keep = np.isfinite(z)
    if not keep.any():
        return s[:0], z[:0]
    i0, i1 = np.argmax(keep), len(keep) - np.argmax(keep[::-1])
    return s[i0:i1], z[i0:i1]


def radial_profile(grid, center=(0.0, 0.0)):
    """(r, mean z, std z) in rings of width one spacing."""
    X, Y = np.meshgrid(grid.xs - center[0], grid.ys - center[1])
    v = np.isfinite(grid.z)
    r = np.hypot(X[v], Y[v])
    z = grid.z[v]
    k = np.floor(r / grid.spacing).astype(np.intp)
    n = np.bincount(k)
    s1 = np.bincount(k, weights=z)
    s2 = np.bincount(k, weights=z * z)
    ok = n > 0
    mean = s1[ok] / n[ok]
    std = np.sqrt(np.clip(s2[ok] / n[ok] - mean**2, 0, None))
    return (np.nonzero(ok)[0] + 0.5) * grid.spacing, mean, std


def _filled(grid):
    z = grid.z
    v = np.isfinite(z)
    if not v.any():
        raise ValueError("the map has no valid node")
    zz = np.where(v, z - z[v].mean(), 0.0)
    return zz, v.mean()


def psd_1d(grid, axis: str = "x"):
    """(f (1/mm), PSD (mm³)) averaged over the map's rows (axis 'x') or columns ('y')."""
    zz, frac = _filled(grid)
    v = np.isfinite(grid.z)
    data, valid = (zz, v) if axis == "x" else (zz.T, v.T)
    rows = valid.mean(axis=1) > 0.5  # lines at least half inside the map
    if not rows.any():
        raise ValueError("no grid line is half inside the map")
    f, p = periodogram_hann(data[rows], fs=1.0 / grid.spacing)
    fill = valid[rows].mean(axis=1)[:, None]
    return f, np.mean(p / fill, axis=0)


def periodogram_hann(x, fs: float):
    """(f, one-sided PSD) of each row of ``x`` with a periodic Hann window, density scaling, no
    detrending — scipy.signal.periodogram(x, fs, window="hann", detrend=False, scaling="density")
    in numpy alone (tests/test_maps.py compares them): importing scipy.signal (and with it
    scipy.stats) cost a batch 0.6 s for this one function.

        w_n = ½ − ½ cos(2πn/N),   P(f_k) = c_k |Σ_n w_n x_n e^{−2πikn/N}|² / (fs Σ w_n²),
        c_k = 2 except at f = 0 and (N even) the Nyquist frequency, where c_k = 1."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    w = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)
    p = np.abs(np.fft.rfft(x * w, axis=-1)) ** 2 / (fs * np.sum(w * w))
    if n % 2:
        p[..., 1:] *= 2.0
    else:
        p[..., 1:-1] *= 2.0
    return np.fft.rfftfreq(n, 1.0 / fs), p


def psd_2d(grid):
    """(fx, fy, PSD) with fx, fy in 1/mm (fftshift order) and PSD in mm⁴ (mm² per (1/mm)²)."""
    zz, frac = _filled(grid)
    ny, nx = zz.shape
    w = np.outer(np.hanning(ny), np.hanning(nx))
    F = np.fft.fftshift(np.fft.fft2(zz * w))
    d = grid.spacing
    psd = (d * d) * np.abs(F) ** 2 / (nx * ny * np.mean(w * w) * frac)
    fx = np.fft.fftshift(np.fft.fftfreq(nx, d))
    fy = np.fft.fftshift(np.fft.fftfreq(ny, d))
    return fx, fy, psd
