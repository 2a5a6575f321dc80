"""Profiles and power spectral densities of a gridded form-error map (core.maps.MapGrid), and of a
stylus profile's residual along its line (profile_slope, profile_psd, profile_power, profile_astigmatism).

Profile at angle θ through a point: the map sampled by bilinear interpolation along the line at steps
of one spacing, NaN where the map has no value. The steps are placed so that the samples fall on the
grid's nodes wherever the line runs along a row or a column through nodes (the 0° and 90° profiles
through a centre on a node — bspline_map's nodes are multiples of the spacing): interpolating between
nodes would damp what the map holds (a ripple of 4 nodes per period read 0.707 of its amplitude at
0.43 spacing off the nodes). Radial profile: the mean (and spread) of the map in rings of one grid
spacing — the azimuthal average an optician reads the rotationally symmetric zones from.

PSD (ISO 10110-8 / ISO 25178-2 conventions, one-sided in 1-D): with the Hann window w, per unit length
    1-D:  PSD(f) = 2 Δx |Σ w z e^{−2πi f x}|² / (N Σ w² v/N)       (scipy.signal.periodogram's definition
                                                                  when every node v of the line is mapped)
    2-D:  PSD(fx, fy) = Δx Δy |FFT2(w z)|² / (Nx Ny mean(w² v))
with v = 1 at mapped nodes and 0 elsewhere: unmapped nodes count as zero after the mean is removed,
and the density is divided by the window's energy over the mapped nodes, not by their plain fraction
— the Hann window weights the middle of a line more than its ends, so on a disk (a row's mapped
nodes in its middle) the plain fraction read a ripple's PSD 20 % too strong (2-D 29 %), on an annulus
8 % too weak (2-D 40 %). The 1-D PSD removes each line's own mean (over its mapped nodes) and
averages the lines at least half mapped: ∫ PSD df = the lines' variance along that direction (the
variance of the map less that of the line means: a ripple along x is all in psd_x and leaves psd_y
zero — one global mean put the lines' offsets into psd_y's lowest bins); the 2-D PSD removes the
map's mean: ∫∫ PSD dfx dfy = the variance of the map. Both are window-weighted (w²) variances, equal
to the plain ones for a statistically uniform map (tested on a disk and an annulus: within 2 %).
Units: z in mm, f in 1/mm, PSD in mm²·mm (1-D) and mm²·mm² (2-D).
"""
from __future__ import annotations

import numpy as np


def cos_sin_deg(angle_deg: float) -> tuple[float, float]:
    """(cos θ, sin θ) of an angle in degrees, exact at multiples of 90° (np.cos(π/2) is 6.1e-17: a
    90° profile's x read −3.9e-14 mm instead of 0, and a join with map.csv's nodes failed — a review)."""
    q, r = divmod(float(angle_deg), 90.0)
    if r == 0.0:
        return ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[int(q) % 4]
    t = np.deg2rad(angle_deg)
    return float(np.cos(t)), float(np.sin(t))


def profile(grid, angle_deg: float = 0.0, through=(0.0, 0.0)):
    """(s, z): signed distance along the line (mm) and map value (mm) at steps of one spacing.

    s runs over s₀ + k·spacing, s₀ the projection onto the line of the node nearest ``through``
    (modulo the spacing): a line along a row or a column of nodes samples the nodes themselves (a
    centre on a node: s = 0 is the centre and, at 0° and 90°, every sample a node), where samples
    starting at −(½ diagonal + spacing) fell up to half a spacing between them and bilinear
    interpolation damped the map's finest detail. Samples within 10⁻⁹ spacing of a node's row or
    column are put on it, so rounding neither mixes in the neighbour nor loses the last node."""
    d = float(grid.spacing)
    xs, ys = np.asarray(grid.xs, dtype=np.float64), np.asarray(grid.ys, dtype=np.float64)
    cx, cy = float(through[0]), float(through[1])
    c, sn = cos_sin_deg(angle_deg)
    nx_ = xs[0] + d * np.round((cx - xs[0]) / d)  # the node nearest the centre (on the grid's lattice)
    ny_ = ys[0] + d * np.round((cy - ys[0]) / d)
    s0 = ((nx_ - cx) * c + (ny_ - cy) * sn) % d
    # to the farthest corner of the grid (½ diagonal for a centre in the middle of the grid)
    half = float(np.hypot(max(abs(xs[0] - cx), abs(xs[-1] - cx)), max(abs(ys[0] - cy), abs(ys[-1] - cy)))) + d
    k0, k1 = int(np.floor((-half - s0) / d)), int(np.ceil((half - s0) / d))
    s = s0 + d * np.arange(k0, k1 + 1, dtype=np.float64)
    px = _onto_nodes(cx + s * c, xs, d)
    py = _onto_nodes(cy + s * sn, ys, d)
    z = bilinear(ys, xs, grid.z, py, px)
    keep = np.isfinite(z)
    if not keep.any():
        return s[:0], z[:0]
    i0, i1 = np.argmax(keep), len(keep) - np.argmax(keep[::-1])
    return s[i0:i1], z[i0:i1]


