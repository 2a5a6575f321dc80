"""knn_denoise (robust): guards from a review of a change that was taken back (issue 16 part 3, eighth
session). A per-point noise estimate below 0.5 nm was taken for noise-free data and real smooth pits
and bumps were kept as form on 0.1–0.45 nm noise and on 1 nm-quantized heights (67 → 29 of 74 defects);
a σ clip in the coarse pass lost wide, deep Gaussian pits and bumps whole (a 709 nm pit of 68 points at
2 nm noise: 68 → 0). These hold on the method as it is; a new attempt must keep them."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pointspro.plugins.knn_denoise.robust import robust_outliers

FLOOR = 1e-5  # mm: the step's default absolute floor (10 nm)


def sample(layout, R, n, rng):
    if layout == "scattered":
        m = int(n * 4 / math.pi)
        x, y = rng.uniform(-R, R, m), rng.uniform(-R, R, m)
    else:  # raster
        h = math.sqrt(math.pi * R * R / n)
        X, Y = np.meshgrid(np.arange(-R, R + h / 2, h), np.arange(-R, R + h / 2, h))
        x, y = X.ravel(), Y.ravel()
    keep = np.hypot(x, y) <= R
    return x[keep], y[keep]


def smooth_defects(layout, seed, noise, curved, quantum=None, n=20000, R=10.0, depth=(0.1e-3, 1e-3),
                   width=(1.2, 2.5), count=8):
    """A 20 mm part (flat, or a 0.3 µm order-4 residual), Gaussian pits and bumps `depth` deep with σ of
    `width` point spacings, 8 windows apart; Gaussian noise, heights rounded to `quantum` if given.
    Returns x, y, d, window (5 spacings), and per defect its deep points (beyond half its depth)."""
    rng = np.random.default_rng(seed)
    x, y = sample(layout, R, n, rng)
    sp = math.sqrt(math.pi * R * R / len(x))
    window = 5 * sp
    r, t = np.hypot(x, y) / R, np.arctan2(y, x)
    d = 1e-4 * x / R + (0.3e-3 * (r**4 * np.cos(2 * t) + 0.5 * (6 * r**4 - 6 * r**2 + 1)) if curved else 0.0)
    centres = []
    for q in rng.permutation(np.flatnonzero(np.hypot(x, y) < R - 2)):
        if len(centres) == count:
            break
        if all(math.hypot(x[q] - a, y[q] - b) > 8 * window for a, b in centres):
            centres.append((x[q], y[q]))
    deep = []
    for i, (cx, cy) in enumerate(centres):
        s = sp * rng.uniform(*width)
        dep = 10 ** rng.uniform(*np.log10(depth)) * (-1 if i % 2 == 0 else 1)
        a = dep * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
        d = d + a
        deep.append(np.flatnonzero(np.abs(a) > 0.5 * abs(dep)))
    d = d + rng.normal(0, noise, len(x))
    if quantum:
        d = np.round(d / quantum) * quantum
    return x, y, d, window, deep


@pytest.mark.parametrize("noise,quantum", [(0.1e-6, None), (0.3e-6, None), (0.45e-6, None), (0.0, 1e-6),
                                           (0.2e-6, 1e-6)])
@pytest.mark.parametrize("layout", ["scattered", "raster"])
def test_smooth_defects_on_quiet_or_quantized_data_are_not_kept_as_form(noise, quantum, layout):
    """0.1–1 µm Gaussian pits and bumps on interferometer-quiet data: each is found, most of its deep
    points removed, and nothing is kept as form (that rule is for noise-free data only)."""
    for seed, curved in ((1, False), (2, True)):
        x, y, d, window, deep = smooth_defects(layout, seed, noise, curved, quantum)
        r = robust_outliers(x, y, d, window, 1.0, 5.0, FLOOR)
        assert r.kept_as_form == 0
        found = [r.flagged[g].mean() for g in deep]
        assert min(found) >= 0.5, (seed, np.round(found, 2))


@pytest.mark.parametrize("noise", [2e-6, 5e-6, 20e-6])
def test_deep_pits_and_bumps_are_found_whole(noise):
    """Pits and bumps 150–400 σ deep, σ 1.5–2.5 point spacings (their half-depth diameter up to ~6 of
    the 10 spacings of the 2a window) on a flat: every one found, nearly all of its deep points, and
    nothing flagged far from them. (Wider ones — σ 3–4 spacings, as wide as the window — are form at
    this window's scale and are kept, before and after: 23 of 36 such, all or nothing.)"""
    for seed in (10, 11, 12):
        x, y, d, window, deep = smooth_defects("scattered", seed, noise, False, depth=(150 * noise, 400 * noise),
                                               width=(1.5, 2.5), count=6, n=15000)
        r = robust_outliers(x, y, d, window, 1.0, 5.0, FLOOR)
        found = [r.flagged[g].mean() for g in deep]
        assert min(found) >= 0.8, (seed, np.round(found, 2))
        near = cKDTree(np.column_stack([x, y])[np.concatenate(deep)]).query(np.column_stack([x, y]))[0]
        assert not np.any(r.flagged & (near > 2 * window))


@pytest.mark.parametrize("noise", [2e-6, 50e-6])
@pytest.mark.parametrize("height,width,x0", [(3e-3, 0.4, 0.0), (3.64e-3, 0.41, 2.02)])
def test_steep_steps_without_outliers_lose_nothing_at_a_small_window(noise, height, width, x0):
    """A tanh step of 3–3.6 µm over 0.4 mm on a 0.5 mm raster, a = 2.5 spacings, Gaussian noise: no
    point is an outlier and none is removed (a second attempt at small-window digs, also taken back,
    removed whole raster columns along the step's shoulder: 0 → 33–66)."""
    g = np.arange(-8, 8.001, 0.5)
    x, y = (v.ravel() for v in np.meshgrid(g, g))
    for seed in range(3):
        d = height * np.tanh((x - x0) / (width / 2)) + np.random.default_rng(seed).normal(0, noise, x.size)
        assert robust_outliers(x, y, d, 1.25, 1.0, 5.0, FLOOR).flagged.sum() == 0
