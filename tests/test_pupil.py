"""Issue 15: maps have a centre. Pupil-based quantities (Zernike, PVr, the map's profiles) use the
surface's axis, or for a map with no nominal (or a flat) the bounding-box centre of the measured
region — never a file's corner origin; a removal that makes the residual larger is an error; a flat
gets the DOF a plane determines; the automatic map spacing is always feasible."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pointspro.core.cloud import PointCloud
from pointspro.core.errors import StepError
from pointspro.core.metrics.pupil import pupil_of
from pointspro.core.pipeline import check_sanity, remove_piston_tilt, run_pipeline
from pointspro.core.recipe import parse_recipe
from pointspro.core.step import Context
from pointspro.core.surfaces.even_asphere import EvenAsphere
from pointspro.plugins.bspline_map import BSplineMapStep
from pointspro.plugins.misalignment import MisalignmentStep
from pointspro.plugins.zernike import ZernikeStep

REAL = Path(__file__).parent / "data" / "realdata"


def _run(step, cloud, surface=None, **params):
    return step().run(cloud, step.Params.model_validate(params), Context(surface=surface))


def _plane_power_removed(x, y, z, c):
    """numpy's least squares on [1, x, y, r²] about centre c; returns z − (b0 + b1 x + b2 y)."""
    dx, dy = x - c[0], y - c[1]
    A = np.column_stack([np.ones_like(dx), dx, dy, dx * dx + dy * dy])
    b, *_ = np.linalg.lstsq(A, z, rcond=None)
    return z - A[:, :3] @ b[:3]


def _check_piston_tilt_equals_numpy(cloud):
    res = _run(ZernikeStep, cloud, terms=4, remove=["piston", "tilt"])
    rep = res.report
    x, y, z = cloud.x, cloud.y, cloud.z
    c = (0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max()))
    assert rep["centre_mm"] == pytest.approx(list(c), rel=1e-12, abs=1e-12)
    assert rep["centre_from"].startswith("bounding-box centre")
    assert rep["norm_radius_mm"] == pytest.approx(np.sqrt(np.max((x - c[0]) ** 2 + (y - c[1]) ** 2)))
    # an evenly sampled area that does not cover the Zernike disk (a rectangle): piston and tilt are
    # its best-fit plane, fitted alone (core.metrics.sampling.plain_best_fits); over a covered disk
    # the joint fit's, which numpy's plane-and-power fit gives
    alone = rep["removal"].startswith("the removed terms fitted alone")
    want = remove_piston_tilt(x, y, z) if alone else _plane_power_removed(x, y, z, c)
    got = res.cloud["residual"]
    # power keeps its own constant (Z4 = √3(2ρ² − 1)): equal up to a piston
    d = (got - got.mean()) - (want - want.mean())
    assert np.max(np.abs(d)) <= 1e-9 * np.ptp(z)
    # about the centre, tilt and power are nearly orthogonal: the tilt of the joint fit is the plane's
    # (about a corner they trade, and "removing tilt" left a slope: 3.5× the RMS on metropro-1)
    plane = np.std(remove_piston_tilt(x, y, z))
    assert plane * (1 - 1e-12) <= np.std(got) <= 1.01 * plane
    return rep


@pytest.mark.parametrize("name", ["metropro-1.dat", "sur-2.sur"])
def test_real_map_piston_tilt_removal_equals_numpy_about_the_measured_centre(name):
    from pointspro.core.io import read_cloud

    cloud = read_cloud(REAL / name)
    rep = _check_piston_tilt_equals_numpy(cloud)
    assert rep["rms_after_um"] < rep["rms_before_um"]


