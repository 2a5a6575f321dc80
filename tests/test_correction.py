"""`correction`: the form error turned into what the next run takes, and the loop shown closing."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.correction.files import fixed_point_bytes, read_comment_csv, write_grid_csv
from pointspro.core.correction.loop import Program, cut_and_measure, default_machine, true_form_error
from pointspro.core.errors import StepError
from pointspro.core.step import Context
from pointspro.core.surfaces import EvenAsphere, QConAsphere, XYPolynomial, surface_from_spec
from pointspro.plugins.correction import CorrectionParams, CorrectionStep


def _run(cloud, surface=None, **params):
    return CorrectionStep().run(cloud, CorrectionParams.model_validate(params), Context(surface=surface))


def _write_all(res, folder):
    folder.mkdir(parents=True, exist_ok=True)
    for name, art in res.artifacts.items():
        if name.endswith(".png"):
            continue
        p = folder / name
        if callable(art):
            art(p)
        else:
            p.write_text(art, encoding="utf-8")
    return folder


def _grid_of(path):
    """(xs, ys, Z) of a grid CSV written by the step; also its comment lines."""
    comments, header, d = read_comment_csv(path)
    xs, ys = np.unique(d[:, 0]), np.unique(d[:, 1])
    Z = np.full((ys.size, xs.size), np.nan)
    Z[np.searchsorted(ys, d[:, 1]), np.searchsorted(xs, d[:, 0])] = d[:, 2]
    return xs, ys, Z, comments, header


def _map_cloud(fn, half=30.0, h=0.25, radius=None):
    """A regular-grid map of the error fn(x, y) (mm) as a cloud with a residual."""
    g = np.arange(-half, half + h / 2, h)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    if radius is not None:
        keep = np.hypot(x, y) <= radius
        x, y = x[keep], y[keep]
    return PointCloud.from_xyz(x, y, np.zeros_like(x), residual=fn(x, y))


NOMINAL = EvenAsphere(1 / 200.0, -0.5, {4: 1e-7}, aperture=50.0)


def test_sign_piston_tilt_and_files(tmp_path):
    """A high spot (positive residual) gives a negative dz (cut lower next time); piston and tilt are
    removed and reported; every file states the sign; dz = −E for detail coarser than the cutoff."""
    def err(x, y):
        return 2e-4 * np.exp(-((x - 5) ** 2 + y**2) / (2 * 6.0**2)) + 3e-4 + 1e-5 * x - 2e-5 * y
    res = _run(_map_cloud(err), NOMINAL, cutoff_mm=1.0)
    rep = res.report
    assert rep["map_from"].startswith("the input's 0.25 mm grid")
    assert rep["outputs"] == ["cutting", "radial", "freeform", "polishing"]
    assert rep["tilt_removed_urad"][0] == pytest.approx(10.0, rel=0.2)
    assert rep["tilt_removed_urad"][1] == pytest.approx(-20.0, rel=0.2)
    out = _write_all(res, tmp_path / "o")
    xs, ys, dz, comments, header = _grid_of(out / "correction.csv")
    assert header == "x [mm],y [mm],dz [mm]"
    assert any("ADD to the programmed surface" in c for c in comments)
    assert any("piston" in c and "tilt removed" in c for c in comments)
    X, Y = np.meshgrid(xs, ys)
    i = np.nanargmin(dz)
    assert np.hypot(X.flat[i] - 5, Y.flat[i]) < 1.0  # the high spot is cut down most
    inside = np.hypot(X, Y) <= 25
    # dz + E has no form left beyond a plane (the bump is much wider than the cutoff)
    e = err(X, Y)
    s = (dz + e)[inside]
    A = np.column_stack([np.ones(s.size), X[inside], Y[inside]])
    left = s - A @ np.linalg.lstsq(A, s, rcond=None)[0]
    assert np.sqrt(np.mean(left**2)) < 0.02 * np.std(e[inside])
    # no plane left in dz over the aperture
    A = np.column_stack([np.ones(inside.sum()), X[inside], Y[inside]])
    assert np.abs(np.linalg.lstsq(A, dz[inside], rcond=None)[0][1:]).max() < 1e-9
    # the extension: dz written beyond the aperture to 25 + cutoff
    assert np.nanmax(np.hypot(X, Y)[np.isfinite(dz)]) == pytest.approx(26.0, abs=0.26)
    for name in ("removal.csv", "corrected_sag.csv", "correction_radial.csv", "corrected_surface.yaml"):
        assert "PointsPro" in (out / name).read_text(encoding="utf-8").splitlines()[0]


def test_low_pass_is_iso_gaussian_50_percent_at_cutoff():
    """A sinusoid at the cutoff wavelength comes through at half its amplitude; one at 4× passes
    nearly whole; one at a quarter is stopped."""
    out = {}
    for lam in (2.0, 8.0, 0.5):
        res = _run(_map_cloud(lambda x, y, lam=lam: 1e-4 * np.cos(2 * np.pi * x / lam), h=0.05, half=12),
                   None, diameter=16.0, cutoff_mm=2.0, outputs=["cutting"])
        g = res.artifacts["correction.x3p"].grid  # the correction grid
        X, Y = np.meshgrid(g.xs, g.ys)
        inner = np.hypot(X, Y) <= 8 - 2 * 2.0  # away from the edge's continuation
        e = 1e-4 * np.cos(2 * np.pi * X[inner] / lam)
        out[lam] = np.std(g.z[inner]) / np.std(e)
    assert out[2.0] == pytest.approx(0.5, abs=0.03)
    assert out[8.0] > 0.95
    assert out[0.5] < 0.01


@pytest.mark.parametrize("case", [
    ("even_asphere", 0, "raster"),
    ("even_asphere_concave", 1, "spiral"),
    ("qcon", 2, "raster"),
])
def test_loop_two_runs_keep_under_20_percent(case):
    """Run 1 on a machine with repeatable spindle, squareness, straightness and tool-radius errors;
    run 2 programmed with the correction keeps ≤ 20 % of run 1's RMS form error over the clear
    aperture — measured, and on the true part."""
    kind, seed, path = case
    rng = np.random.default_rng(100 + seed)
    nominal = {"even_asphere": NOMINAL,
               "even_asphere_concave": EvenAsphere(-1 / 150.0, -1.2, {4: -2e-8, 6: 1e-12}, aperture=40.0),
               "qcon": QConAsphere(1 / 300.0, -0.8, [2e-3, -4e-4, 1e-4], 30.0, aperture=60.0)}[kind]
    radius = nominal.aperture / 2
    machine = default_machine(radius, rng)
    scan = ({"type": "raster", "radius": radius + 1.5, "spacing": 0.3, "lines": int((radius + 1.5) / 0.15)}
            if path == "raster" else
            {"type": "spiral", "radius": radius + 1.5, "rpm": 60, "pitch": 0.3, "fs": 300})
    prog = Program(nominal)
    meas, true = [], []
    for run in range(2):
        cloud = cut_and_measure(prog, machine, radius=radius, scan=scan, noise_mm=3e-6, seed=seed * 10 + run)
        res = _run(cloud, nominal, cutoff_mm=2.5, knot_spacing=1.0, spacing=0.25,
                   outputs=["cutting"], history_rms_um=meas)
        meas.append(res.report["error_rms_um"])
        true.append(true_form_error(prog, machine, radius))
        cor = res.artifacts["correction.x3p"].grid
        prog = prog.add(cor.xs, cor.ys, cor.z)
    assert meas[0] > 0.05  # a real error to correct (µm)
    assert meas[1] <= 0.2 * meas[0], meas
    assert true[1] <= 0.2 * true[0], true
    assert res.report["runs_rms_um"] == meas


def test_gain_below_one_converges_run_by_run(tmp_path):
    """gain 0.5: each run keeps about half the error; the history is reported and plotted."""
    radius = 25.0
    machine = default_machine(radius, np.random.default_rng(5))
    scan = {"type": "raster", "radius": 26.5, "spacing": 0.3, "lines": 177}
    prog = Program(NOMINAL)
    runs = []
    for run in range(4):
        cloud = cut_and_measure(prog, machine, radius=radius, scan=scan, noise_mm=2e-6, seed=40 + run)
        res = _run(cloud, NOMINAL, cutoff_mm=2.5, knot_spacing=1.0, spacing=0.25, gain=0.5,
                   outputs=["cutting"], history_rms_um=runs)
        runs.append(res.report["error_rms_um"])
        cor = res.artifacts["correction.x3p"].grid
        prog = prog.add(cor.xs, cor.ys, cor.z)
    assert all(b < 0.7 * a for a, b in zip(runs, runs[1:])), runs
    assert runs[-1] < 0.2 * runs[0]
    assert res.report["run_ratios"] == pytest.approx([b / a for a, b in zip(runs, runs[1:])])
    assert "correction_history.png" in res.artifacts
    res.artifacts["correction_history.png"](tmp_path / "h.png")
    assert (tmp_path / "h.png").stat().st_size > 1000


@pytest.mark.parametrize("nominal", [
    NOMINAL,
    QConAsphere(1 / 300.0, -0.8, [2e-3, -4e-4, 1e-4], 30.0, aperture=60.0),
    EvenAsphere(1 / 80.0, 0.0, {}, aperture=30.0),
])
def test_corrected_surface_matches_nominal_plus_radial_within_1nm(nominal, tmp_path):
    """corrected_surface.yaml is the recipe's surface syntax; its sag = nominal + the radial
    correction (correction_radial.csv) to ≤ 1 nm RMS over the clear aperture."""
    radius = nominal.aperture / 2
    machine = default_machine(radius, np.random.default_rng(7))
    scan = {"type": "raster", "radius": radius + 1.5, "spacing": 0.3, "lines": int((radius + 1.5) / 0.15)}
    cloud = cut_and_measure(Program(nominal), machine, radius=radius, scan=scan, noise_mm=3e-6, seed=3)
    res = _run(cloud, nominal, cutoff_mm=2.5, knot_spacing=1.0, spacing=0.25)
    out = _write_all(res, tmp_path / "o")
    from pointspro.core.yamlio import load_yaml

    spec = load_yaml((out / "corrected_surface.yaml").read_text(encoding="utf-8"), "yaml")["surface"]
    surf = surface_from_spec(spec)
    info = res.report["corrected_surface"]
    assert spec["type"] == info["type"] == nominal.kind  # its own type fits here
    _, header, d = read_comment_csv(out / "correction_radial.csv")
    assert header == "r [mm],dz [mm]"
    r, dz = d[:, 0], d[:, 1]
    ins = r <= radius
    # the new vertex is at z = 0: the correction's piston is the reported z offset of the program
    err = surf.sag_r(r[ins]) + info["vertex_offset_um"] * 1e-3 - nominal.sag_r(r[ins]) - dz[ins]
    w = np.maximum(r[ins], 0.0625)
    assert np.sqrt(np.average(err**2, weights=w)) <= 1e-6
    assert np.sqrt(np.mean(err**2)) <= 1e-6 and np.max(np.abs(err)) < 5e-6
    assert info["fit_rms_nm"] <= 1.0
    # the radial correction is the symmetric part of dz: the remainder is reported
    assert res.report["radial"]["non_symmetric_rms_um"] > 0
    assert res.report["radial"]["symmetric_rms_um"] > 0


def test_programmed_surface_carries_the_loop():
    """With programmed_surface (the previous corrected_surface.yaml's surface) the corrected surface
    is that program plus this run's radial correction."""
    prog = {"type": "even_asphere", "c": 1 / 200.0, "k": -0.49, "A": {4: 1.0e-7}}
    cloud = _map_cloud(lambda x, y: 1e-4 * (np.hypot(x, y) / 25) ** 4, radius=29)
    res = _run(cloud, NOMINAL, cutoff_mm=2.0, programmed_surface=prog, outputs=["radial"])
    s = surface_from_spec(res.report["corrected_surface"]["surface"])
    p = surface_from_spec(prog)
    # the correction of a +r⁴ error is about −r⁴ (less its piston), added to the program, not to
    # the nominal (which differs from it by 6 µm at the rim)
    rise = s.sag_r(25.0) - p.sag_r(25.0) - (s.sag_r(0.0) - p.sag_r(0.0))
    assert rise == pytest.approx(-1e-4, abs=1e-5)
    assert abs(p.sag_r(25.0) - NOMINAL.sag_r(25.0)) > 5e-3 * 1e-3


def test_removal_map_nonnegative_volume_and_x3p(tmp_path):
    def err(x, y):
        return 3e-4 * np.cos(np.pi * x / 30) * np.cos(np.pi * y / 40)
    res = _run(_map_cloud(err), NOMINAL, cutoff_mm=1.0, bias_um=0.05, outputs=["polishing"])
    out = _write_all(res, tmp_path / "o")
    xs, ys, rem, comments, header = _grid_of(out / "removal.csv")
    assert header == "x [mm],y [mm],removal [um]"
    assert any("REMOVE" in c for c in comments)
    assert np.nanmin(rem) == pytest.approx(0.05, abs=1e-9)
    assert np.all(rem[np.isfinite(rem)] >= 0)
    rep = res.report["removal"]
    assert rep["max_depth_um"] == pytest.approx(np.nanmax(rem), rel=1e-9)
    assert rep["volume_mm3"] == pytest.approx(np.nansum(rem) * 1e-3 * 0.25**2, rel=1e-9)
    # the high spots are removed most (removal ~ E about its minimum)
    X, Y = np.meshgrid(xs, ys)
    i = np.nanargmax(rem)
    assert err(X.flat[i], Y.flat[i]) > 0.9 * 3e-4 * np.cos(np.pi * 25 / 30 / np.sqrt(2)) ** 2 * 0.5
    from pointspro.core.maps.grid import read_x3p_map

    g = read_x3p_map(out / "removal.x3p")
    ix = np.searchsorted(np.round(g.xs, 9), np.round(xs, 9))
    iy = np.searchsorted(np.round(g.ys, 9), np.round(ys, 9))
    assert np.allclose(g.z[np.ix_(iy, ix)] * 1e3, rem, equal_nan=True, atol=1e-6)
    assert set(res.artifacts) >= {"removal.csv", "removal.x3p"} and "correction.csv" not in res.artifacts


def test_freeform_sag_and_stl(tmp_path):
    res = _run(_map_cloud(lambda x, y: 1e-4 * x * y / 625), NOMINAL, cutoff_mm=1.0, outputs=["freeform"])
    out = _write_all(res, tmp_path / "o")
    xs, ys, Z, comments, _ = _grid_of(out / "corrected_sag.csv")
    X, Y = np.meshgrid(xs, ys)
    ok = np.isfinite(Z) & (np.hypot(X, Y) <= 25 - 1.0)  # inside the aperture, one cutoff from the rim
    dz = Z[ok] - NOMINAL.sag(X[ok], Y[ok])
    # xy/625 is a saddle, not tilt: the correction is its negative
    assert np.allclose(dz, -1e-4 * X[ok] * Y[ok] / 625, atol=3e-6)
    from pointspro.core.io.mesh import read_mesh

    V, F = read_mesh(out / "corrected_surface.stl")[:2]
    assert len(F) == res.report["freeform"]["faces"]
    assert np.allclose(np.sort(V[:, 2])[[0, -1]], [np.nanmin(Z), np.nanmax(Z)], atol=1e-5)


def test_non_rotational_nominal_skips_radial_and_says_why():
    xy = XYPolynomial({(2, 0): 1e-3, (0, 2): -5e-4}, 0.0, 0.0, 20.0, aperture=40.0)
    res = _run(_map_cloud(lambda x, y: 1e-5 * np.cos(x / 5), radius=24), xy, cutoff_mm=1.0)
    assert "radial" not in res.report["outputs"] and "freeform" in res.report["outputs"]
    assert "not a surface of revolution" in res.report["skipped"]["radial"]
    with pytest.raises(StepError, match="rotationally symmetric"):
        _run(_map_cloud(lambda x, y: 0 * x, radius=24), xy, cutoff_mm=1.0, outputs=["radial"])


def test_no_nominal_gives_cutting_and_polishing_only():
    res = _run(_map_cloud(lambda x, y: 1e-5 * np.cos(x / 5)), None, diameter=50, cutoff_mm=1.0)
    assert res.report["outputs"] == ["cutting", "polishing"]
    assert set(res.report["skipped"]) == {"radial", "freeform"}


# --- bad input: one line each, nothing written ----------------------------------------------------

def _one_line(e):
    msg = str(e.value)
    assert "\n" not in msg and len(msg) < 400
    return msg


def test_bad_input_one_line_each():
    cloud = _map_cloud(lambda x, y: 1e-5 * np.cos(x / 5))
    with pytest.raises(StepError) as e:
        _run(cloud, None, diameter=50, cutoff_mm=1.0, outputs=["freeform"])
    assert "output 'freeform'" in _one_line(e) and "corrected_sag.csv" in str(e.value)
    with pytest.raises(StepError) as e:
        _run(cloud, None, diameter=50, cutoff_mm=1.0, outputs=["cutting", "radial"])
    assert "output 'radial'" in _one_line(e) and "nominal" in str(e.value)
    with pytest.raises(StepError) as e:
        _run(cloud, NOMINAL, cutoff_mm=0.2)
    assert "below twice the map spacing" in _one_line(e)
    with pytest.raises(StepError) as e:
        _run(cloud, NOMINAL, cutoff_mm=0.6, spacing=0.5, knot_spacing=1.0)  # scattered path
    assert "below twice the map spacing" in _one_line(e)
    with pytest.raises(StepError) as e:
        _run(_map_cloud(lambda x, y: 0 * x, radius=20), NOMINAL, cutoff_mm=1.0)
    assert "covers" in _one_line(e) and "50 mm clear aperture" in str(e.value)
    with pytest.raises(StepError) as e:
        _run(_map_cloud(lambda x, y: 1e-3 * np.cos(x / 5)), NOMINAL, cutoff_mm=1.0, max_depth_um=0.5)
    assert "max_depth_um" in _one_line(e) and "nothing written" in str(e.value)
    with pytest.raises(StepError) as e:
        _run(cloud, None, cutoff_mm=1.0)
    assert "clear aperture" in _one_line(e)


def test_bad_input_in_batch_writes_nothing(tmp_path, run_cli):
    from tests.conftest import write

    g = np.arange(-30, 30.01, 0.5)
    X, Y = np.meshgrid(g, g)
    data = write(tmp_path / "part.csv", "x,y,z,residual\n" + "".join(
        f"{a},{b},0,{1e-3 * np.cos(a / 5)}\n" for a, b in zip(X.ravel(), Y.ravel())))
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsurface: {type: even_asphere, R: 200, k: -0.5, "
                   "aperture: 50}\nsteps:\n  - correction: {cutoff_mm: 2, max_depth_um: 0.5}\n")
    code, out, err = run_cli("--batch", recipe, data, "--out", tmp_path / "out")
    assert code == 2  # one input, failed on its data: an input error
    assert "max_depth_um" in out + err and "nothing written" in out + err
    assert not (tmp_path / "out" / "part").exists()


def test_scattered_points_coverage_and_regular_grid_with_holes():
    """A map with a few dropouts inside the aperture is taken node for node, the holes filled and
    counted; a scattered cloud is fitted first."""
    cloud = _map_cloud(lambda x, y: 1e-5 * np.cos(x / 5), radius=28)
    keep = np.ones(cloud.n, bool)
    keep[np.random.default_rng(1).choice(cloud.n, 30, replace=False)] = False
    res = _run(cloud.select(keep), NOMINAL, cutoff_mm=1.0, outputs=["cutting"])
    assert res.report["map_from"].startswith("the input's") and res.report["holes_filled"] > 0
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-28, 28, (2, 20000))
    sc = PointCloud.from_xyz(x, y, 0 * x, residual=1e-5 * np.cos(x / 5))
    res = _run(sc, NOMINAL, cutoff_mm=2.0, outputs=["cutting"])
    assert res.report["map_from"].startswith("smoothing B-spline")


