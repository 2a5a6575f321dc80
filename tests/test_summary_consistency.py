"""The summary's figures are computed in three places — core.pipeline.summarize (report.json's
summary), core.uncertainty.montecarlo.summary_figures (the uncertainty's samples) and
core.tolerance.quantities.compute (the verdict) — each through core.metrics (area_weights,
weighted_rms, form, pvr). They must agree: an uncertainty or a verdict about another RMS than the one
reported would be silently wrong. Checked on a star scan (weights over the area), a raster (plain
mean) and a height map with no residual on a flat (piston and tilt removed). Fixed seeds."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.pipeline import summarize
from pointspro.core.surfaces import EvenAsphere
from pointspro.core.tolerance.quantities import compute
from pointspro.core.uncertainty.montecarlo import summary_figures

R = 50.0


def star(lines=12, step=0.5):
    s = np.arange(-R, R + 1e-9, step)
    th = np.pi * np.arange(lines) / lines
    return np.concatenate([s * np.cos(t) for t in th]), np.concatenate([s * np.sin(t) for t in th])


def raster(pitch=1.5):
    g = np.arange(-R, R + 1e-9, pitch)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = np.hypot(x, y) <= R
    return x[keep], y[keep]


def field(x, y, seed):
    rng = np.random.default_rng(seed)
    rho2 = (x * x + y * y) / R ** 2
    return (1e-3 * (0.8 * (x * x - y * y) / R ** 2 + 0.5 * (6 * rho2 * rho2 - 6 * rho2 + 1))
            + 2e-4 * np.sin(x / 7.0 + seed) + 2e-5 * rng.standard_normal(x.size))


@pytest.mark.parametrize("sampling,seed", [("star", 0), ("star", 1), ("raster", 2)])
def test_summary_uncertainty_and_tolerance_agree_on_a_residual(sampling, seed):
    x, y = star() if sampling == "star" else raster()
    surface = EvenAsphere(1 / 500.0, 0.0, {}, 2 * R)
    cloud = PointCloud.from_xyz(x, y, surface.sag(x, y), residual=field(x, y, seed))
    s = summarize(cloud, cloud, surface)
    assert s["rms_over"].startswith("area" if sampling == "star" else "points")
    mc = summary_figures(cloud, surface)
    tol = compute(cloud, surface, ["rms_um", "pv_um", "pvr_um", "slope_rms_urad"])
    for key in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad"):
        assert mc[key] == pytest.approx(s[key], rel=1e-9), key
        assert tol[key] == pytest.approx(s[key], rel=1e-9), key


def test_summary_uncertainty_and_tolerance_agree_on_heights_of_a_flat():
    """No residual, no nominal (a flat): all three judge the heights less their least-squares plane."""
    x, y = star(lines=10, step=1.0)
    z = field(x, y, 5) + 3e-3 * x / R - 1e-3 * y / R + 0.2
    cloud = PointCloud.from_xyz(x, y, z)
    flat = None  # no nominal: a plane (core.metrics.pupil.is_flat)
    s = summarize(cloud, cloud, flat)
    assert s["figures_of"].startswith("heights")
    mc = summary_figures(cloud, flat)
    tol = compute(cloud, flat, ["rms_um", "pv_um"])
    for key in ("rms_um", "pv_um"):
        assert mc[key] == pytest.approx(s[key], rel=1e-9), key
        assert tol[key] == pytest.approx(s[key], rel=1e-9), key