def _onto_nodes(p, axis, d):
    """p with the values within 10⁻⁹·d of a node coordinate of ``axis`` (uniform, step d) set to it."""
    k = np.round((p - axis[0]) / d)
    on = (np.abs(p - (axis[0] + d * k)) <= 1e-9 * d) & (k >= 0) & (k <= len(axis) - 1)
    out = p.copy()
    out[on] = axis[k[on].astype(np.intp)]
    return out


def bilinear(ys, xs, z, py, px) -> np.ndarray:
    """z (ny × nx on the ascending axes ys, xs) bilinearly interpolated at the points (py, px), NaN
    outside the grid or where a NaN node carries weight — scipy's RegularGridInterpolator((ys, xs),
    z, "linear", bounds_error=False, fill_value=NaN) to the last bit where the cell's four nodes are
    valid (same cell search, same expression; tested), without importing scipy.interpolate
    (0.15–0.25 s of a batch's start; issue 17). Unlike it, a point on a node or a cell's edge next to
    unmapped nodes keeps its value (``_term``)."""
    ys, xs = np.asarray(ys, dtype=np.float64), np.asarray(xs, dtype=np.float64)
    px, py = np.asarray(px, dtype=np.float64), np.asarray(py, dtype=np.float64)
    out = np.full(px.shape, np.nan)
    inside = (px >= xs[0]) & (px <= xs[-1]) & (py >= ys[0]) & (py <= ys[-1])
    qx, qy = px[inside], py[inside]
    i = np.clip(np.searchsorted(ys, qy, "right") - 1, 0, len(ys) - 2)   # ys[i] ≤ y < ys[i + 1]
    j = np.clip(np.searchsorted(xs, qx, "right") - 1, 0, len(xs) - 2)
    ty = (qy - ys[i]) / (ys[i + 1] - ys[i])
    tx = (qx - xs[j]) / (xs[j + 1] - xs[j])
    out[inside] = (_term(z[i, j], 1 - ty, 1 - tx) + _term(z[i, j + 1], 1 - ty, tx)
                   + _term(z[i + 1, j], ty, 1 - tx) + _term(z[i + 1, j + 1], ty, tx))
    return out


def _term(zc, wy, wx):
    """One corner's share z·wy·wx, 0 where a weight is 0: a point on a node or on a cell's edge does
    not use the nodes across the cell, and NaN × 0 = NaN there lost the map's rim nodes from the
    profiles (a map row from −640 to 640 mm profiled from −630; a review). Elsewhere the same bits."""
    return np.where((wy == 0.0) | (wx == 0.0), 0.0, zc * wy * wx)


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
    return zz, v


def _hann(n: int) -> np.ndarray:
    """periodogram_hann's periodic Hann window."""
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


