"""The RMS over the area, not over the points (core/metrics/area_weights.py).

A star scan or a spiral of even angular steps crowds its centre. Each case below compares the RMS with
the area integral of the same field over the measured region (the points' convex hull, less a bore),
by quadrature on a fine grid; the plain mean over the points is checked to be far off, so each test
fails if the weights are dropped."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from pointspro.core.metrics.area_weights import area_weights, density_centre, weighted_rms

R = 50.0


def star(diameters=12, step=0.5, centre=(0.0, 0.0), jitter=0.0, seed=0):
    s = np.arange(-R, R + 1e-9, step)
    th = np.pi * np.arange(diameters) / diameters
    x = np.concatenate([s * np.cos(t) for t in th])
    y = np.concatenate([s * np.sin(t) for t in th])
    rng = np.random.default_rng(seed)
    return x + centre[0] + rng.normal(0, jitter, x.size), y + centre[1] + rng.normal(0, jitter, x.size)


def spiral(turns=40, step_deg=2.0):
    t = np.arange(0, 2 * np.pi * turns, np.radians(step_deg))
    r = R * t / t[-1]
    return r * np.cos(t), r * np.sin(t)


def patch(seed=3):
    """Random points over the disk plus as many again crowded in one patch off the centre."""
    rng = np.random.default_rng(seed)
    r, t = R * np.sqrt(rng.uniform(0, 1, 6000)), rng.uniform(0, 2 * np.pi, 6000)
    px, py = 20 + rng.normal(0, 4, 6000), rng.normal(0, 4, 6000)
    k = np.hypot(px, py) < R
    return np.r_[r * np.cos(t), px[k]], np.r_[r * np.sin(t), py[k]]


FIELDS = {  # smooth form errors (mm), as a polishing run leaves them
    "spherical": lambda x, y: 6 * (np.hypot(x, y) / R) ** 4 - 6 * (np.hypot(x, y) / R) ** 2 + 1,
    "astigmatism": lambda x, y: (x * x - y * y) / R ** 2,
    "edge": lambda x, y: -np.clip((np.hypot(x, y) / R - 0.7) / 0.3, 0, None) ** 2,
    "zone": lambda x, y: np.exp(-((np.hypot(x, y) / R - 0.6) / 0.1) ** 2),
}


def area_truth(x, y, f, bore=0.0, centre=(0.0, 0.0)) -> float:
    """RMS of f about its mean over the points' convex hull (less a bore about ``centre``)."""
    eq = ConvexHull(np.column_stack([x, y])).equations
    g = np.linspace(-1.6 * R, 1.6 * R, 641)
    X, Y = (a.ravel() for a in np.meshgrid(g + centre[0], g + centre[1]))
    inside = np.all(eq[:, :2] @ np.vstack([X, Y]) + eq[:, 2:3] <= 1e-9, axis=0)
    inside &= np.hypot(X - centre[0], Y - centre[1]) >= bore
    v = f(X[inside] - centre[0], Y[inside] - centre[1])
    return float(np.std(v))


LAYOUTS = {
    "star 12 lines": (star(), 0.0, (0.0, 0.0)),
    "star 5 lines": (star(5), 0.0, (0.0, 0.0)),
    "star off the axis, jittered": (star(centre=(30.0, -10.0), jitter=0.05, seed=1), 0.0, (30.0, -10.0)),
    "spiral 40 turns": (spiral(), 0.0, (0.0, 0.0)),
    "spiral 10 turns": (spiral(10, 3.0), 0.0, (0.0, 0.0)),
    "dense patch": (patch(), 0.0, (0.0, 0.0)),
}


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("field", list(FIELDS))
def test_the_rms_is_the_area_rms_on_uneven_samplings(layout, field):
    (x, y), bore, c = LAYOUTS[layout]
    f = FIELDS[field]
    v = f(x - c[0], y - c[1])
    truth = area_truth(x, y, f, bore, c)
    w = area_weights(x, y)
    assert w is not None, "an uneven sampling gets weights"
    assert weighted_rms(v, w) == pytest.approx(truth, rel=0.05), (weighted_rms(v, None) / truth)