def test_fixed_point_csv_roundtrip(tmp_path):
    v = np.array([0.0, -0.0, 1e-13, -1e-13, 123.456, -7.25, 1e-4 / 3, 9999.999999999999, -0.5])
    b = fixed_point_bytes(v, 12)
    text = b[b != 0].tobytes().decode()
    assert "." in text and "e" not in text
    xs = np.array([0.0, 0.1])
    Z = np.array([[1.5, np.nan], [-2e-6, 3.0]])
    write_grid_csv(tmp_path / "g.csv", xs, np.array([0.0, 0.1]), Z, "x [mm],y [mm],dz [mm]\n", ["sign"])
    assert (tmp_path / "g.csv").read_text(encoding="utf-8") == (
        "# sign\nx [mm],y [mm],dz [mm]\n0.0,0.0,1.5\n0.0,0.1,-0.000002\n0.1,0.1,3.0\n")
    w = np.random.default_rng(0).normal(0, 1e-3, 1000)
    rows = [bytes(r[r != 0]).decode() for r in fixed_point_bytes(w, 12)]
    assert np.max(np.abs(np.array([float(s) for s in rows]) - w)) <= 5e-13


def test_example_star_pattern_gets_a_correction_a_cam_can_take():
    """The example's CMM star (36 spokes, gaps of ~110 mm at the rim) after its recipe: the clear
    aperture is the recipe's `aperture` step (1290 mm, not the surface's 1300), the spline covers the
    rim between spokes, and the turning program is a polynomial with no coefficient a CAM must print
    to 1e-110 (even asphere at most to A20, else Forbes Q-con), within 1 nm RMS."""
    import yaml

    import pointspro.core as pp

    from .conftest import EXAMPLE

    recipe = yaml.safe_load((EXAMPLE / "recipe.yaml").read_text(encoding="utf-8"))
    recipe["steps"].append({"correction": {}})
    res = pp.run(recipe, EXAMPLE / "asphere_cmm.csv")
    rep = res.steps[-1].report
    assert rep["diameter_mm"] == 1290.0 and rep["coverage"] >= 0.99
    cs = rep["corrected_surface"]
    assert cs["fit_rms_nm"] <= 1.0
    spec = cs["surface"]
    if spec["type"] == "even_asphere":
        assert max(int(k) for k in spec.get("A", {4: 0})) <= 20
    assert rep["predicted_rms_um"] < 0.2 * rep["error_rms_um"]