def test_metropro_figures_as_numpy_computes_them():
    """The issue's figures: plane-removed RMS 0.01333 µm; 36 terms minus piston/tilt/power: the best-fit
    sphere's 0.006784 µm (it was 155.6 µm about the corner origin)."""
    from pointspro.core.io import read_cloud

    cloud = read_cloud(REAL / "metropro-1.dat")
    plane = remove_piston_tilt(cloud.x, cloud.y, cloud.z)
    assert np.std(plane) * 1e3 == pytest.approx(0.01333, abs=5e-5)
    res = _run(ZernikeStep, cloud, terms=36, remove=["piston", "tilt", "power"])
    # the rectangle's best-fit sphere (piston, tilt, power fitted alone; 0.0082 µm with the joint
    # fit's coefficients before 2026-11-27): numpy's least squares on [1, x, y, r²]
    x, y, z = cloud.x, cloud.y, cloud.z
    A = np.column_stack([np.ones_like(x), x, y, x * x + y * y])
    sphere = z - A @ np.linalg.lstsq(A, z, rcond=None)[0]
    assert res.report["rms_after_um"] == pytest.approx(np.std(sphere) * 1e3, rel=1e-9)
    assert res.report["rms_after_um"] == pytest.approx(0.006784, abs=2e-6)
    # a best-fit sphere does not depend on the pupil's centre: about the corner (once 155.6 µm) too
    corner = _run(ZernikeStep, cloud, terms=36, remove=["piston", "tilt", "power"], centre=(0.0, 0.0))
    assert corner.report["rms_after_um"] == pytest.approx(res.report["rms_after_um"], rel=1e-9)
    # the joint fit's terms about the corner still trade: removing a higher one is refused
    with pytest.raises(StepError, match=r"raises the RMS .* fit fewer terms, or check the pupil"):
        _run(ZernikeStep, cloud, terms=36, remove=["piston", "tilt", "power", "astigmatism", "coma"],
             centre=(0.0, 0.0))


@pytest.mark.parametrize("seed", range(6))
def test_corner_origin_maps_of_any_shape_and_offset(seed):
    """Synthetic maps whose origin is a corner (rectangles, disks, with dropouts), several sizes:
    piston/tilt removal equals numpy's plane-and-power fit about the bounding-box centre."""
    rng = np.random.default_rng(seed)
    nx, ny = rng.integers(40, 160, size=2)
    px = rng.uniform(0.005, 0.5)
    X, Y = np.meshgrid(np.arange(nx) * px, np.arange(ny) * px)
    x, y = X.ravel(), Y.ravel()
    keep = rng.uniform(size=x.size) > 0.1  # dropouts
    if seed % 2:  # a disk inside the rectangle, as an interferometer's aperture
        cx, cy = x.max() / 2, y.max() / 2
        keep &= np.hypot(x - cx, y - cy) <= 0.5 * min(x.max(), y.max())
    x, y = x[keep], y[keep]
    s = max(x.max(), y.max())
    z = (rng.normal() * 1e-4 + rng.normal() * 1e-4 * x / s + rng.normal() * 1e-4 * y / s
         + 5e-5 * ((x / s) ** 2 - (y / s) ** 2) + rng.normal(0, 5e-6, x.size))
    _check_piston_tilt_equals_numpy(PointCloud.from_xyz(x, y, z))


def test_surface_axis_is_the_centre_with_a_nominal():
    surf = EvenAsphere(1 / 500.0, -1.0, aperture=100.0)
    x = np.random.default_rng(1).uniform(10, 40, 500)
    y = np.random.default_rng(2).uniform(-5, 30, 500)
    p = pupil_of(x, y, surf)
    assert p.center == (0.0, 0.0) and p.radius == 50.0 and "axis" in p.how
    flat = EvenAsphere(0.0)
    p = pupil_of(x, y, flat)
    assert p.center == pytest.approx((0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())))
    assert "flat" in p.how
    p = pupil_of(x, y, surf, center=(1.0, 2.0), radius=7.0)
    assert (p.center, p.radius) == ((1.0, 2.0), 7.0)


def test_centre_given_twice_or_half_is_refused():
    with pytest.raises(ValueError, match="give both center_x and center_y"):
        ZernikeStep.Params.model_validate({"center_x": 1.0})
    with pytest.raises(ValueError, match="give the centre once"):
        ZernikeStep.Params.model_validate({"center_x": 1.0, "center_y": 0.0, "centre": [0, 0]})
    p = ZernikeStep.Params.model_validate({"center_x": 1.0, "center_y": 2.0})
    assert p.given_centre == (1.0, 2.0)