def test_the_plain_mean_over_those_points_is_far_off():
    """Why the weights: on these layouts the points' RMS misses the area's by 10–160 %."""
    worst = []
    for (x, y), bore, c in LAYOUTS.values():
        errs = [abs(weighted_rms(f(x - c[0], y - c[1]), None) / area_truth(x, y, f, bore, c) - 1)
                for f in FIELDS.values()]
        worst.append(max(errs))
    assert min(worst) > 0.10, worst


def test_the_weights_add_up_to_the_measured_area_and_leave_a_bore_out():
    x, y = star()
    assert area_weights(x, y).sum() == pytest.approx(np.pi * R * R, rel=0.03)
    keep = np.hypot(x, y) >= 15.0
    w = area_weights(x[keep], y[keep])
    assert w.sum() == pytest.approx(np.pi * (R * R - 15.0 ** 2), rel=0.04)
    v = FIELDS["astigmatism"](x[keep], y[keep])
    assert weighted_rms(v, w) == pytest.approx(area_truth(x[keep], y[keep], FIELDS["astigmatism"], 15.0), rel=0.05)


def test_even_samplings_keep_the_plain_mean_to_the_last_bit():
    g = np.arange(-R, R + 1e-9, 1.0)
    X, Y = np.meshgrid(g, g)
    k = np.hypot(X, Y) <= R
    x, y = X[k], Y[k]
    v = FIELDS["zone"](x, y) + np.random.default_rng(0).normal(0, 0.01, x.size)
    assert area_weights(x, y) is None
    assert weighted_rms(v, None) == float(np.sqrt(np.mean((v - v.mean()) ** 2)))
    rng = np.random.default_rng(1)
    r, t = R * np.sqrt(rng.uniform(0, 1, 40_000)), rng.uniform(0, 2 * np.pi, 40_000)
    assert area_weights(r * np.cos(t), r * np.sin(t)) is None  # random but even: no weights
    # a small raster off its lattice (probe compensation moves each point a little): too few points
    # for uniform_sampling's cell counts, and even all the same
    g = np.arange(-R, R + 1e-9, 2.0)
    X, Y = np.meshgrid(g, g)
    k = np.hypot(X, Y) <= R
    x, y = X[k] + rng.normal(0, 0.05, k.sum()), Y[k] + rng.normal(0, 0.05, k.sum())
    assert x.size < 2500 and area_weights(x, y) is None
    r, t = R * np.sqrt(rng.uniform(0, 1, 800)), rng.uniform(0, 2 * np.pi, 800)
    assert area_weights(r * np.cos(t), r * np.sin(t)) is None


def test_the_density_centre_is_where_the_lines_cross():
    x, y = star(centre=(12.3, -4.5), jitter=0.02)
    assert np.hypot(*(np.subtract(density_centre(x, y), (12.3, -4.5)))) < 0.1


def test_the_summary_and_the_tolerance_take_the_area_rms():
    """The whole path: a star scan's summary RMS and slope RMS, and the tolerance's RMSt, are the
    area's (the summary says so in ``rms_over``)."""
    from pointspro.core.cloud import PointCloud
    from pointspro.core.pipeline import summarize
    from pointspro.core.tolerance.quantities import iso_quantities

    x, y = star(diameters=18, step=0.25)
    f = FIELDS["astigmatism"]
    v = 1e-3 * f(x, y)  # 1 µm of astigmatism, mm
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(x), residual=v)
    s = summarize(cloud, cloud)
    truth_um = area_truth(x, y, f)  # f in µm: v = 1e-3·f mm
    assert s["rms_um"] == pytest.approx(truth_um, rel=0.03)
    assert s["rms_over"].startswith("area")
    # slope of (x² − y²)/R² µm: |∇| = 2r/R² µm/mm, RMS over the disk √2/R mm⁻¹ → µrad
    assert s["slope_rms_urad"] == pytest.approx(np.sqrt(2) / R * 1e3, rel=0.05)
    q = iso_quantities(x, y, v, (0.0, 0.0), ["rmst_um"], area_weights(x, y))
    assert q["rmst_um"] == pytest.approx(truth_um, rel=0.03)


