"""`explain`'s inputs (a review): a measurement beyond the model's aperture, a measurement without its
time or spindle angle, repeated time stamps, the updated model written to another folder, and a
simulated file at other positions than the measurement on a curved part. Fixed seeds throughout."""
from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.explain.workflow import against_simulation, explain, scan_speed
from pointspro.core.io import write_csv
from pointspro.core.simulate.model import ModelSpec, simulate

NOISE = 2e-6  # mm
ASPHERE = {"type": "even_asphere", "R": 200.0, "k": -0.5, "A": {4: 2e-8}, "aperture": 30.0}
STEEP = {"type": "even_asphere", "R": -80.0, "k": -1.0, "aperture": 40.0}
SPIRAL = {"type": "spiral", "radius": 15.0, "rpm": 60.0, "pitch": 0.5, "fs": 300.0}
BASE = [{"pose": {"alpha_deg": 0.001, "dz": 0.001}}]


def model(surface=ASPHERE, scan=SPIRAL, effects=BASE, seed=1, noise=NOISE):
    return ModelSpec.model_validate({"pointspro_model": 1, "surface": surface, "scan": scan,
                                     "probe": {"noise": noise}, "seed": seed, "effects": effects})


def write_meas(path, sim, z=None, **channels):
    write_csv(PointCloud.from_xyz(sim["x"], sim["y"], sim["z"] if z is None else z, **channels), path)
    return path


def test_a_measurement_beyond_the_model_s_aperture_is_refused(tmp_path, run_cli):
    """A measurement 25 mm in radius against a model of a Ø 30 mm part was explained (a review had
    z_scale ≈ −1 "found"); it is refused with the file, how far beyond and the aperture. With no
    aperture on the surface the model's scan is what it describes; a few points past the rim are
    kept, and said."""
    big = simulate(model({**ASPHERE, "aperture": 60.0}, {**SPIRAL, "radius": 25.0}))
    write_meas(tmp_path / "big.csv", big, t=big["t"], c=big["c"])
    (tmp_path / "m.yaml").write_text(model().to_yaml(), encoding="utf-8")
    code, _, err = run_cli("explain", "--model", tmp_path / "m.yaml", "--measured", tmp_path / "big.csv",
                           "--out", tmp_path / "o")
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "big.csv: " in err and "lie outside the model's aperture, up to 10 mm beyond it" in err, err
    assert "the surface's aperture Ø 30 mm" in err and not (tmp_path / "o").exists()
    no_aperture = {k: v for k, v in ASPHERE.items() if k != "aperture"}
    (tmp_path / "m2.yaml").write_text(model(no_aperture).to_yaml(), encoding="utf-8")
    code, _, err = run_cli("explain", "--model", tmp_path / "m2.yaml", "--measured", tmp_path / "big.csv",
                           "--out", tmp_path / "o")
    assert code == 2 and "the model's spiral scan of radius 15 mm (the surface states no aperture)" in err, err
    # a measurement of the aperture, decentred by 20 µm: 0.2 % of its points just past the rim
    own = simulate(model())
    x = own["x"] + 0.02
    out = np.hypot(x, own["y"]) > 15.0
    assert 0 < out.mean() < 0.01
    write_meas(tmp_path / "dec.csv", {**own, "x": x}, t=own["t"], c=own["c"])
    code, _, err = run_cli("explain", "--model", tmp_path / "m.yaml", "--measured", tmp_path / "dec.csv",
                           "--out", tmp_path / "o3", "--bootstrap", "0")
    assert code == 0, err
    assert f"dec.csv: warning: {int(out.sum())} of {x.size} measured points" in err and "kept" in err, err