def psd_1d(grid, axis: str = "x"):
    """(f (1/mm), PSD (mm³)) averaged over the map's rows (axis 'x') or columns ('y') that are at
    least half mapped: each line less its own mean over its mapped nodes (unmapped nodes 0), its
    periodogram divided by the share of the window's energy on its mapped nodes, Σ w²v / Σ w²
    (module doc: ∫ PSD df = the lines' variance)."""
    z = np.asarray(grid.z, dtype=np.float64)
    v = np.isfinite(z)
    if not v.any():
        raise ValueError("the map has no valid node")
    data, valid = (z, v) if axis == "x" else (z.T, v.T)
    rows = valid.mean(axis=1) > 0.5  # lines at least half inside the map
    if not rows.any():
        raise ValueError("no grid line is half inside the map")
    data, valid = data[rows], valid[rows]
    zz = np.where(valid, data, 0.0)
    mean = zz.sum(axis=1) / valid.sum(axis=1)
    zz = np.where(valid, zz - mean[:, None], 0.0)
    f, p = periodogram_hann(zz, fs=1.0 / grid.spacing)
    w2 = _hann(zz.shape[1]) ** 2
    energy = (valid @ w2) / w2.sum()  # the window's energy on the mapped nodes, per line
    return f, np.mean(p / energy[:, None], axis=0)


def periodogram_hann(x, fs: float):
    """(f, one-sided PSD) of each row of ``x`` with a periodic Hann window, density scaling, no
    detrending — scipy.signal.periodogram(x, fs, window="hann", detrend=False, scaling="density")
    in numpy alone (tests/test_maps.py compares them): importing scipy.signal (and with it
    scipy.stats) cost a batch 0.6 s for this one function.

        w_n = ½ − ½ cos(2πn/N),   P(f_k) = c_k |Σ_n w_n x_n e^{−2πikn/N}|² / (fs Σ w_n²),
        c_k = 2 except at f = 0 and (N even) the Nyquist frequency, where c_k = 1."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    w = _hann(n)
    p = np.abs(np.fft.rfft(x * w, axis=-1)) ** 2 / (fs * np.sum(w * w))
    if n % 2:
        p[..., 1:] *= 2.0
    else:
        p[..., 1:-1] *= 2.0
    return np.fft.rfftfreq(n, 1.0 / fs), p


def psd_2d(grid):
    """(fx, fy, PSD) with fx, fy in 1/mm (fftshift order) and PSD in mm⁴ (mm² per (1/mm)²): the map
    less its mean, unmapped nodes 0, divided by the window's energy on the mapped nodes (module doc:
    ∫∫ PSD = the map's variance)."""
    zz, v = _filled(grid)
    ny, nx = zz.shape
    w = np.outer(np.hanning(ny), np.hanning(nx))
    F = np.fft.fftshift(np.fft.fft2(zz * w))
    d = grid.spacing
    w2 = w * w
    psd = (d * d) * np.abs(F) ** 2 / (nx * ny * np.mean(w2 * v))
    fx = np.fft.fftshift(np.fft.fftfreq(nx, d))
    fy = np.fft.fftshift(np.fft.fftfreq(ny, d))
    return fx, fy, psd


# --- stylus profiles (core.profiles): a residual r(u) along one line ------------------------------