def test_a_centre_too_far_for_a_finite_pupil_is_refused_by_name():
    """centre: [1e300, 0] made the normalisation radius inf: the step ran to exit 0 with overflow
    warnings and a report without a radius; now one message naming the centre."""
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-10, 10, (2, 400))
    cloud = PointCloud(np.column_stack([x, y, 1e-3 * x * y]))
    step = ZernikeStep()
    with pytest.raises(StepError, match=r"centre \(1e\+300, 0\) mm lies so far"):
        step.run(cloud, step.Params.model_validate({"terms": 4, "centre": [1e300, 0]}), Context())
    out = step.run(cloud, step.Params.model_validate({"terms": 4, "centre": [1e3, 0]}), Context())
    assert np.isfinite(out.report["norm_radius_mm"])  # far but finite: fitted (and warned if ill-posed)


@pytest.mark.parametrize("seed", range(4))
def test_misalignment_on_a_flat_fits_what_a_plane_determines(seed):
    rng = np.random.default_rng(seed)
    X, Y = np.meshgrid(np.linspace(0, 5, 60), np.linspace(0, 4, 50))
    x, y = X.ravel(), Y.ravel()
    a, b, h = rng.normal(0, 1e-4, 3)
    z = h + a * y - b * x + rng.normal(0, 1e-5, x.size)  # small tilts about x and y, and a height
    cloud = PointCloud.from_xyz(x, y, z)
    flat = EvenAsphere(0.0)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow RuntimeWarning
        res = _run(MisalignmentStep, cloud, flat)
    rep = res.report
    assert rep["parameters"] == ["alpha", "beta", "dz"]
    assert any("flat" in w for w in rep["warnings"])
    assert rep["condition_number"] < 1e3
    assert all(np.isfinite(v) and v < 1e-2 for v in rep["uncertainty"].values())
    assert np.std(res.cloud["residual"]) == pytest.approx(1e-5, rel=0.1)
    with pytest.raises(StepError, match=r"a flat .* cannot be fitted — use dof: \[alpha, beta, dz\]"):
        _run(MisalignmentStep, cloud, flat, dof=["alpha", "beta", "dx", "dy", "dz"])


@pytest.mark.parametrize("n, span", [(16, 3.0), (17, 1e-3), (25, 40.0), (28, 0.003), (40, 700.0)])
def test_automatic_map_spacing_is_always_feasible(n, span):
    rng = np.random.default_rng(n)
    if n == 16:
        X, Y = np.meshgrid(np.arange(4.0), np.arange(4.0))
        x, y = X.ravel() * span / 3, Y.ravel() * span / 3
    else:
        x, y = rng.uniform(0, span, n), rng.uniform(0, span, n)
    z = 1e-4 * np.sin(x / span * 3) + rng.normal(0, 1e-6, n)
    res = _run(BSplineMapStep, PointCloud.from_xyz(x, y, z))
    assert res.report["nodes"] > 0
    assert res.report["knot_spacing"] > 0


def test_height_map_without_residual_gets_a_labelled_summary():
    from pointspro.core.io import read_cloud

    cloud = read_cloud(REAL / "sur-2.sur")
    recipe = parse_recipe({"pointspro": 1, "steps": [{"bspline_map": {}}]})
    s = run_pipeline(cloud, recipe).summary()
    assert s["figures_of"] == "heights, piston and tilt removed (no residual)"
    assert s["rms_um"] == pytest.approx(np.std(remove_piston_tilt(cloud.x, cloud.y, cloud.z)) * 1e3)
    assert s["pupil"]["centre_from"].startswith("bounding-box centre")
    # the same map with an asphere's nominal but no residual: no figures are invented
    recipe = parse_recipe({"pointspro": 1, "surface": {"type": "even_asphere", "R": 100.0},
                           "steps": [{"bspline_map": {}}]})
    assert run_pipeline(cloud, recipe).summary()["rms_um"] is None


