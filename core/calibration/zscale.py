"""z-axis scale calibration from a step artefact (seed paper 000 §2.6, §3.2).

A step artefact with certified heights (000: 0.2, 2, 5, 11 µm, by white-light interferometry; or an
ISO 5436-1 type A1 groove, given as its depth twice: once for each edge) is scanned across its edges,
several times. Each scan is first levelled by a robust line (``level``: the median of the slopes
between points a window apart — the steps lie between few of those pairs, so, unlike a least-squares
line through a staircase, it leaves the plateaus level and a tilt of several mrad does not hide the
smaller steps from ``find_edges``). Each step height is then evaluated as ISO 5436-1 does for a type A
standard: least-squares lines on either side of the edge, away from it, fitted jointly with a common
slope (the artefact's tilt) and an offset h between them,
    z = a + b·x + h·[x > x_edge]        over x_edge − 0.45 L < x < x_edge − 0.15 L and x_edge + 0.15 L < x < x_edge + 0.45 L
(L the distance to the nearer neighbouring edge, on the levelled scan — the fit's own line makes h
independent of the levelling), read perpendicularly to that line (ISO 5436-1: the depth is assessed
perpendicularly to the mean line): h·cos(atan(b_total)), b_total the line's slope before levelling —
a tilted artefact is rotated, its planes' vertical separation is h / cos θ.

The windows differ from ISO 5436-1's for a type A1 groove of width W, which fits one mean line over
regions A — outside the groove on each side, from W/3 to W from its edge (the W/3 next to the edge
is ignored for the corners' rounding) — and, parallel to it, the groove bottom's central third C, and
reads one depth at the groove's centre. Here every edge is a step of its own: a staircase has no
"outside", and ISO's A region (W beyond the edge) would reach the next step; the windows stay within
half the distance to the neighbouring edge, and they are symmetric about the edge, so a scan's bow
(the axis's straightness, the artefact's form) cancels in h. For a groove the bottom is used over
0.15–0.45 W and 0.55–0.85 W from its left edge (more of it than the central third, less its centre)
and the top over 0.15–0.45 W outside each edge. With sharp corners both give the same depth; with
corners rounded over more than 0.15 W (A1 grooves are far wider than their corners' radii) the
standard's W/3 is the safer margin.

Over the steps (y the heights of every edge of every scan, N of them, against the certified h):
  - two or more distinct certified heights: the line y = m·h + c by least squares (m the
    amplification coefficient, c an offset of the evaluation, not of the axis), and
        linearity = max |ȳ_k − (m·h_k + c)|        (ȳ_k: edge k's mean over the scans);
  - a single distinct certified height (one step, or a groove measured at both edges): the line has
    no slope to give (a slope and an offset that trade against each other: an A1 groove read 0.5
    for 1.001 — a review), and a step height has no offset: y = m·h through the origin,
    m = Σ h·y / Σ h², and no linearity (it needs two heights).
The amplification's standard uncertainty is the fit's, from its residuals r (GUM H.3):
    u(m) = s / √Σ(h_i − h̄)²   (line, ν = N − 2)
    u(m) = s / √Σ h_i²         (through the origin, ν = N − 1)
    s² = Σ r² / ν,   the sums over all N = scans × edges evaluations
and U95 = t₀.₉₇₅(ν)·u(m). The residuals hold the scans' repeatability and any non-linearity alike (a
non-linearity widens u(m)); with ν = 0 (one edge, or two heights, in one scan) u is not known (nan).
The certificate's uncertainty of the heights is not an input: add its u(h)/h to u(m)/m in quadrature.

A measurement is corrected by z' = z̄ + (z − z̄)/m (heights about the cloud's mean).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import StepError


def _window(n: int) -> int:
    return max(n // 100, 3)


def level(x, z) -> tuple[np.ndarray, float]:
    """(z less the scan's robust line, the line's slope). The slope is the median of the slopes between
    points ``w`` apart along x (w the edge-finding window, 1 % of the scan): only the pairs that
    straddle a step (w + its transition per step: 4 % of them for four sharp steps) are off, so the
    median is the plateaus' slope (they shift it by a fraction of the pairs' noise); a
    least-squares line would lean with the steps' rise (2.1 mrad for the 0.5, 2, 5, 11 µm staircase
    over 10 mm) and tilt every plateau by as much. The level is the median of z less the slope."""
    x, z = np.asarray(x, float), np.asarray(z, float)
    o = np.argsort(x, kind="stable")
    xs, zs = x[o], z[o]
    n = xs.size
    k = _window(n)
    if n <= k:
        return z - np.median(z), 0.0
    dx = xs[k:] - xs[:-k]
    ok = dx > 0
    if not ok.any():
        return z - np.median(z), 0.0
    b = float(np.median((zs[k:] - zs[:-k])[ok] / dx[ok]))
    r = z - b * x
    return r - np.median(r), b


#: a step's jump must exceed this many standard deviations of the jump's noise (find_edges)
JUMP_FACTOR = 8.0


def jump_noise(sigma: float, w: int) -> float:
    """Standard deviation of the difference of two medians of ``w`` independent points of σ
    ``sigma`` each: the median's is √(π/2) σ/√w = 1.2533 σ/√w (large w; the median of 3 has 0.67 σ,
    0.72 by this), the difference's √2 times that."""
    return float(np.sqrt(np.pi / 2) * sigma * np.sqrt(2.0 / w))