def profile_slope(u, r, window_mm: float | None = None) -> tuple[np.ndarray, float]:
    """(slope of r along u at each point (rad), window used (mm)): the least-squares line through the
    points within ±window/2 of each point (cumulative sums: O(N)), so noise is not differentiated
    point to point. Default window: 1 % of the profile's length, at least 5 points' spacing."""
    u = np.asarray(u, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    order = np.argsort(u, kind="stable")
    us, rs = u[order], r[order]
    n = len(us)
    if n < 3:
        return np.zeros(n), 0.0
    step = float(np.median(np.diff(us)))
    if window_mm is None:
        window_mm = max(0.01 * float(us[-1] - us[0]), 5.0 * step)
    lo = np.searchsorted(us, us - 0.5 * window_mm, side="left")
    hi = np.searchsorted(us, us + 0.5 * window_mm, side="right")
    uc = us - us.mean()
    rc = rs - rs.mean()
    cs = [np.concatenate([[0.0], np.cumsum(a)]) for a in (np.ones(n), uc, uc * uc, rc, uc * rc)]
    m, su, suu, sr, sur = (c[hi] - c[lo] for c in cs)
    den = m * suu - su * su
    with np.errstate(divide="ignore", invalid="ignore"):
        slope_sorted = np.where(den > 0, (m * sur - su * sr) / den, 0.0)
    out = np.empty(n)
    out[order] = slope_sorted
    return out, float(window_mm)


def profile_psd(u, r) -> tuple[np.ndarray, np.ndarray]:
    """(f (1/mm), one-sided PSD (mm³)) of r along u: resampled linearly on the median spacing, mean
    removed, Hann window (periodogram_hann: ∫PSD df = variance)."""
    u = np.asarray(u, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    order = np.argsort(u, kind="stable")
    us, rs = u[order], r[order]
    step = float(np.median(np.diff(us)))
    grid = np.arange(us[0], us[-1] + 0.5 * step, step)
    z = np.interp(grid, us, rs)
    return periodogram_hann(z - z.mean(), fs=1.0 / step)


def profile_power(u, r, half: float) -> float:
    """The quadratic coefficient a₂ (1/mm) of the least-squares a₀ + a₁u + a₂u² of r over |u| ≤ half:
    the profile's power; a₂·half² is its sag at the edge of ±half (mm)."""
    u = np.asarray(u, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    keep = np.abs(u) <= half
    t = u[keep] / half
    A = np.column_stack([np.ones_like(t), t, t * t])
    coef, *_ = np.linalg.lstsq(A, r[keep], rcond=None)
    return float(coef[2] / (half * half))


def profile_astigmatism(items) -> dict | None:
    """A coarse astigmatism from profiles at two or more azimuths, stated as such. ``items``: (angle
    in degrees, u, r) with r the profile's form error including its power (mm).

    Each profile's power a₂ over the common half-length h (the shortest profile's reach on both sides
    of the axis); astigmatism W = A·ρ²·cos 2(θ − θ₀) makes a₂(θ) = P + A cos 2(θ − θ₀)/h². Two
    azimuths give the difference of their powers, (a₂(θ₁) − a₂(θ₂))·h² = 2A cos 2(θ₁ − θ₀) for crossed
    profiles: the astigmatism's PV over ±h when the profiles lie along its axes, less otherwise. Three
    azimuths or more (mod 180°) determine A and θ₀ by least squares."""
    angles = np.array([float(a) % 180.0 for a, _, _ in items])
    if len(np.unique(np.round(angles, 9))) < 2:
        return None
    h = min(min(-np.min(u), np.max(u)) for _, u, _ in items)
    if not h > 0:
        return None
    a2 = np.array([profile_power(u, r, h) for _, u, r in items])
    power_um = a2 * h * h * 1e3
    out = {"method": "", "common_half_length_mm": float(h)}
    for a, p in zip(angles, power_um):
        out[f"power_um_at_{a:g}deg"] = float(p)
    ua = np.unique(np.round(angles, 9))
    if len(ua) == 2:
        i = int(np.argmax(angles == angles[0]))
        j = int(np.argmax(angles != angles[0]))
        diff = float(power_um[i] - power_um[j])
        out["astigmatism_pv_estimate_um"] = abs(diff)
        out["method"] = (f"difference of the powers of the profiles at {angles[i]:g}° and {angles[j]:g}° "
                         f"over ±{h:.4g} mm: a coarse estimate from two profiles — the astigmatism's PV "
                         "when they lie along its axes, a lower bound otherwise; its axis is not "
                         "determined")
        out["crossing_angle_deg"] = float(abs(angles[i] - angles[j]))
        return out
    t = np.radians(2.0 * angles)
    A = np.column_stack([np.ones_like(t), np.cos(t), np.sin(t)])
    (p, a, b), *_ = np.linalg.lstsq(A, power_um, rcond=None)
    amp = float(np.hypot(a, b))
    out["astigmatism_pv_estimate_um"] = 2.0 * amp
    out["astigmatism_axis_deg"] = float(np.degrees(0.5 * np.arctan2(b, a)) % 180.0)
    out["method"] = (f"powers of {len(items)} profiles at {len(ua)} azimuths over ±{h:.4g} mm fitted as "
                     "P + A·cos 2(θ − θ₀): the astigmatism's PV (2A) and the azimuth θ₀ of its highest "
                     "power, a coarse estimate from profiles")
    return out