def test_a_residual_larger_than_the_input_is_an_error():
    x, y = np.meshgrid(np.linspace(0, 150, 30), np.linspace(0, 150, 30))
    cin = PointCloud.from_xyz(x.ravel(), y.ravel(), 1e-3 * np.sin(x.ravel()))
    good = cin.replace(channels={"residual": cin.z * 0.5})
    check_sanity(cin, good)
    bad = cin.replace(channels={"residual": cin.z * 0 + 1.5e6 * np.cos(x.ravel())})
    with pytest.raises(StepError, match=r"sanity check: the residual's RMS \(1.06 km|m\)"):
        check_sanity(cin, bad)
    nan = cin.replace(channels={"residual": np.where(x.ravel() > 100, np.nan, 0.0)})
    with pytest.raises(StepError, match="NaN"):
        check_sanity(cin, nan)


def test_map_x3p_is_read_by_surface_topography(tmp_path):
    import warnings

    from SurfaceTopography.IO import open_topography

    from pointspro.core.maps.grid import read_x3p_map

    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 20, 4000), rng.uniform(0, 10, 4000)
    res = _run(BSplineMapStep, PointCloud.from_xyz(x, y, 1e-4 * np.sin(x / 3)), spacing=0.5)
    res.artifacts["map.x3p"](tmp_path / "map.x3p")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = open_topography(str(tmp_path / "map.x3p")).topography()
    g = read_x3p_map(tmp_path / "map.x3p")
    assert t.nb_grid_pts == (len(g.xs), len(g.ys))
    h = np.ma.filled(t.heights().astype(float), np.nan).T  # SurfaceTopography's arrays are (x, y)
    assert np.allclose(h * 1e3 if t.unit == "m" else h, g.z, equal_nan=True, rtol=1e-12, atol=1e-15)


def test_points_microns_beyond_the_normalisation_radius_raise_no_warning():
    """A scan that ends at the clear aperture leaves points a few µm beyond it once the pose is
    removed: the extrapolation warning fired on 10 of 17 ordinary parts in a review. From 0.1 %."""
    rng = np.random.default_rng(5)
    r, t = 30.0 * np.sqrt(rng.uniform(0, 1, 2000)), rng.uniform(0, 2 * np.pi, 2000)
    r[:3] = 30.0 + 0.0069  # 6.9 µm beyond
    x, y = r * np.cos(t), r * np.sin(t)
    cloud = PointCloud(np.column_stack([x, y, 1e-4 * (x / 30) ** 2]))
    step = ZernikeStep()
    near = step.run(cloud, step.Params.model_validate({"terms": 4, "norm_radius": 30.0, "centre": [0, 0]}), Context())
    assert not any("outside the normalisation radius" in w for w in near.report["warnings"])
    far = step.run(cloud, step.Params.model_validate({"terms": 4, "norm_radius": 29.0, "centre": [0, 0]}), Context())
    assert any("outside the normalisation radius" in w for w in far.report["warnings"])


def test_a_rectangular_maps_tilt_alone_is_taken_from_its_best_fit_plane():
    """Removing tilt but not piston on a rectangular map with dropouts: the tilt of the best-fit plane
    (piston fitted beside it), not a tilt fitted without piston, which takes part of the mean where the
    points are not centred on the pupil."""
    rng = np.random.default_rng(2)
    X, Y = np.meshgrid(np.arange(120) * 0.1, np.arange(80) * 0.1)
    x, y = X.ravel(), Y.ravel()
    keep = (x > 3) | (y > 4)  # a missing corner: the points' mean is off the pupil centre
    x, y = x[keep], y[keep]
    z = 5e-4 + 2e-5 * x - 1e-5 * y + 3e-6 * np.cos(x) + rng.normal(0, 1e-7, x.size)
    res = _run(ZernikeStep, PointCloud.from_xyz(x, y, z), terms=36, remove=["tilt"])
    assert res.report["removal"].startswith("the removed terms fitted alone")
    A = np.column_stack([np.ones_like(x), x, y])
    b = np.linalg.lstsq(A, z, rcond=None)[0]
    want = z - A[:, 1:] @ b[1:]  # the plane's tilt away, its piston kept (about the pupil's centre:
    got = res.cloud["residual"]  # the same up to a constant)
    d = (got - got.mean()) - (want - want.mean())
    assert np.max(np.abs(d)) < 1e-12
