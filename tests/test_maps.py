"""bspline_map: accuracy, files (CSV, X3P, ASCII matrix), measured-region masking, bad input, speed
guard rails; zernike step; the self-contained report."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import StepError
from pointspro.core.maps import fit_bspline, grid_map
from pointspro.core.maps.grid import MapGrid, read_x3p_map
from pointspro.core.metrics import zernike as zk
from pointspro.core.step import Context
from pointspro.plugins.bspline_map import BSplineMapStep
from pointspro.plugins.zernike import ZernikeStep

R620 = 310.0


def smooth_form(x, y):
    """A polishing-like form error (mm): astigmatism, coma, a zone and a 160 mm ripple, ~µm."""
    r, t = np.hypot(x, y) / R620, np.arctan2(y, x)
    return (1.0e-3 * zk.zernike(2, 2, r, t) + 0.4e-3 * zk.zernike(3, 1, r, t)
            + 0.3e-3 * zk.zernike(4, 0, r, t) + 0.15e-3 * np.cos(2 * np.pi * x / 160.0)
            * np.cos(2 * np.pi * y / 220.0))


def raster_620(step=15.0, noise=0.0, seed=0):
    g = np.arange(-R620, R620 + 1e-9, step)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    keep = np.hypot(x, y) <= R620
    x, y = x[keep], y[keep]
    z = smooth_form(x, y) + np.random.default_rng(seed).normal(0, noise, len(x))
    return x, y, z


def _run(step, cloud, surface=None, **params):
    return step().run(cloud, step.Params.model_validate(params), Context(surface=surface))


def test_raster_620_reproduces_within_2_percent_inside_95_percent():
    """Issue 5: a known smooth form error on a 620 mm raster at 15 mm → map within 2 % of its RMS
    inside 95 % of the aperture."""
    x, y, z = raster_620()
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(z), residual=z)
    res = _run(BSplineMapStep, cloud, diameter=620.0, spacing=2.0, centre=(0.0, 0.0))
    from pointspro.core.maps import MapGrid  # noqa: F401

    spline = fit_bspline(x, y, z)  # over the points' box, as the step fits it
    grid = grid_map(spline, 2.0, x, y, diameter=620.0)
    X, Y = np.meshgrid(grid.xs, grid.ys)
    inner = (np.hypot(X, Y) <= 0.95 * R620) & grid.valid
    truth = smooth_form(X[inner], Y[inner])
    err = grid.z[inner] - truth
    rel = np.sqrt(np.mean(err**2)) / np.std(truth)
    assert rel < 0.02, rel
    assert inner.sum() > 0.9 * np.pi * (0.95 * R620) ** 2 / 4.0  # the inner disk is mapped
    assert res.report["nodes"] == int(grid.valid.sum())
    assert res.report["map_rms_um"] == pytest.approx(np.std(grid.z[grid.valid]) * 1e3)


def test_noise_is_smoothed_not_interpolated():
    x, y, z = raster_620(step=5.0, noise=2e-5, seed=3)
    s = fit_bspline(x, y, z)
    inner = np.hypot(x, y) < 0.9 * R620
    err = s(x[inner], y[inner]) - smooth_form(x[inner], y[inner])
    # ~4 points per knot cell: the map is about half as noisy as the data (and unbiased)
    assert np.sqrt(np.mean(err**2)) < 0.6 * 2e-5
    assert abs(np.mean(err)) < 1e-6


def test_derivatives_match_the_function():
    x, y, z = raster_620(step=5.0)
    s = fit_bspline(x, y, z)
    p = np.array([[10.0, -40.0], [120.0, 80.0], [-150.0, 30.0]])
    h = 1e-3
    fx = (smooth_form(p[:, 0] + h, p[:, 1]) - smooth_form(p[:, 0] - h, p[:, 1])) / (2 * h)
    fy = (smooth_form(p[:, 0], p[:, 1] + h) - smooth_form(p[:, 0], p[:, 1] - h)) / (2 * h)
    assert np.allclose(s(p[:, 0], p[:, 1], dx=1), fx, atol=0.03 * np.abs(fx).max())
    assert np.allclose(s(p[:, 0], p[:, 1], dy=1), fy, atol=0.03 * np.abs(fy).max())


def test_map_has_no_values_beyond_the_measured_region():
    x, y, z = raster_620()
    half = x < 0  # only the left half measured
    s = fit_bspline(x[half], y[half], z[half], bounds=(-R620, R620, -R620, R620))
    g = grid_map(s, 5.0, x[half], y[half], diameter=620.0)
    X, _ = np.meshgrid(g.xs, g.ys)
    assert np.all(np.isnan(g.z[X > 2 * s.h]))
    g2 = grid_map(s, 5.0, x[half], y[half], diameter=620.0, extrapolate=True)
    assert np.isfinite(g2.z[X > 2 * s.h]).any()


def test_map_files_round_trip(tmp_path):
    x, y, z = raster_620()
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(z), residual=z)
    res = _run(BSplineMapStep, cloud, diameter=620.0, spacing=5.0, matrix_unit="nm",
               centre=(0.0, 0.0))
    for name, art in res.artifacts.items():
        art(tmp_path / name)
    # CSV: one row per valid node, x y z in mm
    data = np.loadtxt(tmp_path / "map.csv", delimiter=",", skiprows=1)
    assert data.shape == (res.report["nodes"], 3)
    assert np.all(np.hypot(data[:, 0], data[:, 1]) <= R620 + 1e-9)
    assert np.allclose(np.round(data[:, :2] / 5.0) * 5.0, data[:, :2])
    # X3P through x3pio, back bit-exact (float64 storage) with its position and spacing
    g = read_x3p_map(tmp_path / "map.x3p")
    assert g.spacing == pytest.approx(5.0)
    X, Y = np.meshgrid(g.xs, g.ys)
    v = np.isfinite(g.z)
    assert v.sum() == len(data)
    back = np.column_stack([X[v], Y[v], g.z[v]])
    assert np.allclose(back[:, :2], data[:, :2], atol=1e-9)
    assert np.allclose(back[:, 2], data[:, 2], rtol=0, atol=1e-15)
    # ASCII matrix: header, NaN outside, heights in nm
    lines = (tmp_path / "map.asc").read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("#") and "nm" in "".join(lines[:5])
    assert f"# x0 {float(g.xs[0])!r} mm, y0 {float(g.ys[0])!r} mm, spacing 5.0 mm" in lines
    M = np.loadtxt(tmp_path / "map.asc", comments="#")
    assert M.shape == g.z.shape
    assert np.allclose(M[v] * 1e-6, g.z[v], atol=1e-15)
    assert np.isnan(M[~v]).all()
    prof = np.genfromtxt(tmp_path / "profiles.csv", delimiter=",", names=True)
    assert set(prof["angle_deg"]) == {0.0, 90.0}
    at0 = prof[prof["angle_deg"] == 0.0]  # header "angle [deg],s [mm],…": numpy names it angle_deg, s_mm …
    ok = np.isfinite(at0["z_mm"])
    assert np.allclose(at0["y_mm"], 0.0) and np.allclose(at0["x_mm"], at0["s_mm"])
    assert np.allclose(at0["z_mm"][ok], smooth_form(at0["x_mm"][ok], at0["y_mm"][ok]), atol=0.05 * np.std(z))
    psd = np.genfromtxt(tmp_path / "psd.csv", delimiter=",", names=True)
    assert psd["f_x_1mm"][0] == 0 and psd["f_y_1mm"][0] == 0 and np.all(psd["psd_x_mm3"][np.isfinite(psd["psd_x_mm3"])] >= 0)
    for png in ("map.png", "profiles.png", "psd.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_input_messages():
    x, y, z = raster_620()
    cloud = PointCloud.from_xyz(x[:10], y[:10], z[:10])
    with pytest.raises(StepError, match="10 points cannot carry a bicubic spline"):
        _run(BSplineMapStep, cloud)
    cloud = PointCloud.from_xyz(x, y, z)
    with pytest.raises(StepError, match="no point lies inside the 100 mm aperture"):
        _run(BSplineMapStep, cloud, diameter=100.0, centre=(2000.0, 0.0))
    with pytest.raises(StepError, match="asked for, but the cloud has none"):
        _run(BSplineMapStep, cloud, channel="residual")
    line = PointCloud.from_xyz(np.linspace(0, 10, 100), np.zeros(100), np.zeros(100))
    with pytest.raises(StepError, match="do not span an area"):
        _run(BSplineMapStep, line)
    with pytest.raises(StepError, match=r"points are too few for knots every 5 mm .*use knot_spacing ≥"):
        _run(BSplineMapStep, cloud, knot_spacing=5.0)


def test_zernike_step_removes_named_terms_and_keeps_the_rest():
    x, y, _ = raster_620(step=10.0)
    r, t = np.hypot(x, y) / R620, np.arctan2(y, x)
    keep_part = 0.8e-3 * zk.zernike(2, 2, r, t)
    z = 0.5e-3 + 0.3e-3 * zk.zernike(1, 1, r, t) + 0.6e-3 * zk.zernike(2, 0, r, t) + keep_part
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(z), residual=z)
    res = _run(ZernikeStep, cloud, norm_radius=R620, remove=["piston", "tilt", "power"])
    assert np.allclose(res.cloud["residual"], keep_part, atol=1e-12)
    rows = {(c["n"], c["m"]): c for c in res.report["coefficients"]}
    assert rows[(2, 2)]["coefficient_nm"] == pytest.approx(0.8e3 * 1e3 * 1e-3, rel=1e-9)
    assert rows[(2, 0)]["removed"] and not rows[(2, 2)]["removed"]
    assert res.report["removed_terms"] == [1, 2, 3, 4]  # Fringe piston, tilt x/y, power
    # the same by index in Noll ordering: Noll 4 is power
    res2 = _run(ZernikeStep, cloud, ordering="noll", norm_radius=R620, remove=[1, 2, 3, 4])
    assert np.allclose(res2.cloud["residual"], keep_part, atol=1e-12)
    assert "zernike.csv" in res.artifacts and "j,n,m,name" in res.artifacts["zernike.csv"]
    # every row parses to the header's 7 fields, the unnamed terms' "Z(4,2)" quoted (it shifted the
    # coefficients into the uncertainty column of a CSV reader), and reads back the report's numbers
    import csv
    import io

    rows = list(csv.DictReader(io.StringIO(res.artifacts["zernike.csv"])))
    assert len(rows) == 36 and all(None not in r and len(r) == 7 for r in rows)
    for r, c in zip(rows, res.report["coefficients"]):
        assert (r["name"], float(r["coefficient_nm"]), float(r["uncertainty_nm"])) == \
            (c["name"], c["coefficient_nm"], c["uncertainty_nm"])
    assert rows[11]["name"] == "Z(4,2)"


def test_zernike_bad_input():
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="unknown term name 'focus'"):
        ZernikeStep.Params.model_validate({"remove": ["focus"]})
    x, y, z = raster_620(step=100.0)
    cloud = PointCloud.from_xyz(x, y, z)
    with pytest.raises(StepError, match="cannot determine 36 Zernike terms"):
        _run(ZernikeStep, cloud)
    x, y, z = raster_620(step=20.0)
    # an index outside the fitted terms is refused with the parameters (a review: the window's form
    # took -4 and 400, the run failed later)
    for bad, ordering in ((40, "fringe"), (-4, "fringe"), (0, "noll"), (36, "ansi")):
        with pytest.raises(ValidationError, match=f"remove: index {bad} is not among the 36 fitted {ordering} terms"):
            ZernikeStep.Params.model_validate({"remove": [bad], "ordering": ordering})
    assert ZernikeStep.Params.model_validate({"remove": [0, 35], "ordering": "ansi"}).remove == [0, 35]
    # a name none of whose terms was fitted: removed nothing, silently, while the figure's title
    # named it (a review); now refused as an index is
    with pytest.raises(StepError, match="remove: spherical is not among the 4 fitted fringe terms"):
        _run(ZernikeStep, PointCloud.from_xyz(x, y, z), terms=4, remove=["piston", "tilt", "spherical"])
    # a name partly fitted (tilt's two terms within 3) still removes what was fitted
    assert _run(ZernikeStep, PointCloud.from_xyz(x, y, z), terms=3, remove=["piston", "tilt"]).report
    # the default list (piston, tilt, power) takes what a fit of 3 terms has
    assert _run(ZernikeStep, PointCloud.from_xyz(x, y, z), terms=3).report["removed_terms"] == [1, 2, 3]


def test_report_html_is_self_contained_with_figures(tmp_path, run_cli):
    from tests.conftest import EXAMPLE

    out = tmp_path / "out"
    code, _, err = run_cli("--batch", str(EXAMPLE / "recipe.yaml"), str(EXAMPLE / "asphere_cmm.csv"),
                           "--out", str(out))
    assert code == 0, err
    folder = out / "asphere_cmm"
    html = (folder / "report.html").read_text(encoding="utf-8")
    assert html.count("data:image/png;base64,") >= 6  # form error, ω, Zernike ×2, map, profiles, PSD
    assert "src='http" not in html and 'src="http' not in html
    import json

    rep = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    s = rep["summary"]
    assert s["pvr_um"] is not None and s["slope_rms_urad"] > 0
    assert s["pvr_um"] <= s["pv_um"] * 1.5
    for name in ("map.csv", "map.x3p", "map.asc", "zernike.csv"):
        assert (folder / name).is_file()


@pytest.mark.parametrize("n", [64, 65, 7])
def test_periodogram_in_numpy_equals_scipy(n):
    from scipy.signal import periodogram

    from pointspro.core.metrics.profiles import periodogram_hann

    x = np.random.default_rng(n).normal(size=(5, n))
    f, p = periodogram_hann(x, fs=2.5)
    f0, p0 = periodogram(x, fs=2.5, window="hann", detrend=False, scaling="density", axis=-1)
    assert np.allclose(f, f0, rtol=1e-15, atol=0) and np.allclose(p, p0, rtol=1e-12, atol=0)


def test_bilinear_profile_equals_scipys_regular_grid_interpolator_bit_for_bit():
    """profile()'s numpy interpolation (no scipy.interpolate import, issue 17) gives the values of
    RegularGridInterpolator(linear, NaN outside) to the last bit: random grids with NaN nodes, lines
    at random angles through and beyond them, points on the last row and column."""
    from scipy.interpolate import RegularGridInterpolator

    from pointspro.core.metrics.profiles import bilinear

    rng = np.random.default_rng(1)
    for trial in range(60):
        nx, ny = rng.integers(2, 60, 2)
        h = rng.uniform(0.1, 7)
        xs, ys = rng.uniform(-300, 0) + h * np.arange(nx), rng.uniform(-300, 0) + h * np.arange(ny)
        z = rng.normal(0, 1e-3, (ny, nx))
        z[rng.random((ny, nx)) < 0.2] = np.nan
        s, t = np.arange(-400, 400, h * rng.uniform(0.3, 1.5)), rng.uniform(0, np.pi)
        px, py = rng.uniform(-50, 50) + s * np.cos(t), rng.uniform(-50, 50) + s * np.sin(t)
        px, py = np.concatenate([px, xs, [xs[-1]]]), np.concatenate([py, np.full(nx, ys[0]), [ys[-1]]])
        ref = RegularGridInterpolator((ys, xs), z, bounds_error=False, fill_value=np.nan)(np.column_stack([py, px]))
        got = bilinear(ys, xs, z, py, px)
        assert np.array_equal(got[np.isfinite(ref)], ref[np.isfinite(ref)]), trial
        # where scipy says NaN, a value only for a point whose NaN neighbours carry no weight (on a node
        # or a cell's edge): it is then the valid nodes' own interpolation
        extra = np.isfinite(got) & ~np.isfinite(ref)
        filled = np.where(np.isfinite(z), z, 0.0)
        ref0 = RegularGridInterpolator((ys, xs), filled, bounds_error=False, fill_value=np.nan)(
            np.column_stack([py[extra], px[extra]]))
        assert np.allclose(got[extra], ref0, rtol=0, atol=1e-18), trial
        nan_weight = RegularGridInterpolator((ys, xs), (~np.isfinite(z)).astype(float), bounds_error=False,
                                             fill_value=np.nan)(np.column_stack([py[extra], px[extra]]))
        assert np.all(nan_weight == 0), trial


def test_profile_keeps_the_maps_rim_nodes_next_to_unmapped_ones():
    """A disc map at 1 mm spacing, z = x²/100: the profile along x through the centre runs from node
    to node, rim to rim (−10 … 10 mm, rim value 1.0). NaN × 0 at the unmapped nodes beside the rim
    lost them (the profile stopped at −9 and +8 mm; a review)."""
    from pointspro.core.maps.grid import MapGrid
    from pointspro.core.metrics.profiles import profile

    g = np.arange(-12.0, 12.5, 1.0)
    X, Y = np.meshgrid(g, g)
    z = np.where(np.hypot(X, Y) <= 10.0, X**2 / 100.0, np.nan)
    s, v = profile(MapGrid(g, g, z, 1.0), 0.0)
    ok = np.isfinite(v)
    assert s[ok].min() == pytest.approx(-10.0) and s[ok].max() == pytest.approx(10.0)
    assert v[ok][0] == pytest.approx(1.0) and v[ok][-1] == pytest.approx(1.0)
    assert np.count_nonzero(ok) >= 21


def _ripple_grid(pitch, half, lam, amp):
    g = np.arange(-half, half + 1e-9, pitch)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    k = 2 * np.pi / lam
    e = amp * np.sin(k * x) * np.cos(0.8 * k * y)
    gx = amp * k * np.cos(k * x) * np.cos(0.8 * k * y)
    gy = -amp * 0.8 * k * np.sin(k * x) * np.sin(0.8 * k * y)
    return x, y, e, gx, gy


@pytest.mark.parametrize("hole", ["bore 30", "bore 50", "strip 12", "strip 20", "sector"])
def test_holes_in_the_measured_region_do_not_coarsen_the_knots(hole):
    """A central bore, a dropout strip (a support arm's shadow) or a missing sector is not a gap of the
    sampling pattern: the knots stay those of the full disc, and the map's RMS and the summary's slope
    RMS are the true ones (before: a 30 mm bore in 100 mm on a 1 mm grid gave knots of 8.3 mm and a
    slope RMS 6× too small; an 11 % strip 50× too small)."""
    import pointspro.core as pp

    x, y, e, gx, gy = _ripple_grid(1.0, 50.0, 10.0, 1e-5)
    r = np.hypot(x, y)
    keep = r <= 50
    kind, _, size = hole.partition(" ")
    if kind == "bore":
        keep &= r >= float(size) / 2
    elif kind == "strip":
        keep &= ~((np.abs(y) < float(size) / 2) & (x > 0) & (x < 45))
    else:
        keep &= ~((np.degrees(np.arctan2(y, x)) % 360) < 40)
    cloud = PointCloud.from_numpy(np.column_stack([x[keep], y[keep], e[keep]]), residual=e[keep],
                                  meta={"frame": "part"})
    res = pp.run({"steps": [{"bspline_map": {}}]}, cloud)
    rep = res.steps[0].report
    assert rep["knot_spacing"] <= 2.4  # the full disc's: 2.0 mm
    assert rep["map_rms_um"] * 1e3 == pytest.approx(np.std(e[keep]) * 1e6, rel=0.02)
    sx, sy = gx[keep] - gx[keep].mean(), gy[keep] - gy[keep].mean()
    assert res.summary["slope_rms_urad"] == pytest.approx(1e6 * np.sqrt(np.mean(sx**2 + sy**2)), rel=0.02)


@pytest.mark.parametrize("seed", range(6))
def test_random_points_and_scan_patterns_have_no_holes(seed):
    """The hole test (core.maps.bspline._holes) finds none where there is none: random points, a
    star's widening gaps, a spiral — their knot spacing is the sampling pattern's, as before."""
    from scipy.spatial import cKDTree

    from pointspro.core.maps.bspline import PLACES, _holes

    rng = np.random.default_rng(seed)
    n = 20_000
    a, s = rng.uniform(0, 2 * np.pi, n), 50 * np.sqrt(rng.uniform(0, 1, n))
    spokes = np.repeat(np.arange(18) * np.pi / 18, 200)
    t = np.tile(np.linspace(-50, 50, 200), 18)
    turns = np.linspace(0, 40 * 2 * np.pi, n)
    for px, py in ((s * np.cos(a), s * np.sin(a)), (t * np.cos(spokes), t * np.sin(spokes)),
                   (50 * turns / turns[-1] * np.cos(turns + seed), 50 * turns / turns[-1] * np.sin(turns + seed))):
        g = np.stack(np.meshgrid(np.linspace(-50, 50, PLACES), np.linspace(-50, 50, PLACES)), -1)
        inside = np.hypot(g[..., 0], g[..., 1]) <= 48
        d = np.full(inside.shape, np.nan)
        d[inside] = cKDTree(np.column_stack([px, py])).query(g[inside])[0]
        assert not _holes(d, inside).any()


def test_a_patch_of_a_large_part_is_mapped_at_its_own_sampling(tmp_path, run_cli):
    """A 100 mm patch measured at 1 mm on a part whose aperture is 1300 mm: the spline covers the
    patch, not the aperture's box (where its knots were coarsened to 15 mm and the map missed the
    10 nm ripple it was measured for), and every map file is written (psd.csv failed: "no grid
    line is half inside the map")."""
    import pointspro.core as pp

    x, y, e, gx, gy = _ripple_grid(1.0, 50.0, 10.0, 1e-5)
    keep = np.hypot(x, y) <= 50
    x, y, e = x[keep] + 300.0, y[keep], e[keep]
    surface = {"type": "even_asphere", "c": 5e-4, "k": -1, "aperture": 1300}
    cloud = PointCloud.from_numpy(np.column_stack([x, y, e]), residual=e, meta={"frame": "part"})
    res = pp.run({"surface": surface, "steps": [{"bspline_map": {"spacing": 1.0}}]}, cloud)
    rep = res.steps[0].report
    assert rep["knot_spacing"] < 2.5
    assert rep["map_rms_um"] * 1e3 == pytest.approx(np.std(e) * 1e6, rel=0.02)
    assert rep["fit_residual_rms_um"] * 1e3 < 1.0  # the ripple is in the map, not left in the rest
    assert rep["grid"][0] * rep["grid"][1] < 2 * rep["nodes"]  # the grid spans the patch
    # the summary's slope RMS takes this very spline (core.pipeline._reusable)
    assert res.summary["slope_rms_urad"] == pytest.approx(
        1e6 * np.sqrt(np.mean((gx[keep] - gx[keep].mean()) ** 2 + (gy[keep] - gy[keep].mean()) ** 2)),
        rel=0.02)
    (tmp_path / "patch.csv").write_text("x,y,z,residual\n" + "\n".join(
        f"{a!r},{b!r},{c!r},{c!r}" for a, b, c in zip(x.tolist(), y.tolist(), e.tolist())), encoding="utf-8")
    (tmp_path / "r.yaml").write_text("pointspro: 1\nsurface: {type: even_asphere, c: 0.0005, k: -1, "
                                     "aperture: 1300}\nsteps:\n  - bspline_map: {spacing: 1.0}\n",
                                     encoding="utf-8")
    code, _, err = run_cli("--batch", str(tmp_path / "r.yaml"), str(tmp_path / "patch.csv"), "--out",
                           str(tmp_path / "o"), "--quiet", "--figures", "none")
    assert code == 0, err
    assert (tmp_path / "o" / "patch" / "psd.csv").stat().st_size > 100


def test_map_spacing_beyond_the_region_or_absurdly_fine_is_refused():
    """spacing 700 mm over a 1290 mm part gave a 1 × 1 map with RMS and PV 0 and exit 0; 1e-9 mm
    asked numpy for 9.5 TiB (MemoryError, "please report") — both one clear message now."""
    from pointspro.core.maps import fit_bspline, grid_map

    rng = np.random.default_rng(0)
    x, y = rng.uniform(-645, 645, (2, 4000))
    spline = fit_bspline(x, y, 1e-4 * np.sin(x / 200))
    with pytest.raises(ValueError, match=r"spacing 700 mm leaves 1 × 1 map nodes"):
        grid_map(spline, 700.0, x, y)
    with pytest.raises(ValueError, match="too large"):
        grid_map(spline, 1e-9, x, y)
    assert grid_map(spline, 300.0, x, y).z.shape == (5, 5)  # ≤ span / 4: ≥ 3 nodes across


def test_form_error_png_of_a_grid_has_no_empty_bins():
    """The report's form_error.png of a 256 × 256 map: 307 bins across left empty rows and columns."""
    from pointspro.core.figures import default_bins, scattered_map

    g = np.arange(256) * 0.04  # mm
    X, Y = np.meshgrid(g, g)
    r = 1e-5 * np.sin(X)
    assert default_bins(X.size) == 307 and default_bins(X.size, np.ptp(g), [0.04, 0.04]) == 254
    assert default_bins(300) == 20 and default_bins(20) == 16  # a small cloud: not 60 × 60 mostly empty
    img = scattered_map(X.ravel(), Y.ravel(), r.ravel(), pixel_mm=[0.04, 0.04]).axes[0].images[0].get_array()
    assert not np.isnan(np.asarray(img, dtype=float)).any()
    img = scattered_map(X.ravel(), Y.ravel(), r.ravel()).axes[0].images[0].get_array()
    assert not np.isnan(np.asarray(img, dtype=float)).any()  # without the pixel too: its pitch is read
    # from the coordinates (core.figures.raster_pitch; it had the gaps — a review of the window)


def test_the_map_says_when_the_scan_gaps_set_its_knots():
    """On a star scan the automatic knots follow the widest gap between the lines (the example:
    86.6 mm for points every 5 mm along them), and a 40 mm ring is smoothed away with no sign in the
    fit residual: the report says what the map cannot hold. A raster: no note."""
    from .paper002 import raster, star

    step = BSplineMapStep()
    for (x, y), noted in ((star(1000.0, lines=12, pitch=5.0), True), (raster(1000.0, 12.0), False)):
        cloud = PointCloud(np.column_stack([x, y, np.zeros_like(x)]), {"residual": 1e-4 * (x / 500) ** 2})
        rep = step.run(cloud, step.Params(), Context()).report
        assert ("resolution_note" in rep) is noted, rep.get("resolution_note")
        if noted:
            assert "widest gaps between the scan's lines" in rep["resolution_note"]


@pytest.mark.parametrize("revision", ["2000", "2017"])
def test_x3p_record_names_pointspro_and_claims_no_calibration(tmp_path, revision):
    """Record2 named x3pio as the instrument and wrote the moment of writing as CalibrationDate — in
    ISO 25178-72 the instrument's last calibration (a review). Now PointsPro and its version, a
    software probing system; the 2017 revision has no CalibrationDate (the 2000 schema requires one)."""
    import zipfile

    from pointspro.core import __version__

    g = MapGrid(np.arange(5.0) * 0.5, np.arange(4.0) * 0.5, np.zeros((4, 5)), 0.5)
    g.write_x3p(tmp_path / "m.x3p", revision=revision)
    xml = zipfile.ZipFile(tmp_path / "m.x3p").read("main.xml").decode("utf-8")
    assert "<Manufacturer>PointsPro</Manufacturer>" in xml and f"<Version>{__version__}</Version>" in xml
    assert "x3pio" not in xml.split("<Record3>")[0]
    assert ("<CalibrationDate>" in xml) == (revision == "2000")
    # the creator named, no blank serial number (a review read both as empty)
    assert f"<Creator>PointsPro {__version__}</Creator>" in xml and "<Serial>not available</Serial>" in xml
    assert read_x3p_map(tmp_path / "m.x3p").z.shape == (4, 5)


@pytest.mark.parametrize("noise_nm, warned", [(0.0, False), (2.0, True), (10.0, True)])
def test_extrapolated_map_reports_the_measured_nodes_and_warns(noise_nm, warned):
    """A review: points to 9 mm mapped with `extrapolate` over a 20 mm aperture read map PV 3155 nm for
    a true 418 nm at 10 nm of noise (791 nm at 2 nm) without a word. The report now gives the map's
    RMS and PV over the measured nodes and the extrapolated share, and warns when the PV over all
    nodes is well above the measured nodes'."""
    import pointspro.core as pp

    g = np.arange(-9.0, 9.0 + 1e-9, 0.12)
    X, Y = np.meshgrid(g, g)
    k = np.hypot(X, Y) <= 9.0
    x, y = X[k], Y[k]
    r2 = (x * x + y * y) / 100.0
    v = 80e-6 * (x * x - y * y) / 100.0 + 30e-6 * (6 * r2 * r2 - 6 * r2 + 1)
    v = v + np.random.default_rng(7).normal(0, noise_nm * 1e-6, v.size)
    res = pp.run({"steps": [{"bspline_map": {"diameter": 20.0, "extrapolate": True}}]},
                 pp.PointCloud.from_numpy(np.column_stack([x, y, v]), residual=v))
    rep = res.steps[-1].report
    assert 0.1 < rep["extrapolated_node_fraction"] < 0.3
    assert rep["map_pv_measured_um"] < 0.45  # the field over the points: ~0.32 µm
    assert any("extrapolated beyond the points" in w for w in rep["warnings"]) == warned


def test_a_height_maps_figure_shows_it_less_piston_and_tilt(monkeypatch):
    """An instrument's heights (channel z, no residual) with a 50 µm offset and a 0.3 µm tilt over
    10 nm of form: map.png was one saturated colour on a ±50 µm range, its title's RMS the tilt's (a
    review on a real MetroPro map: 75 nm beside the summary's 13 nm). The figure shows the heights
    less their plane and says so; map.csv keeps z."""
    import pointspro.core.figures as figs

    g = np.arange(-10.0, 10.01, 0.25)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    form = 1e-5 * np.cos(2 * np.pi * x / 7.0) * np.cos(2 * np.pi * y / 9.0)
    z = 0.05 + 1.5e-5 * x + form
    res = BSplineMapStep().run(PointCloud.from_xyz(x, y, z), BSplineMapStep.Params(), Context())
    rep = res.report
    grid = res.artifacts["map.csv"].__self__
    assert np.nanmax(grid.z) > 0.049  # the file keeps the heights
    true_rms = np.std(form) * 1e3
    assert rep["map_rms_tilt_removed_um"] == pytest.approx(true_rms, rel=0.05)
    assert rep["map_rms_um"] > 10 * true_rms
    drawn = {}
    monkeypatch.setattr(figs, "grid_map_figure", lambda gr, title: drawn.update(grid=gr, title=title))
    monkeypatch.setattr(figs, "profiles_figure",
                        lambda gr, angles, centre, quantity: drawn.update(profiles=gr, quantity=quantity))
    monkeypatch.setattr(figs, "save_png", lambda fig, path: None)
    arts = BSplineMapStep().run(PointCloud.from_xyz(x, y, z), BSplineMapStep.Params(), Context()).artifacts
    arts["map.png"]("x.png")
    arts["profiles.png"]("p.png")
    assert "piston and tilt removed" in drawn["title"] and "piston and tilt removed" in drawn["quantity"]
    assert np.nanmax(np.abs(drawn["grid"].z)) < 3e-5  # the form, not the 50 µm offset
    assert np.nanmax(np.abs(drawn["profiles"].z)) < 3e-5  # profiles.png too (a review of the change)
