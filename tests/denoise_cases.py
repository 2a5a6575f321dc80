"""Residual maps of paper 002 §5 (Q1, Q2) rebuilt for the denoising tests and benchmark."""
from __future__ import annotations

import numpy as np

from pointspro.core import PointCloud

from .paper002 import raster, star


def polishing_residual(x, y, radius, rms_um=0.4, seed=0):
    """A smooth polishing residual: low-order terms plus mid-spatial ripples, scaled to rms_um (mm)."""
    rng = np.random.default_rng(seed)
    u, v = x / radius, y / radius
    r2 = u * u + v * v
    w = (0.8 * (2 * r2 - 1) + 0.6 * (u * u - v * v) + 0.5 * u * v + 0.4 * (3 * r2 - 2) * u
         + 0.3 * np.cos(2 * np.pi * np.sqrt(r2) * 3.2 + rng.uniform(0, 6))
         + 0.15 * np.sin(2 * np.pi * (u * 4.1 + v * 2.3) + rng.uniform(0, 6)))
    w = w - w.mean()
    return w / np.sqrt(np.mean(w * w)) * rms_um * 1e-3


def q1(seed=1, spikes=(12.0, 15.0, 16.0), noise_um=0.02):
    """Q1: 620 mm aperture, raster at 15 mm, ~0.4 µm RMS residual, 20 nm noise, three spikes (µm)."""
    rng = np.random.default_rng(seed)
    x, y = raster(620, 15.0)
    d = polishing_residual(x, y, 310, 0.4, seed) + rng.normal(0, noise_um * 1e-3, len(x))
    where = rng.choice(len(x), len(spikes), replace=False)
    d[where] += np.asarray(spikes) * 1e-3
    return PointCloud.from_xyz(x, y, np.zeros_like(x), residual=d), set(where.tolist())


def q2(seed=2, n_low=36, spikes=(8.0, 11.0, 14.0, -9.0), noise_um=0.02):
    """Q2: 1300 mm star (10°, 5 mm); the points nearest the centre sag by 2–6 µm; a few spikes."""
    rng = np.random.default_rng(seed)
    x, y = star(1300)
    d = polishing_residual(x, y, 650, 0.4, seed) + rng.normal(0, noise_um * 1e-3, len(x))
    r = np.hypot(x, y)
    low = np.argsort(r, kind="stable")[:n_low]
    d[low] -= rng.uniform(2.0, 6.0, n_low) * 1e-3
    others = np.setdiff1d(np.arange(len(x)), low)
    sp = rng.choice(others[r[others] > 100], len(spikes), replace=False)
    d[sp] += np.asarray(spikes) * 1e-3
    return PointCloud.from_xyz(x, y, np.zeros_like(x), residual=d), set(low.tolist()) | set(sp.tolist())


def injected(n_points, seed=3, fraction=0.002, scattered=False, noise_um=0.02):
    """Benchmark data: ~n_points over a 1000 mm aperture, 0.3 µm RMS residual, outliers of ±0.5–20 µm."""
    rng = np.random.default_rng(seed)
    if scattered:
        m = int(n_points / (np.pi / 4))
        x, y = rng.uniform(-500, 500, m), rng.uniform(-500, 500, m)
        keep = np.hypot(x, y) <= 500
        x, y = x[keep], y[keep]
    else:
        x, y = raster(1000, 1000 * np.sqrt(np.pi / 4 / n_points))
    d = polishing_residual(x, y, 500, 0.3, seed) + rng.normal(0, noise_um * 1e-3, len(x))
    k = int(round(fraction * len(x)))
    where = rng.choice(len(x), k, replace=False)
    d[where] += rng.choice([-1, 1], k) * rng.uniform(0.5, 20.0, k) * 1e-3
    return PointCloud.from_xyz(x, y, np.zeros_like(x), residual=d), set(where.tolist())