def test_heights_of_a_curved_part_are_not_its_form_error():
    """A sphere's sag with 0.1 µm of error, no misalignment: the step took z as the error and wrote a
    624 µm "correction"; refused now. With a flat or no nominal, z is a form-error map (unchanged)."""
    g = np.arange(-20.0, 20.01, 1.0)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = np.hypot(x, y) <= 20.0
    x, y = x[keep], y[keep]
    sphere = EvenAsphere(1 / 500.0, 0.0, aperture=40.0)
    cloud = PointCloud.from_xyz(x, y, sphere.sag(x, y) + 1e-4 * np.cos(x / 7))
    with pytest.raises(StepError, match="heights z are the part's sag, not its form error"):
        _run(cloud, sphere, cutoff_mm=4.0)
    assert _run(cloud, sphere, channel="z", cutoff_mm=4.0).report["channel"] == "z"  # said explicitly
    assert _run(cloud, None, diameter=40, cutoff_mm=4.0).report["channel"] == "z"
    # an instrument's map of deviations (0.1 µm) under the curved nominal is a form-error map: zernike
    # and bspline_map map it, and correction now takes it too (it refused any curved nominal)
    dev = PointCloud.from_xyz(x, y, 1e-4 * np.cos(x / 7))
    rep = _run(dev, sphere, cutoff_mm=4.0).report
    assert rep["channel"] == "z" and rep["error_rms_um"] < 0.2