def find_edges(x, z, count: int) -> np.ndarray:
    """x of the ``count`` strongest steps of a profile (sorted by x): the profile levelled (``level``),
    the jump between the medians of the samples on either side, in windows of 1 % of the profile,
    above 10 × the points' noise and 5 × the typical jump (so a wavy profile without steps has none);
    where that finds fewer steps than ``count``, above JUMP_FACTOR × the jump's own noise instead
    (``jump_noise`` of the points' σ, or the jumps' robust spread where that is larger): a 0.2 µm step
    under 20 nm of point noise is ~25–55 × its jump's noise but below 10 × the points' (refused at any
    density, a review). Not that lower threshold first: on a dense scan it counts a 20–50 nm bump of
    the artefact's form as a step (a review of that fix). Where more steps than heights stand out, a
    bump's or a groove's flanks (``bumps``) are dropped first."""
    o = np.argsort(x)
    x, z = np.asarray(x, float)[o], np.asarray(z, float)[o]
    n = x.size
    w = _window(n)
    if n < 8 * w:
        raise StepError(f"{n} points are too few to find steps")
    # a tilt gives every window a jump of tilt × width (0.3 µm at 3 mrad over 0.1 mm), and 5 × that
    # typical jump rose above a 0.5 µm step (a review: refused as "found 3 steps" from 2 mrad on)
    z = level(x, z)[0]
    from numpy.lib.stride_tricks import sliding_window_view

    win = sliding_window_view(z, w)
    med = np.median(win, axis=1)
    signed = np.zeros(n)  # the jump between the medians either side of each sample, signed
    signed[w: n - w + 1] = med[w:] - med[: n - 2 * w + 1]
    jump = np.abs(signed)
    d = np.diff(z)
    noise = 1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2) + 1e-15
    # the jump is a difference of two medians of w points: its noise is √2 · 1.2533 σ/√w for
    # independent points (a review: against 10 × the point noise σ, a 0.2 µm step was refused from
    # σ = 20 nm however dense the scan — 55 × the jump's noise at 10001 points). Filtered (correlated)
    # points make the medians noisier than that and their point-to-point σ smaller, so the jumps' own
    # robust spread counts too (the steps touch 2w of the n − 2w jumps each: the MAD hardly sees them)
    sj = jump_noise(noise, w)
    inner = signed[w: n - w + 1]
    sj = max(sj, 1.4826 * float(np.median(np.abs(inner - np.median(inner)))))
    # a step stands out from the profile's own waviness (5 × the typical jump) and from the points'
    # noise (10 ×), or where that leaves steps unfound from the noise of the jump (JUMP_FACTOR × it: the
    # largest of ~n/w independent jumps of a flat scan stays below 5 of their σ)
    typical = 5 * float(np.median(jump[w: n - w + 1]))
    cand = np.argsort(jump)[::-1]

    def bumps(out):
        """The candidates that are a flank of a bump or a groove of the artefact's form: within 10
        windows an opposite jump of at least half its size (the other flank) — a step is alone (a
        stylus's 1 nm noise makes a 20 nm bump 20 × the noise, and it read as a fifth step: a review).
        Asked only where more steps than heights were found, so an artefact's own groove whose edges
        are certified is never dropped."""
        gone = set()
        for a in out:
            near = signed[max(a - 10 * w, 0): a + 10 * w + 1]
            if np.max(-np.sign(signed[a]) * near) >= 0.5 * jump[a]:
                gone.add(a)
        return gone

    def pick(thr):
        out = []
        for i in cand:
            if jump[i] < thr or len(out) == count + 5:
                break
            if all(abs(i - j) > 2 * w for j in out):
                out.append(i)
        if len(out) > count:  # more than the heights: a bump's two flanks are no steps
            gone = bumps(out)
            kept = [i for i in out if i not in gone]
            out = kept if len(kept) >= count else out
        return out[:count + 1]

    picked = pick(max(10 * noise, typical))
    if len(picked) < count:
        picked = pick(max(JUMP_FACTOR * sj, typical))
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


