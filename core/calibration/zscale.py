"""z-axis scale calibration from a step artefact (seed paper 000 §2.6, §3.2).

A step artefact with calibrated heights (000: 0.2, 2, 5, 11 µm, by white-light interferometry) is
scanned across its edges, several times. Each step height is evaluated as ISO 5436-1 does for a type A
standard: least-squares lines on either side of the edge, away from it, with a common slope (the
artefact's tilt) and an offset h between them:
    z = a + b·x + h·[x > x_edge]        over x_edge − 0.45 L < x < x_edge − 0.15 L and x_edge + 0.15 L < x < x_edge + 0.45 L
(L the distance to the neighbouring edge). Then, over the steps,
    measured = m · calibrated + c        (first-order fit: m the amplification coefficient)
    linearity = max |measured − (m · calibrated + c)|
and a measurement is corrected by z' = z̄ + (z − z̄)/m (heights about the cloud's mean; the offset c is
a property of the evaluation, not of the axis).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import StepError


def find_edges(x, z, count: int) -> np.ndarray:
    """x of the ``count`` strongest steps of a profile (sorted by x): the jump between the medians of
    the samples on either side, in windows of 1 % of the profile, above 10 × the noise and 5 × the
    typical jump (so a wavy profile without steps has none)."""
    o = np.argsort(x)
    x, z = np.asarray(x, float)[o], np.asarray(z, float)[o]
    n = x.size
    w = max(n // 100, 3)
    if n < 8 * w:
        raise StepError(f"{n} points are too few to find steps")
    from numpy.lib.stride_tricks import sliding_window_view

    win = sliding_window_view(z, w)
    med = np.median(win, axis=1)
    jump = np.zeros(n)
    jump[w: n - w + 1] = np.abs(med[w:] - med[: n - 2 * w + 1])
    d = np.diff(z)
    noise = 1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2) + 1e-15
    # a step stands out from the profile's own waviness: 10 × the noise and 5 × the typical jump
    thr = max(10 * noise, 5 * float(np.median(jump[w: n - w + 1])))
    picked = []
    cand = np.argsort(jump)[::-1]
    for i in cand:
        if jump[i] < thr or len(picked) == count + 1:
            break
        if all(abs(i - j) > 2 * w for j in picked):
            picked.append(i)
    if len(picked) < count:
        raise StepError(f"found {len(picked)} step(s) above the noise where {count} calibrated heights "
                        "were given")
    if len(picked) > count:
        # one more step above the noise: the heights would be matched to the wrong steps
        # (a review: 3 heights for a 4-step artefact gave amplification 1.85, exit 0)
        raise StepError(f"found more than {count} steps where {count} calibrated heights were given: give "
                        "the height of every step, in their order along x")
    picked = picked[:count]
    return np.sort(x[picked] - 0.5 * (x[1] - x[0]))


def step_heights(x, z, edges) -> np.ndarray:
    """ISO 5436-1-style height of each step (same unit as z)."""
    x, z = np.asarray(x, float), np.asarray(z, float)
    out = []
    for k, e in enumerate(edges):
        gaps = [abs(e - edges[k - 1])] if k > 0 else []
        gaps += [abs(edges[k + 1] - e)] if k + 1 < len(edges) else []
        L = min(gaps) if gaps else np.ptp(x) / 2
        left = (x > e - 0.45 * L) & (x < e - 0.15 * L)
        right = (x > e + 0.15 * L) & (x < e + 0.45 * L)
        if left.sum() < 3 or right.sum() < 3:
            raise StepError(f"the step at x = {e:.4g} has too few points on a side for the line fits")
        sel = left | right
        A = np.column_stack([np.ones(sel.sum()), x[sel], right[sel].astype(float)])
        coef, *_ = np.linalg.lstsq(A, z[sel], rcond=None)
        out.append(coef[2])
    return np.array(out)


@dataclass
class ZScaleCalibration:
    amplification: float
    offset: float
    linearity: float          # mm
    calibrated: np.ndarray    # mm
    measured: np.ndarray      # mm, mean over scans
    repeatability: np.ndarray  # mm, std over scans (nan with one scan)

    def describe(self) -> dict:
        return {"amplification": self.amplification, "offset_um": self.offset * 1e3,
                "linearity_um": self.linearity * 1e3, "calibrated_um": (self.calibrated * 1e3).tolist(),
                "measured_um": (self.measured * 1e3).tolist(),
                "repeatability_um": (self.repeatability * 1e3).tolist()}


def calibrate(x, z, scan, heights_mm) -> ZScaleCalibration:
    heights = np.asarray(heights_mm, dtype=np.float64)
    if heights.size < 2:
        raise StepError("the amplification needs at least two calibrated step heights")
    per = []
    for s in np.unique(scan):
        m = scan == s
        edges = find_edges(x[m], z[m], heights.size)
        h = step_heights(x[m], z[m], edges)
        # a step down is a height too: sign by the calibrated heights' order along the profile
        per.append(np.abs(h))
    per = np.array(per)
    meas = per.mean(axis=0)
    rep = per.std(axis=0, ddof=1) if per.shape[0] > 1 else np.full(heights.size, np.nan)
    m, c = np.polyfit(heights, meas, 1)
    lin = float(np.max(np.abs(meas - (m * heights + c))))
    return ZScaleCalibration(float(m), float(c), lin, heights, meas, rep)