@pytest.mark.parametrize("drop", ["t", "c", "tc"])
def test_a_missing_time_or_spindle_angle_is_said_not_borrowed_silently(tmp_path, run_cli, drop):
    """Without `t` or `c` the measurement's clock or angle came from the model's scan path, silently."""
    sim = simulate(model())
    ch = {k: sim[k] for k in ("t", "c") if k not in drop}
    write_meas(tmp_path / "meas.csv", sim, **ch)
    (tmp_path / "m.yaml").write_text(model().to_yaml(), encoding="utf-8")
    code, _, err = run_cli("explain", "--model", tmp_path / "m.yaml", "--measured", tmp_path / "meas.csv",
                           "--out", tmp_path / "o", "--bootstrap", "0")
    assert code == 0, err
    line = next((w for w in err.splitlines() if "meas.csv: warning: no " in w), None)
    assert line is not None, err
    assert ("time 't'" in line) == ("t" in drop) and ("spindle angle 'c'" in line) == ("c" in drop), line
    assert "the nearest point of the model's spiral scan path" in line
    rep = json.loads((tmp_path / "o" / "explain.json").read_text(encoding="utf-8"))
    assert any(w.startswith("no ") for w in rep["warnings"])
    assert "Warning: no " in (tmp_path / "o" / "explain.html").read_text(encoding="utf-8")