def step_heights(x, z, edges, tilt: float = 0.0) -> np.ndarray:
    """ISO 5436-1-style height of each step (same unit as z), signed (up along x positive), read
    perpendicularly to the fitted line. ``tilt``: the slope already taken out of z (``level``), added
    to each fit's own slope for the perpendicular."""
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
        A = np.column_stack([np.ones(sel.sum()), x[sel] - e, right[sel].astype(float)])
        coef, *_ = np.linalg.lstsq(A, z[sel], rcond=None)
        out.append(coef[2] / np.hypot(1.0, tilt + coef[1]))
    return np.array(out)


@dataclass
class ZScaleCalibration:
    amplification: float
    offset: float             # mm (0 through the origin)
    linearity: float          # mm (nan with a single certified height)
    calibrated: np.ndarray    # mm
    measured: np.ndarray      # mm, mean over scans
    repeatability: np.ndarray  # mm, std over scans (nan with one scan)
    u_amplification: float = float("nan")   # standard uncertainty of the fit (nan when ν = 0)
    dof: int = 0              # ν, the residuals' degrees of freedom
    fit: str = "line"         # "line" or "through origin"

    @property
    def U95(self) -> float:
        """Expanded uncertainty, k = t₀.₉₇₅(ν) (nan when ν = 0)."""
        if self.dof < 1 or not np.isfinite(self.u_amplification):
            return float("nan")
        from scipy.stats import t

        return float(t.ppf(0.975, self.dof) * self.u_amplification)

    def describe(self) -> dict:
        def num(v):
            return float(v) if np.isfinite(v) else None

        return {"amplification": self.amplification, "amplification_u": num(self.u_amplification),
                "amplification_U95": num(self.U95), "dof": self.dof, "fit": self.fit,
                "offset_um": self.offset * 1e3, "linearity_um": num(self.linearity * 1e3),
                "calibrated_um": (self.calibrated * 1e3).tolist(),
                "measured_um": (self.measured * 1e3).tolist(),
                "repeatability_um": [num(v) for v in self.repeatability * 1e3]}


def calibrate(x, z, scan, heights_mm) -> ZScaleCalibration:
    """Amplification (slope of measured against certified step heights), see the module's notes."""
    heights = np.asarray(heights_mm, dtype=np.float64).ravel()
    if heights.size < 1:
        raise StepError("the amplification needs the certified height of at least one step")
    if not (np.all(np.isfinite(heights)) and np.all(heights > 0)):
        raise StepError("the certified step heights must be positive (a step down is given by its height)")
    x, z, scan = np.asarray(x, float), np.asarray(z, float), np.asarray(scan)
    per = []
    for s in np.unique(scan):
        m = scan == s
        zl, tilt = level(x[m], z[m])
        edges = find_edges(x[m], zl, heights.size)
        # a step down is a height too: the certified heights are magnitudes
        per.append(np.abs(step_heights(x[m], zl, edges, tilt)))
    per = np.array(per)                       # scans × edges
    meas = per.mean(axis=0)
    rep = per.std(axis=0, ddof=1) if per.shape[0] > 1 else np.full(heights.size, np.nan)
    H = np.tile(heights, per.shape[0])
    Y = per.ravel()
    if np.ptp(heights) <= 1e-6 * heights.max():
        # one certified height: no slope to fit a line with (its slope and offset trade), and a step
        # height has no offset — measured = m · certified
        fit = "through origin"
        m = float(H @ Y / (H @ H))
        c = 0.0
        r = Y - m * H
        dof = Y.size - 1
        sxx = float(H @ H)
        lin = float("nan")
    else:
        fit = "line"
        (m, c), *_ = np.linalg.lstsq(np.column_stack([H, np.ones_like(H)]), Y, rcond=None)
        m, c = float(m), float(c)
        r = Y - (m * H + c)
        dof = Y.size - 2
        sxx = float(np.sum((H - H.mean()) ** 2))
        lin = float(np.max(np.abs(meas - (m * heights + c))))
    u = float(np.sqrt(float(r @ r) / dof / sxx)) if dof > 0 else float("nan")
    return ZScaleCalibration(m, c, lin, heights, meas, rep, u, int(dof), fit)