@pytest.mark.parametrize("params", [{"cutoff_mm": 1e6}, {"cutoff_mm": 2.0, "extend_mm": 1e5}])
def test_a_working_grid_beyond_its_limit_is_refused_before_it_is_allocated(params):
    """Node for node on a gridded input: cutoff_mm 1e6 asked numpy for 284 TiB (internal error)."""
    cloud = _map_cloud(lambda x, y: 1e-5 * np.cos(x / 5), half=10.0, h=1.0)
    with pytest.raises(StepError, match="working grid .* too large|more than 25,000,000 nodes"):
        _run(cloud, None, diameter=20, **params)


def test_scattered_points_report_what_the_map_does_not_resolve():
    """predicted_rms_um is the error left on the map's grid; the points also hold what the spline
    does not resolve (noise, detail finer than the knots): unresolved_rms_um. A cutoff below twice
    the knot spacing holds no data: a warning."""
    rng = np.random.default_rng(4)
    x, y = rng.uniform(-25, 25, (2, 3000))
    keep = np.hypot(x, y) <= 25
    x, y = x[keep], y[keep]
    noise = 2e-5
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(x), residual=1e-4 * (x / 25) ** 2 + rng.normal(0, noise, x.size))
    rep = _run(cloud, None, diameter=50).report
    assert rep["unresolved_rms_um"] == pytest.approx(noise * 1e3, rel=0.25)
    assert not any("knot spacing" in w for w in rep["warnings"])
    fine = _run(cloud, None, diameter=50, cutoff_mm=2.0, spacing=0.5).report
    assert any("below twice the knot spacing" in w for w in fine["warnings"])


