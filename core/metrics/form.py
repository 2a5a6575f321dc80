"""Form-error metrics of a residual over the clear aperture.

    PV   = max(r) − min(r)                       (sensitive to a single spike)
    RMS  = sqrt(Σ wᵢ (rᵢ − r̄)² / Σ wᵢ), r̄ = Σ wᵢ rᵢ / Σ wᵢ: over the area (ISO 10110-5), wᵢ the area
           point i stands for (core.metrics.area_weights) — all equal on an even sampling (a raster,
           a pixel map: the plain mean), by annuli on a star or spiral scan, which crowd their centre
    PVr  = PV(Zernike fit, Fringe Z1…Z36) + 3 · RMS(r − fit)
           (Evans, "Robust specification of optical surfaces", Proc. SPIE 7426, 2009: the fit carries
           the form, the 3·RMS term what the fit leaves, so one outlier no longer dominates.)
    slope RMS = RMS of |∇r| after removing the mean slope (tilt), µrad, over the area as the RMS; the
           gradient comes from a smoothing bicubic B-spline of the residual (core.maps.bspline),
           not from differences between points — but its knots follow the points' density (two
           spacings), so what noise the spline keeps is differentiated too: the figure is biased up
           by the noise (an independent review, a 20 mm disk of 43.0 µrad true slope RMS: ×1.2–1.7 at
           10 nm of noise, ×3.7–7.1 at 50 nm, rising with the point count from 5k to 200k). The
           recipe's ``uncertainty:`` block removes that bias (docs/uncertainty.md: slope RMS is a
           quadratic figure, f_c² = f₀² − (mean f_i² − f₀²)); without it the figure is as measured.

All inputs in mm; outputs in µm and µrad.
"""
from __future__ import annotations

import numpy as np

from . import zernike as zk
from .area_weights import weighted_rms

#: Evans' PVr uses the 36 Fringe terms (through radial order 10)
PVR_TERMS = 36


def _radius(x, y, radius: float | None, center=(0.0, 0.0)) -> float:
    r = (float(np.max(np.hypot(x - center[0], y - center[1]))) if radius is None
         else float(radius))
    return r if r > 0 else 1.0


def pvr(x, y, r, radius: float | None = None, center=(0.0, 0.0)) -> float | None:
    """Robust PV in the unit of r (see module doc); None with 72 points or fewer (the 36-term fit
    needs more than twice its terms — it was the plain PV, labelled PVr, without a word).

    The 36-term fit is over the disk of ``radius`` about ``center`` (core.metrics.pupil chooses
    them for a run: never a file's corner origin, where the fit is singular)."""
    x, y, r = (np.asarray(a, dtype=np.float64) for a in (x, y, r))
    R = _radius(x, y, radius, center)
    pairs = zk.terms(PVR_TERMS, "fringe")
    if len(r) <= 2 * len(pairs):
        return None
    resid = zk.fit(x, y, r, R, pairs, center=center).residual
    fitted = r - resid
    return float(np.ptp(fitted) + 3.0 * np.sqrt(np.mean(resid**2)))


def slope_rms_urad(x, y, r, spline=None, weights=None) -> float | None:
    """RMS slope (µrad) of the residual about its mean slope, over the area (``weights``: the points'
    areas, core.metrics.area_weights; None: equal); None when too few points."""
    from ..maps.bspline import fit_bspline

    x, y, r = (np.asarray(a, dtype=np.float64) for a in (x, y, r))
    if len(r) < 50:
        return None
    try:
        s = spline if spline is not None else fit_bspline(x, y, r)
    except ValueError:
        return None
    gx, gy = s.gradient(x, y) if hasattr(s, "gradient") else (s(x, y, dx=1), s(x, y, dy=1))
    if weights is None:
        gx -= gx.mean()
        gy -= gy.mean()
        return float(np.sqrt(np.mean(gx * gx + gy * gy)) * 1e6)
    return float(np.hypot(weighted_rms(gx, weights), weighted_rms(gy, weights)) * 1e6)


def form_metrics(x, y, r, radius: float | None = None, slopes: bool = True,
                 center=(0.0, 0.0), pvr_parts=None, spline=None, weights=None) -> dict:
    """PV, RMS, PVr (µm) and slope RMS (µrad) of residual r (mm) at points (x, y) (mm); PVr's fit
    over the disk of ``radius`` about ``center``. ``pvr_parts`` (PV of the 36-term fit, RMS of its
    rest; mm) and ``spline`` (the residual's smoothing spline): already fitted on these data by a step
    (core.pipeline._reusable), used instead of fitting again. ``weights``: the points' areas for the
    RMS and the slope RMS (core.metrics.area_weights; None: an even sampling, the plain mean). PVr
    stays Evans' figure over the points: its rest is the fit's leftover, noise mostly, alike everywhere."""
    r = np.asarray(r, dtype=np.float64)
    if r.size == 0:
        return {"rms_um": None, "pv_um": None, "pvr_um": None, "slope_rms_urad": None}
    out = {"rms_um": weighted_rms(r, weights) * 1e3,
           "pv_um": float(np.ptp(r) * 1e3),
           "pvr_um": _um(float(pvr_parts[0] + 3.0 * pvr_parts[1]) if pvr_parts is not None
                         else pvr(x, y, r, radius, center))}
    out["slope_rms_urad"] = slope_rms_urad(x, y, r, spline, weights) if slopes else None
    return out


def _um(v_mm: float | None) -> float | None:
    return None if v_mm is None else v_mm * 1e3