def test_a_lattice_is_a_map_only_when_its_nodes_are_mostly_held():
    """A pixel map with dropouts keeps the plain mean (its valid pixels are the area); a fine patch in
    a coarse raster on one lattice is weighted (the plain mean read astigmatism 18 % low)."""
    g = np.arange(-R, R + 1e-9, 0.5)
    X, Y = (a.ravel() for a in np.meshgrid(g, g))
    r = np.hypot(X, Y)
    rng = np.random.default_rng(0)
    k = (r <= R) & (rng.uniform(size=r.size) > 0.3)
    assert area_weights(X[k], Y[k]) is None
    coarse = (np.round(X / 0.5) % 2 == 0) & (np.round(Y / 0.5) % 2 == 0)
    k = (r <= R) & ((r < 20) | coarse)
    x, y = X[k], Y[k]
    f = FIELDS["astigmatism"]
    w = area_weights(x, y)
    assert w is not None
    truth = 1 / np.sqrt(6)  # (x² − y²)/R² over the disk
    assert weighted_rms(f(x, y), None) < 0.85 * truth
    assert weighted_rms(f(x, y), w) == pytest.approx(truth, rel=0.02)


def test_a_fit_that_takes_the_radius_fits_the_areas_sphere():
    """misalignment/probe_radius with `radius` free: the best-fit sphere is the area's (ISO 14999-4).
    On a star scan the points' fit took part of the spherical aberration into power — the area RMS
    left read 12 % high and R 26 µm long on a 200 mm paraboloid; weighted by area: within 2 %, 4 µm."""
    from pointspro.core.geometry.posed_fit import PosedSurfaceFit, form_weights
    from pointspro.core.surfaces import EvenAsphere

    x, y = star()
    c = 1 / 200.0
    sa = FIELDS["spherical"]  # orthogonal to piston and power over the disk: the area's R is 200 mm
    z = c * (x * x + y * y) / 2 + 1e-3 * sa(x, y)
    q = np.column_stack([x, y, z])
    nominal = EvenAsphere(c=c, k=-1.0, aperture=100.0)
    dof = ["alpha", "beta", "dx", "dy", "dz", "radius"]
    assert form_weights(q, dof[:5]) is None  # a pose alone: the points' fit
    truth_um = area_truth(x, y, sa)  # sa in µm
    w = form_weights(q, dof)
    for weights, tol_rms, tol_r in ((w, 0.02, 0.01), (None, None, None)):
        fit = PosedSurfaceFit(nominal, q, dof, weights=weights).fit()
        part = fit.part
        rms_um = weighted_rms(fit.residuals, area_weights(part[:, 0], part[:, 1])) * 1e3
        if tol_rms is None:  # the points' fit, for contrast: the test fails without the weights
            assert rms_um > 1.05 * truth_um and abs(fit.values["radius"] - 200.0) > 0.02
        else:
            assert rms_um == pytest.approx(truth_um, rel=tol_rms)
            assert fit.values["radius"] == pytest.approx(200.0, abs=tol_r)