def test_repeated_time_stamps_raise_no_numpy_warnings_and_share_their_speed(tmp_path):
    """A repeated time stamp made np.gradient divide by zero in the scan-speed view: RuntimeWarnings on
    stderr. Points sharing a stamp share their group's speed, as they share zdot."""
    sim = simulate(model())
    t = sim["t"].copy()
    t[101] = t[100]  # one repeated row
    t[2000:4000] = np.round(t[2000:4000], 1)  # a clock written to 0.1 s: 30 points a stamp
    write_meas(tmp_path / "meas.csv", sim, t=t, c=sim["c"])
    (tmp_path / "m.yaml").write_text(model().to_yaml(), encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rep = explain(tmp_path / "meas.csv", tmp_path / "o", tmp_path / "m.yaml", bootstrap=0)
    assert rep["verdict"] == "nothing_missing", rep["found"]
    # a straight line at 2 mm/s sampled every 10 ms, its clock truncated to 0.1 s: 10 points a stamp
    tt = np.arange(1000) * 0.01
    v = scan_speed(2.0 * tt, np.zeros_like(tt), (np.arange(1000) // 10) * 0.1)
    assert np.all(np.isfinite(v)) and v == pytest.approx(2.0, rel=1e-9)


def test_the_updated_model_simulates_from_wherever_it_is_written(tmp_path, run_cli):
    """model.updated.yaml kept the original's relative mesh path: written to another folder (or saved
    from the window, a copy), `pointspro simulate` from it could not find the mesh."""
    from pointspro.core.io.mesh import write_mesh

    g = np.linspace(-12.0, 12.0, 49)
    X, Y = np.meshgrid(g, g)
    V = np.column_stack([X.ravel(), Y.ravel(), (X * X + Y * Y).ravel() / 400.0])
    i = np.arange(48)[:, None] * 49 + np.arange(48)[None, :]
    i = i.ravel()
    F = np.concatenate([np.column_stack([i, i + 1, i + 50]), np.column_stack([i, i + 50, i + 49])])
    models = tmp_path / "models"
    models.mkdir()
    write_mesh(models / "part.obj", V, F)
    m = model({"type": "mesh", "path": "part.obj"}, {**SPIRAL, "radius": 10.0, "pitch": 0.8},
              BASE + [{"z_scale": {"scale": 0.0}}])
    (models / "base.yaml").write_text(m.to_yaml(), encoding="utf-8")
    truth = m.model_copy(update={"effects": BASE + [{"z_scale": {"scale": 2e-3}}]})
    sim = simulate(truth, models)
    write_meas(tmp_path / "meas.csv", sim, t=sim["t"], c=sim["c"])
    out = tmp_path / "elsewhere" / "out"
    code, stdout, err = run_cli("explain", "--model", models / "base.yaml", "--measured", tmp_path / "meas.csv",
                                "--out", out, "--bootstrap", "0")
    assert code == 0 and "z_scale" in stdout, (stdout, err)
    third = tmp_path / "third"
    third.mkdir()
    shutil.copyfile(out / "model.updated.yaml", third / "copied.yaml")  # the window's "Save updated model"
    for upd in (out / "model.updated.yaml", third / "copied.yaml"):
        code, _, err = run_cli("simulate", upd, "--out", upd.parent / "resim.csv")
        assert code == 0, err
    assert str((models / "part.obj").resolve()) in (out / "model.updated.yaml").read_text(encoding="utf-8")


@pytest.mark.parametrize("surface, seed", [(ASPHERE, 70), (STEEP, 71)])
def test_a_simulation_at_other_positions_on_a_curved_part_finds_nothing_when_it_is_the_truth(
        tmp_path, surface, seed):
    """The null case of --simulated on a curved, tilted part: the simulation is the truth (noise-free,
    a spiral), the measurement is the truth at other positions (a raster) with 2 nm of noise. The
    nearest simulated point's height carried along its slope left the curvature's 0.5·κ·d² (36 nm
    RMS here on the asphere, 89 nm on the steep conic) and named effects; the interpolated heights
    are right to far below the noise, and nothing is named."""
    effects = BASE + [{"pose": {"beta_deg": 0.05}}]
    truth = model(surface, {**SPIRAL, "radius": 15.5, "pitch": 0.3}, effects, seed=seed, noise=0.0)
    s = simulate(truth)
    write_csv(PointCloud.from_xyz(s["x"], s["y"], s["z"], t=s["t"], c=s["c"]), tmp_path / "sim.csv")
    raster = {"type": "raster", "radius": 15.0, "spacing": 0.1, "lines": 41, "speed": 10.0}
    m = simulate(model(surface, raster, effects, seed=seed + 1))
    exact = simulate(truth, at=m, noise=False)["z"]
    write_meas(tmp_path / "meas.csv", m)
    _, z_sim, match = against_simulation(PointCloud.from_xyz(m["x"], m["y"], m["z"]), tmp_path / "sim.csv")
    assert match.startswith("by position")
    err = z_sim - exact
    assert np.sqrt(np.mean(err**2)) < 0.02 * NOISE and np.max(np.abs(err)) < 0.1 * NOISE
    rep = explain(tmp_path / "meas.csv", tmp_path / "o", simulated=tmp_path / "sim.csv", bootstrap=0)
    assert rep["found"] == [] and rep["verdict"] == "nothing_missing", [f["effect"] for f in rep["found"]]
    assert rep["gap_before"]["rms_um"] < 1.1 * NOISE * 1e3
    assert any("nearest simulated point's" in w for w in rep["warnings"])


def test_linear_interpolation_finds_every_triangle_scipy_finds():
    """A review: ~1.6 % of a spiral's offset points lay in a triangle that does not touch their nearest
    simulated point and fell back to that point's value. Every point inside the triangulation is now
    interpolated, equal to scipy's LinearNDInterpolator."""
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import cKDTree

    from pointspro.core.explain.workflow import linear_interpolation

    s = np.linspace(0, 1, 8000)
    pts = np.column_stack([25 * np.sqrt(s) * np.cos(400 * np.sqrt(s)), 25 * np.sqrt(s) * np.sin(400 * np.sqrt(s))])
    vals = np.sin(pts[:, 0] / 3) + np.cos(pts[:, 1] / 5)
    q = pts + np.random.default_rng(1).normal(0, 0.1, pts.shape)
    near = cKDTree(pts).query(q)[1]
    out = linear_interpolation(pts, vals, q, near)
    ref = LinearNDInterpolator(pts, vals)(q)
    assert np.array_equal(np.isnan(out), np.isnan(ref))
    ok = np.isfinite(ref)
    assert np.max(np.abs(out[ok] - ref[ok])) < 1e-12


def test_a_wide_bump_is_located_apart_from_the_ring_its_piston_leaves():
    """A review: a 100 nm bump of σ 4 mm at (0, 10) on a Ø40 part, its piston removed, came out as one
    region over the whole part centred at (0, 2.9) with a mean of 0.006 nm: cells were grouped by
    |mean|, so the bump and the negative ring around it merged. Raised and sunk cells are apart now."""
    from pointspro.core.explain.workflow import regions

    rng = np.random.default_rng(3)
    r, t = 20 * np.sqrt(rng.random(40_000)), rng.uniform(0, 2 * np.pi, 40_000)
    x, y = r * np.cos(t), r * np.sin(t)
    g = 1e-4 * np.exp(-((x - 0) ** 2 + (y - 10) ** 2) / (2 * 4.0**2)) + rng.normal(0, 2e-6, x.size)
    regs = regions(x, y, g - g.mean(), 2e-6)
    top = regs[0]
    assert top["mean_um"] > 0.02 and np.hypot(top["x"], top["y"] - 10) < 1.0 and top["radius"] < 10


def _disc(n=40_000, radius=20.0, seed=4):
    rng = np.random.default_rng(seed)
    r, t = radius * np.sqrt(rng.random(n)), rng.uniform(0, 2 * np.pi, n)
    return r * np.cos(t), r * np.sin(t), rng


def test_a_zone_is_located_as_a_ring_not_at_the_centre():
    """A 20 nm zone at r = 12 mm (σ 1 mm) was located "at (0.01, 0.09), radius 9.4 mm", where nothing
    is: a region that goes round its own centre is a ring with its inner and outer radius; a bump and
    an arc (a crescent, whose centre of mass lies off it too) stay patches."""
    from pointspro.core.explain.workflow import region_words, regions

    x, y, rng = _disc()
    noise = rng.normal(0, 2e-6, x.size)
    zone = 2e-5 * np.exp(-((np.hypot(x, y) - 12) ** 2) / (2 * 1.0**2)) + noise
    top = regions(x, y, zone - zone.mean(), 2e-6)[0]
    assert top["shape"] == "ring" and top["mean_um"] > 0.005
    assert 8.5 < top["inner_radius"] < 12 < top["outer_radius"] < 15.5 and np.hypot(top["x"], top["y"]) < 0.5
    assert region_words(top).startswith("ring r = ") and "about (" in region_words(top)
    bump = 4e-5 * np.exp(-((x - 8) ** 2 + (y + 5) ** 2) / (2 * 1.5**2)) + noise
    top = regions(x, y, bump - bump.mean(), 2e-6)[0]
    assert top["shape"] == "patch" and "inner_radius" not in top and np.hypot(top["x"] - 8, top["y"] + 5) < 0.5
    assert region_words(top).startswith("at (7.99, -5.02) mm, radius 4 mm, mean +")
    arc = np.where((np.arctan2(y, x) > 0) & (np.arctan2(y, x) < 2.0), zone - noise, 0.0) + noise
    top = regions(x, y, arc - arc.mean(), 2e-6)[0]
    assert top["shape"] == "patch" and top["mean_um"] > 0.005


@pytest.mark.parametrize("crop", ["radius", "time"])
def test_a_measurement_covering_less_than_the_model_s_scan_keeps_the_model_s_parameters(tmp_path, crop):
    """Straightness is normalised by the scan's rim radius and thermal drift by its duration: they were
    taken from the points evaluated, so a measurement covering 3/4 of the model's radius or half its
    time read the model's own straightness as a z_scale and its drift at half its size, and
    model.updated.yaml halved the drift (a review). Now the model's own scan normalises them: the
    model's own simulation, cropped, explains to nothing, and an effect missing from the model is
    found at its true size — by --model and by --simulated."""
    # s3 and drift on a raster: effects the scan tells apart (s2 ∝ r² ties with probe_radius on a
    # near-sphere; on a spiral, whose radius runs with time, drift ties with straightness and squareness
    # — the documented look-alikes)
    effects = BASE + [{"straightness": {"s3": 1.0e-5}}, {"thermal_drift": {"d1": 2.0e-5}}]
    scan = {"type": "raster", "radius": 14.0, "spacing": 0.1, "lines": 29, "speed": 10.0}
    truth = model(ASPHERE, scan, effects, seed=81)
    s = simulate(truth)
    keep = np.hypot(s["x"], s["y"]) < 10.5 if crop == "radius" else s["t"] < 0.5 * s["t"].max()
    cut = {k: np.asarray(v)[keep] for k, v in s.items()}
    write_meas(tmp_path / "meas.csv", cut, t=cut["t"], c=cut["c"])
    (tmp_path / "truth.yaml").write_text(truth.to_yaml(), encoding="utf-8")
    rep = explain(tmp_path / "meas.csv", tmp_path / "o", tmp_path / "truth.yaml", bootstrap=0)
    assert rep["verdict"] == "nothing_missing", [(f["effect"], f["params"]) for f in rep["found"]]
    missing = "straightness" if crop == "radius" else "thermal_drift"
    partial = model(ASPHERE, scan, [e for e in effects if missing not in e], seed=81)
    (tmp_path / "partial.yaml").write_text(partial.to_yaml(), encoding="utf-8")
    rep = explain(tmp_path / "meas.csv", tmp_path / "o2", tmp_path / "partial.yaml", bootstrap=0)
    # what the found effect does at the measured edge (r = 10.5 mm, or half the scan's time) in the
    # model's terms: the true size there — about half of it before (the points' own r.max or t span)
    edge = 10.5 / np.hypot(s["x"], s["y"]).max() if crop == "radius" else 0.5

    def at(params, u):
        if missing == "straightness":
            return sum(params.get(f"s{k}", 0.0) * u ** k for k in (2, 3, 4))
        return params.get("d1", 0.0) * u + params.get("d2", 0.0) * u ** 2

    def at_edge(params):  # its rise over the outer half of the measured range (piston-free)
        return at(params, edge) - at(params, edge / 2)

    true = at_edge({"s3": 1.0e-5} if missing == "straightness" else {"d1": 2.0e-5})
    found = {f["effect"]: f["params"] for f in rep["found"]}
    assert missing in found and at_edge(found[missing]) == pytest.approx(true, rel=0.05), found
    # the same through a simulated cloud of the partial model's whole scan (--simulated)
    p = simulate(partial, noise=False)
    write_csv(PointCloud.from_xyz(p["x"], p["y"], p["z"], t=p["t"], c=p["c"]), tmp_path / "sim.csv")
    rep = explain(tmp_path / "meas.csv", tmp_path / "o3", simulated=tmp_path / "sim.csv", bootstrap=0)
    found = {f["effect"]: f["params"] for f in rep["found"]}
    assert missing in found and at_edge(found[missing]) == pytest.approx(true, rel=0.05), found


def test_rows_dropped_on_reading_are_said(tmp_path):
    """NaN rows are dropped on reading, as in the batch — but explain.json's warnings said nothing of
    them (a review)."""
    sim = simulate(model())
    z = sim["z"].copy()
    z[[10, 500, 501]] = np.nan
    write_meas(tmp_path / "meas.csv", sim, z=z, t=sim["t"], c=sim["c"])
    (tmp_path / "m.yaml").write_text(model().to_yaml(), encoding="utf-8")
    rep = explain(tmp_path / "meas.csv", tmp_path / "o", tmp_path / "m.yaml", bootstrap=0)
    assert any("3 row(s) with a NaN or infinite x, y or z dropped on reading" in w for w in rep["warnings"]), \
        rep["warnings"]
    assert rep["verdict"] == "nothing_missing"


def test_a_measurement_on_another_clock_keeps_the_drift_it_shows(tmp_path):
    """A CMM log's clock time (t + 1000 s) lies outside the model's scan: counted from the model's
    start, τ ≈ 7 moved the drift's offset into d1 (−1.2e-3 for 1e-4 — a review); the measurement's own
    start is taken then, and said."""
    scan = {"type": "raster", "radius": 14.0, "spacing": 0.1, "lines": 29, "speed": 10.0}
    truth = model(ASPHERE, scan, BASE + [{"thermal_drift": {"d1": 1.0e-4, "d2": 1.0e-4}}], seed=83)
    partial = model(ASPHERE, scan, BASE, seed=83)
    (tmp_path / "partial.yaml").write_text(partial.to_yaml(), encoding="utf-8")
    s = simulate(truth)
    for shift in (0.0, 1000.0):
        write_meas(tmp_path / "meas.csv", s, t=s["t"] + shift, c=s["c"])
        rep = explain(tmp_path / "meas.csv", tmp_path / f"o{shift:g}", tmp_path / "partial.yaml", bootstrap=0)
        found = {f["effect"]: f["params"] for f in rep["found"]}
        assert found["thermal_drift"]["d1"] == pytest.approx(1.0e-4, rel=0.05), (shift, found)
        said = any("outside the model's scan" in w for w in rep["warnings"])
        assert said == (shift > 0), rep["warnings"]


def test_a_measurement_less_deleted_rows_is_matched_to_its_simulation_by_row(tmp_path):
    """A review of the window's Explain on the points kept: five rows deleted made the match "by
    position", with a false warning that the simulation was not made at the measured positions. The
    simulation's same rows (the measurement's `index`) are taken: by row, no warning."""
    from pointspro.core.io import read_cloud

    scan = {"type": "raster", "radius": 14.0, "spacing": 0.2, "lines": 15, "speed": 10.0}
    truth = model(ASPHERE, scan, BASE, seed=82)
    s = simulate(truth)
    write_meas(tmp_path / "meas.csv", s, t=s["t"], c=s["c"])
    p = simulate(truth, noise=False)
    write_csv(PointCloud.from_xyz(p["x"], p["y"], p["z"], t=p["t"], c=p["c"]), tmp_path / "sim.csv")
    meas = read_cloud(tmp_path / "meas.csv")
    kept = meas.select(np.arange(meas.n) % 97 != 5)  # rows deleted in the window
    rep = explain(tmp_path / "meas.csv", tmp_path / "o", simulated=tmp_path / "sim.csv", bootstrap=0,
                  measured_cloud=kept)
    assert rep["match"].startswith("by row") and not any("not made at the measured" in w for w in rep["warnings"])


def test_explain_html_gives_a_found_effects_values_to_their_uncertaintys_decimal_place():
    """A vibration's frequency read "23.3 Hz ± 5.9e-05 Hz" (its u is now propagated: 59 µHz): the
    value to the decimal place of u's two significant digits (GUM §7.2.6), u alike."""
    from pointspro.core.explain.workflow import params_for_people

    text = params_for_people({"effect": "vibration",
                              "params": {"frequency_hz": 23.300123, "amplitude": 8.01e-6, "phase_deg": 70.123},
                              "uncertainty": {"frequency_hz": 5.9e-5, "amplitude": 2e-7, "phase_deg": 0.49}})
    assert text["frequency_hz"] == "23.300123 Hz ± 0.000059 Hz"
    assert text["amplitude"] == "8.01 nm ± 0.20 nm"
    assert text["phase_deg"].startswith("70.12") and "± 0.49" in text["phase_deg"]


def test_a_z_scale_no_machine_has_is_said_to_be_a_unit_slip():
    """Heights in µm beside x, y in mm (no header): explain named z_scale 999 with a squareness of 148″
    and no word (a review). A found scale beyond 1 % says what it most likely is."""
    from pointspro.core.explain.workflow import unit_slip_warnings

    (w,) = unit_slip_warnings([{"effect": "z_scale", "params": {"scale": 999.0}}])
    assert "1000 × the model's" in w and "another unit" in w and "z [um]" in w
    assert unit_slip_warnings([{"effect": "z_scale", "params": {"scale": 2e-4}}]) == []
    assert unit_slip_warnings([{"effect": "squareness", "params": {"eb0c_arcsec": 3.0}}]) == []
