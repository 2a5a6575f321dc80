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


# --- the harder classes of issue 16 part 3 -------------------------------------------------------------
#: outlier classes of `mixture`, with the counts of the issue's case (60,000 points, 200 mm)
CLASSES = {"small": 40, "digs": 10, "rim": 20, "big": 30, "steep": 20}
#: the issue's mixture: small spikes, digs, rim outliers and big spikes (no steep region)
ISSUE_MIX = ("small", "digs", "rim", "big")


def _disc(n, radius, rng, scattered):
    if scattered:
        m = int(n / (np.pi / 4) * 1.02) + 16
        x, y = rng.uniform(-radius, radius, m), rng.uniform(-radius, radius, m)
        inside = np.hypot(x, y) <= radius
        return x[inside][:n], y[inside][:n]
    x, y = raster(2 * radius, 2 * radius * np.sqrt(np.pi / 4 / n))
    return x, y


def _steep_feature(x, y, radius, rng):
    """A steep, smooth feature that is not an outlier: a turned-down edge (roll-off 1–3 µm over the
    last 4 % of the radius) and a ring-shaped polishing ridge 0.6–1.5 µm high, σ 1.5–3 % of the
    radius (slopes up to ~0.5 µm/mm on a 200 mm part). Returns the height (mm) and the mask of
    points where the slope exceeds 0.1 µm/mm."""
    r = np.hypot(x, y)
    w_edge = 0.04 * radius
    edge = -rng.uniform(1.0, 3.0) * 1e-3 * np.clip((r - (radius - w_edge)) / w_edge, 0, None) ** 2
    r0, s = rng.uniform(0.3, 0.7) * radius, rng.uniform(0.015, 0.03) * radius
    ridge = rng.uniform(0.6, 1.5) * 1e-3 * np.exp(-0.5 * ((r - r0) / s) ** 2)
    h = edge + ridge
    slope = np.abs(2e-3 * np.clip((r - (radius - w_edge)) / w_edge, 0, None) / w_edge * 3) \
        + np.abs(ridge * (r - r0) / s**2)
    return h, slope > 1e-4


def mixture(n=60_000, seed=0, aperture=200.0, noise_um=0.02, classes=ISSUE_MIX, scattered=True,
            ripple_um=0.03, residual_um=0.3, counts=None, steep_surface=None):
    """The case of issue 16 part 3: `n` points over a disc of `aperture` mm, a `residual_um` RMS
    polishing residual plus a `ripple_um` ripple (wavelength 5–15 mm, random direction) and
    `noise_um` noise, with outliers of the named classes (counts scale with n / 60,000):

    - small: isolated spikes of ±6–10 σ (σ = noise_um);
    - digs: clusters of 3–30 neighbouring points 0.2–2 µm deep (half of them scratches: the points
      within 0.4 mm of a 3–20 mm segment, at most 30);
    - rim: points within 2 % of the radius of the edge, −0.5…−5 µm (probe slipping off the edge)
      or +0.5…+3 µm;
    - big: isolated spikes of ±1–20 µm;
    - steep: spikes of ±0.15–1 µm on a steep feature (a turned-down edge and a polishing ridge,
      `_steep_feature`); the feature is added whenever `steep_surface` is true or "steep" is asked.

    Returns (cloud, truth: {class: set of positions}, steep mask)."""
    rng = np.random.default_rng(seed)
    radius = aperture / 2
    x, y = _disc(n, radius, rng, scattered)
    m = len(x)
    scale = m / 60_000
    counts = {c: max(1, int(round(CLASSES[c] * scale))) if c != "digs" else max(1, int(round(10 * scale)))
              for c in classes} | (counts or {})
    lam, th = rng.uniform(5.0, 15.0), rng.uniform(0, np.pi)
    d = (polishing_residual(x, y, radius, residual_um, seed)
         + ripple_um * 1e-3 * np.sin(2 * np.pi * (x * np.cos(th) + y * np.sin(th)) / lam + rng.uniform(0, 6))
         + rng.normal(0, noise_um * 1e-3, m))
    steep = np.zeros(m, dtype=bool)
    if steep_surface or (steep_surface is None and "steep" in classes):
        h, steep = _steep_feature(x, y, radius, rng)
        d += h
    taken = np.zeros(m, dtype=bool)
    truth: dict[str, set] = {}
    from scipy.spatial import cKDTree

    tree = cKDTree(np.column_stack([x, y]))
    r = np.hypot(x, y)

    def isolated(pool, k):
        """k positions of `pool`, none within 3 mm of another outlier."""
        out = []
        for p in rng.permutation(pool):
            if len(out) == k:
                break
            if not taken[p] and not taken[tree.query_ball_point([x[p], y[p]], 3.0)].any():
                out.append(p)
                taken[p] = True
        return np.asarray(out, dtype=np.int64)

    interior = np.flatnonzero(r < radius - 5.0)
    for c in classes:
        k = counts[c]
        if c == "small":
            p = isolated(interior, k)
            d[p] += rng.choice([-1, 1], len(p)) * rng.uniform(6, 10, len(p)) * noise_um * 1e-3
        elif c == "big":
            p = isolated(interior, k)
            d[p] += rng.choice([-1, 1], len(p)) * rng.uniform(1, 20, len(p)) * 1e-3
        elif c == "rim":
            p = isolated(np.flatnonzero(r > 0.98 * radius), k)
            low = rng.random(len(p)) < 0.7
            d[p] += np.where(low, -rng.uniform(0.5, 5.0, len(p)), rng.uniform(0.5, 3.0, len(p))) * 1e-3
        elif c == "steep":
            p = isolated(np.flatnonzero(steep & (r < radius - 1.0)), k)
            d[p] += rng.choice([-1, 1], len(p)) * rng.uniform(0.15, 1.0, len(p)) * 1e-3
        elif c == "digs":
            groups = []
            for _ in range(k):
                for _try in range(50):
                    c0 = rng.choice(interior)
                    size = int(rng.integers(3, 31))
                    if rng.random() < 0.5:  # a dig: the nearest `size` points
                        g = tree.query([x[c0], y[c0]], k=size)[1]
                    else:  # a scratch: the points near a segment
                        length, ang = rng.uniform(3, 20), rng.uniform(0, np.pi)
                        t = np.linspace(0, length, 40)
                        near = tree.query_ball_point(np.column_stack([x[c0] + t * np.cos(ang),
                                                                      y[c0] + t * np.sin(ang)]), 0.4)
                        g = np.unique(np.concatenate([np.asarray(v, dtype=np.int64) for v in near]))[:30]
                    g = np.asarray(g, dtype=np.int64)
                    ring = np.concatenate([np.asarray(v, dtype=np.int64) for v in
                                           tree.query_ball_point(np.column_stack([x[g], y[g]]), 3.0)])
                    if len(g) >= 3 and not taken[ring].any() and np.all(r[g] < radius - 3):
                        break
                taken[g] = True
                d[g] -= rng.uniform(0.2, 2.0) * 1e-3 * rng.uniform(0.8, 1.0, len(g))
                groups.append(g)
            p = np.concatenate(groups) if groups else np.zeros(0, dtype=np.int64)
        else:
            raise ValueError(c)
        truth[c] = set(p.tolist())
    return PointCloud.from_xyz(x, y, np.zeros_like(x), residual=d), truth, steep