@pytest.mark.parametrize("turns, n", [(8, 2000), (10, 2000), (18, 10000), (40, 20000)])
def test_a_coarse_spiral_with_a_feature_off_its_centre(turns, n):
    """A review: on even-angle spirals of few turns (points at even angular steps from the centre to
    the rim, in one sweep) a bump 18 mm off the centre read 31 % (10 turns) and 15 % (18) low: the
    centre was found 0.2–1.7 mm off a coarse spiral's, and dN/dr smoothed over 1 % of the radius is
    lumpy on that scale. The centre is now where the radius follows the scan order exactly
    (_spiral_centre); two other remedies were tried and not kept (the module's docstring)."""
    th = np.linspace(0, 2 * np.pi * turns, n)
    r = R * th / th[-1]
    x, y = r * np.cos(th), r * np.sin(th)

    def bump(x, y):
        return np.exp(-((x - 15) ** 2 + (y + 10) ** 2) / (2 * 4.0 ** 2))
    w = area_weights(x, y)
    assert weighted_rms(bump(x, y), w) == pytest.approx(area_truth(x, y, bump), rel=0.03)


@pytest.mark.parametrize("n", [80, 200, 500])
def test_points_spread_at_random_are_left_to_the_plain_mean(n):
    """80–500 points at random on a disc (a CMM's scattered sampling) were weighted in 3–5 of 5 seeds —
    the density of so few is noisy and their hull falls short of the rim — and the RMS read 5–14 % low
    (a review). Over 40 seeds, at most 2 are weighted (the KS test's 0.1 % and the quarters' rule)."""
    weighted = 0
    for seed in range(40):
        rng = np.random.default_rng(500 + seed)
        r, t = 10.0 * np.sqrt(rng.random(n)), rng.random(n) * 2 * np.pi
        weighted += area_weights(r * np.cos(t), r * np.sin(t)) is not None
    assert weighted <= 2


@pytest.mark.parametrize("case", ["rim scan", "dense centre"])
def test_scattered_points_with_a_rim_scan_or_a_dense_centre_are_still_weighted(case):
    """The evenness test looks inside the largest disc the hull holds: 300 scattered points with a
    180-point rim scan (just beyond that disc) passed it and the RMS of an edge roll-off read 62–66 %
    high on the plain mean; a rectangle with a dense centre and sparse ends −13…−18 % (a review of
    the test). The count beyond the disc is checked against the hull's area there."""
    for seed in range(3):
        rng = np.random.default_rng(10 + seed)
        if case == "rim scan":
            r, t = 25.0 * np.sqrt(rng.random(300)), rng.random(300) * 2 * np.pi
            tr = np.linspace(0, 2 * np.pi, 180, endpoint=False)
            x, y = np.r_[r * np.cos(t), 25.0 * np.cos(tr)], np.r_[r * np.sin(t), 25.0 * np.sin(tr)]
        else:
            xe, ye = rng.uniform(-40, 40, 300), rng.uniform(-10, 10, 300)
            keep = np.abs(xe) > 10
            x = np.r_[rng.uniform(-10, 10, 400), xe[keep]]
            y = np.r_[rng.uniform(-10, 10, 400), ye[keep]]
        assert area_weights(x, y) is not None, seed


@pytest.mark.parametrize("region", ["annulus", "small rectangle"])
def test_random_points_on_an_annulus_or_a_narrow_part_keep_the_plain_mean(region):
    """300 random points on a 10–25 mm annulus were weighted in 17 of 20 draws (the bore failed the
    disc's test) and their RMS read 20 % low; 100 on an 80 × 20 mm part (~20 in the largest disc the
    hull holds) in 14 of 20, 24 % low (a review). The ring r0 … ρ is tested; too few in it, the whole
    hull's area."""
    weighted = 0
    for seed in range(20):
        rng = np.random.default_rng(900 + seed)
        if region == "annulus":
            r, t = np.sqrt(rng.uniform(100.0, 625.0, 300)), rng.random(300) * 2 * np.pi
            x, y = r * np.cos(t), r * np.sin(t)
        else:
            x, y = rng.uniform(-40, 40, 100), rng.uniform(-10, 10, 100)
        weighted += area_weights(x, y) is not None
    assert weighted <= 1