def test_a_programmed_surface_bending_the_other_way_is_refused():
    """A programmed R −500 against a nominal R +500 (a sign slip) was accepted."""
    cloud = _map_cloud(lambda x, y: 1e-5 * np.cos(x / 5), half=20.0, h=1.0)
    nominal = EvenAsphere(1 / 500.0, 0.0, aperture=40.0)
    with pytest.raises(StepError, match="bends the other way"):
        _run(cloud, nominal, cutoff_mm=4.0, programmed_surface={"type": "even_asphere", "R": -500.0})
    ok = _run(cloud, nominal, cutoff_mm=4.0, programmed_surface={"type": "even_asphere", "R": 501.0})
    assert "cutting" in ok.report["outputs"]


def test_the_parts_tilt_changes_no_correction_inside_or_beyond_the_rim():
    """Tilt is set-up, not form: the same bump with and without 2e-4 rad of tilt gives the same dz over
    the whole written region. The plane was removed after the continuation past the rim, so the rim's
    tilted values minus the extrapolated plane made a ramp there (a review: dz −0.43…+0.53 µm beyond
    the rim of a 1 µm bump; a removal map ≥ 0.36 µm deep everywhere)."""
    from pointspro.core.correction.compute import compute_correction, error_map

    def bump(x, y):
        return 1e-3 * np.exp(-((x - 8) ** 2 + y ** 2) / (2 * 4.0 ** 2))

    res = {}
    for tilt in (0.0, 2e-4):
        cloud = _map_cloud(lambda x, y, t=tilt: bump(x, y) + t * (x + 0.5 * y), half=25.0, h=0.5, radius=25.0)
        em = error_map(cloud.x, cloud.y, cloud["residual"], center=(0.0, 0.0), radius=25.0, outer=28.0,
                       spacing=0.5)
        res[tilt] = compute_correction(em, center=(0.0, 0.0), radius=25.0, extend=3.0, cutoff=2.0).dz
    ok = np.isfinite(res[0.0])
    assert np.array_equal(ok, np.isfinite(res[2e-4]))
    assert np.max(np.abs(res[0.0][ok] - res[2e-4][ok])) < 1e-9  # mm: 1 pm
