"""A raster moved by the pose fit is still a lattice for `correction` (an independent review): a
rotation of ~10⁻⁶ rad spreads each column of x over picometres, the median step of the distinct
values read 10⁻¹¹ mm, and the raster went through the B-spline at twice its pitch — a 1 mm ripple on
a 0.5 mm raster then stood as "unresolved" and the predicted error after the correction read 1.6 nm
for a true 7.6 nm."""
from __future__ import annotations

import numpy as np

from pointspro.core.correction.compute import regular_grid


def _raster(n=41, pitch=0.5):
    g = (np.arange(n) - n // 2) * pitch
    X, Y = np.meshgrid(g, g)
    keep = X**2 + Y**2 <= (n // 2 * pitch) ** 2
    return X[keep], Y[keep]


def test_a_raster_rotated_by_a_pose_fit_is_taken_node_for_node():
    x, y = _raster()
    z = (x**2 + y**2) / 200.0  # a sphere's sag: the tilt couples it into x and y
    a, b = 3e-4, -2e-4  # rad, about x and y: a part tilted by 0.02° (z·β up to 0.3 µm off the lattice)
    xr = x + b * z + 1e-9 * y
    yr = y - a * z - 1e-9 * x
    v = np.sin(x) * 1e-5
    got = regular_grid(xr, yr, v)
    assert got is not None
    xs, ys, Z, h = got
    assert h == np.float64(h) and abs(h - 0.5) < 1e-9
    assert np.count_nonzero(np.isfinite(Z)) == x.size
    assert np.allclose(Z[np.isfinite(Z)], v[np.lexsort((x, y))], atol=0)  # each value at its node


def test_scattered_points_are_not_a_lattice():
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-10, 10, (2, 2000))
    assert regular_grid(x, y, np.zeros_like(x)) is None
    xs, ys = _raster()
    jittered = regular_grid(xs + rng.normal(0, 0.05, xs.size), ys, np.zeros_like(xs))
    assert jittered is None  # a tenth of the pitch off: no lattice
