"""`explain` on varied cases it was not tuned to (issue 16, part 2): effects hidden one at a time at nm
amplitudes (2 nm probe noise; gaps of 3–5 nm RMS) on spirals inward and outward at other speeds, on
rasters, over a rotational asphere, an anamorphic asphere (different x and y curvature), a steep
convex conic and a Forbes Q-con; spindle error motions at other harmonics (ISO 230-7: every integer
harmonic); a null case; an out-of-library bump; two effects at once; a probe radius compared with a
simulated file; the noise σ under a strong vibration. Fixed seeds throughout.
"""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.explain.workflow import explain
from pointspro.core.io import write_csv
from pointspro.core.simulate.model import ModelSpec, simulate

NOISE = 2e-6  # mm
ASPHERE = {"type": "even_asphere", "R": 200.0, "k": -0.5, "A": {4: 2e-8}, "aperture": 50.0}
ANAMORPHIC = {"type": "xy_polynomial", "c": 1 / 250, "k": -0.5, "norm_radius": 20.0,
              "terms": {"x2y0": 0.15, "x0y2": -0.05, "x4y0": 0.002}}
STEEP = {"type": "even_asphere", "R": -80.0, "k": -1.0, "aperture": 40.0}
QCON = {"type": "qcon", "R": 150, "k": -1, "norm_radius": 16, "a": [1e-3, -2e-4]}
SPIRAL = {"type": "spiral", "radius": 15.0, "rpm": 60.0, "pitch": 0.5, "fs": 300.0}
SPIRAL_OUT = {"type": "spiral", "radius": 15.0, "rpm": 45.0, "pitch": 0.4, "fs": 250.0, "direction": "outward"}
RASTER = {"type": "raster", "radius": 15.0, "spacing": 0.1, "lines": 41, "speed": 10.0}
BASE = [{"pose": {"alpha_deg": 0.001, "dz": 0.001}}]


def model(surface, scan, effects, seed=1, noise=NOISE):
    return ModelSpec.model_validate({"pointspro_model": 1, "surface": surface, "scan": scan,
                                     "probe": {"noise": noise}, "seed": seed, "effects": effects})


def run(tmp_path, surface, scan, hidden, extra=None, seed=1, simulated=False, noise=NOISE):
    """Simulate the truth (the base model and the hidden effects, plus ``extra`` outside the library),
    explain it against the base model (or against a simulated file of it), return the report."""
    sim = simulate(model(surface, scan, BASE + hidden, seed, noise))
    z = sim["z"] + (extra(sim["x"], sim["y"], sim["t"]) if extra else 0.0)
    write_csv(PointCloud.from_xyz(sim["x"], sim["y"], z, t=sim["t"], c=sim["c"]), tmp_path / "meas.csv")
    base = model(surface, scan, BASE, seed + 100, noise)
    if simulated:
        s = simulate(base)
        write_csv(PointCloud.from_xyz(s["x"], s["y"], s["z"], t=s["t"], c=s["c"]), tmp_path / "sim.csv")
        return explain(tmp_path / "meas.csv", tmp_path / "out", simulated=tmp_path / "sim.csv", bootstrap=0)
    (tmp_path / "base.yaml").write_text(base.to_yaml(), encoding="utf-8")
    return explain(tmp_path / "meas.csv", tmp_path / "out", tmp_path / "base.yaml", bootstrap=0)


def harmonics_of(params: dict) -> list[int]:
    return sorted({int("".join(ch for ch in k.split("_")[0] if ch.isdigit())) for k in params})


def names(rep):
    return [f["effect"] for f in rep["found"]]


# (case id) → surface, scan, hidden effect (one), seed
ONE = {
    "axial_3_5": (ASPHERE, SPIRAL, {"spindle_axial": {"a3": 4e-6, "b5": 3e-6}}, 1),
    "axial_2_7_11_outward": (ANAMORPHIC, SPIRAL_OUT, {"spindle_axial": {"b2": 3e-6, "a7": -3e-6, "a11": 2e-6,
                                                                         "b11": 2e-6}}, 2),
    "axial_6_raster": (QCON, RASTER, {"spindle_axial": {"a6": 4e-6}}, 3),
    "axial_20_raster": (ASPHERE, RASTER, {"spindle_axial": {"b20": 4e-6}}, 4),
    "tilt_2_6": (ASPHERE, SPIRAL, {"spindle_tilt": {"a2_arcsec": 0.06, "b6_arcsec": -0.05}}, 5),
    "tilt_3_8_outward": (STEEP, SPIRAL_OUT, {"spindle_tilt": {"b3_arcsec": 0.07, "a8_arcsec": 0.05}}, 6),
    "tilt_9_raster": (QCON, RASTER, {"spindle_tilt": {"a9_arcsec": 0.08}}, 7),
    "vibration_43.7": (ASPHERE, SPIRAL, {"vibration": {"frequency_hz": 43.7, "amplitude": 4e-6, "phase_deg": 20.0}}, 8),
    "vibration_raster": (ANAMORPHIC, RASTER, {"vibration": {"frequency_hz": 7.3, "amplitude": 4e-6}}, 9),
    "pose": (STEEP, SPIRAL, {"pose": {"beta_deg": 2e-5, "dy": 5e-5}}, 10),
    "z_scale": (STEEP, SPIRAL, {"z_scale": {"scale": 1e-5}}, 11),
    "probe_radius": (ANAMORPHIC, SPIRAL, {"probe_radius": {"radius": 5e-3}}, 12),
    "squareness": (ANAMORPHIC, SPIRAL_OUT, {"squareness": {"eb0c_arcsec": 0.2}}, 13),
    "straightness": (ANAMORPHIC, SPIRAL, {"straightness": {"s2": 2e-5, "s3": -1.5e-5}}, 14),
    "thermal_drift_raster": (ANAMORPHIC, RASTER, {"thermal_drift": {"d1": 1.5e-5}}, 15),
    "dynamic_lag_raster": (STEEP, RASTER, {"dynamic_lag": {"tau_s": 5e-6}}, 16),
    "volumetric": (ANAMORPHIC, SPIRAL, {"volumetric": {"cxy": 1e-7, "cxz": -1e-7}}, 17),
}


@pytest.mark.parametrize("case", sorted(ONE))
def test_one_hidden_effect_at_nm_amplitude_is_named(tmp_path, case):
    surface, scan, hidden, seed = ONE[case]
    (name, params), = hidden.items()
    rep = run(tmp_path, surface, scan, [hidden], seed=seed)
    # a gap of a few nm, over the area since the gap's RMS is (docs/conventions.md, Summary figures): the
    # spirals crowd their centre, and straightness's gap reads 2.47 nm there, 2.77 nm over its points
    assert rep["gap_before"]["rms_um"] > 1.2 * NOISE * 1e3, rep["gap_before"]
    assert names(rep)[:1] == [name], (names(rep), rep["ambiguous_with"])
    assert rep["verdict"] in ("explained", "ambiguous")
    assert rep["gap_after"]["rms_um"] <= 1.1 * NOISE * 1e3, rep["gap_after"]
    if name.startswith("spindle"):
        # every harmonic hidden, and only those, under the one effect; no vibration for what is synchronous
        assert rep["found"][0]["harmonics"] == harmonics_of(params)
        assert harmonics_of(rep["found"][0]["params"]) == harmonics_of(params)
        assert names(rep) == [name]
        for k, v in params.items():
            assert rep["found"][0]["params"][k] == pytest.approx(v, abs=0.15 * max(map(abs, params.values())))
    if name == "vibration":
        assert rep["found"][0]["params"]["frequency_hz"] == pytest.approx(params["frequency_hz"], abs=0.02)


def test_axial_3_and_5_upr_is_a_spindle_error_not_a_vibration(tmp_path):
    """The issue's case: an axial error of 3 and 5 undulations per revolution, 3 nm noise, gap ~5 nm —
    spindle_axial with harmonics 3 and 5 and the gap down to the noise; on a constant-speed spiral a
    vibration at 3 and 5 × the spindle frequency would fit the same, which the report says."""
    rep = run(tmp_path, ASPHERE, {"type": "spiral", "radius": 20.0, "rpm": 60.0, "pitch": 0.4, "fs": 400.0},
              [{"spindle_axial": {"a3": 5e-6, "b3": 2e-6, "a5": -4e-6}}], seed=21, noise=3e-6)
    assert names(rep) == ["spindle_axial"] and rep["found"][0]["harmonics"] == [3, 5]
    assert rep["gap_after"]["rms_um"] <= 1.05 * 3e-3 and rep["unexplained"]["regions"] == []
    amb = [a for a in rep["ambiguous_with"] if set(a["effects"]) == {"spindle_axial", "vibration"}]
    assert amb and "spindle speed" in amb[0]["separate_by"]
    ev = rep["found"][0]["evidence"]["harmonics"]
    assert [h["harmonic"] for h in ev] == [3, 5] and all(h["p"] < 1e-10 for h in ev)


def test_a_vibration_beyond_the_spindle_band_is_a_vibration_and_its_synchrony_is_reported(tmp_path):
    """37 Hz on a 60 rpm spiral is 37 × the spindle frequency: named a vibration (above the spindle's
    32 harmonics), reported ambiguous with a 37-upr axial motion."""
    rep = run(tmp_path, ASPHERE, SPIRAL, [{"vibration": {"frequency_hz": 37.0, "amplitude": 4e-6}}], seed=22)
    assert names(rep) == ["vibration"]
    amb = rep["ambiguous_with"]
    assert any(set(a["effects"]) == {"vibration", "spindle_axial"} and "37 undulations" in a["why"] for a in amb)


@pytest.mark.parametrize("surface, scan", [(ANAMORPHIC, SPIRAL), (QCON, RASTER), (STEEP, SPIRAL_OUT)])
def test_null_case_finds_nothing(tmp_path, surface, scan):
    rep = run(tmp_path, surface, scan, [], seed=30)
    assert rep["verdict"] == "nothing_missing" and rep["found"] == [] and rep["ambiguous_with"] == []
    assert rep["noise_um"] == pytest.approx(NOISE * 1e3, rel=0.1)


@pytest.mark.parametrize("surface, scan, x0, y0", [(ANAMORPHIC, SPIRAL, -6.0, 4.0), (QCON, RASTER, 5.0, 7.0),
                                                    (ASPHERE, SPIRAL_OUT, 2.0, -1.0)])
def test_an_out_of_library_bump_is_unexplained_and_located(tmp_path, surface, scan, x0, y0):
    bump = lambda x, y, t: 1.5e-5 * np.exp(-((x - x0) ** 2 + (y - y0) ** 2) / (2 * 1.5**2))  # noqa: E731
    rep = run(tmp_path, surface, scan, [], extra=bump, seed=31)
    assert rep["verdict"] == "unexplained"
    reg = rep["unexplained"]["regions"][0]
    assert np.hypot(reg["x"] - x0, reg["y"] - y0) < 1.5 and reg["mean_um"] > 0


TWO = {
    "axial_and_squareness": (ANAMORPHIC, SPIRAL, [{"spindle_axial": {"a3": 4e-6, "b5": 3e-6}},
                                                  {"squareness": {"eb0c_arcsec": 0.2}}]),
    "probe_and_tilt_raster": (ANAMORPHIC, RASTER, [{"probe_radius": {"radius": 5e-3}},
                                                   {"spindle_tilt": {"a4_arcsec": 0.06}}]),
    "vibration_and_tilt": (ASPHERE, SPIRAL, [{"vibration": {"frequency_hz": 61.3, "amplitude": 4e-6}},
                                             {"spindle_tilt": {"b3_arcsec": 0.06}}]),
    "tilt_and_axial_outward": (QCON, SPIRAL_OUT, [{"spindle_tilt": {"a2_arcsec": 0.06}},
                                                  {"spindle_axial": {"b4": 3e-6, "a9": 2e-6}}]),
}


@pytest.mark.parametrize("case", sorted(TWO))
def test_two_hidden_effects_are_both_named(tmp_path, case):
    surface, scan, hidden = TWO[case]
    rep = run(tmp_path, surface, scan, hidden, seed=40)
    assert set(names(rep)) == {next(iter(h)) for h in hidden}, (names(rep), rep["ambiguous_with"])
    assert rep["gap_after"]["rms_um"] <= 1.1 * NOISE * 1e3
    for h in hidden:
        (name, params), = h.items()
        if name.startswith("spindle"):
            f = next(f for f in rep["found"] if f["effect"] == name)
            assert f["harmonics"] == harmonics_of(params)


@pytest.mark.parametrize("radius, seed", [(5e-3, 50), (0.5, 51)])
def test_probe_radius_on_an_anamorphic_asphere_against_a_simulated_file_is_not_volumetric(tmp_path, radius, seed):
    """An uncompensated tip radius over x and y curvatures that differ: its signature's leading term
    ρ(x²/Rx² + y²/Ry²)/2 lies in the volumetric field's span, so a 5-parameter catch-all can fit it
    nearly as well; the 1-parameter physical effect is named, the catch-all at most ambiguous."""
    rep = run(tmp_path, ANAMORPHIC, SPIRAL, [{"probe_radius": {"radius": radius}}], seed=seed, simulated=True)
    assert names(rep) == ["probe_radius"], (names(rep), rep["ambiguous_with"])
    assert rep["found"][0]["params"]["radius"] == pytest.approx(radius, rel=0.1)
    assert all("probe_radius" in a["effects"] for a in rep["ambiguous_with"])
    assert rep["gap_after"]["rms_um"] <= 1.1 * np.sqrt(2) * NOISE * 1e3  # both files carry noise
    assert "slopes from a degree-" in rep["match"]


@pytest.mark.parametrize("surface", [ANAMORPHIC, QCON, STEEP, ASPHERE])
def test_slopes_from_a_simulated_cloud_are_accurate_enough_for_the_probe_radius_signature(surface):
    """The probe_radius signature ρ(√(1 + |∇f|²) − 1) from the slopes of a noisy simulated spiral must
    match the exact one to a small part of the noise for ρ = 0.5 mm (a smoothing spline through the
    cloud was off by 1.4 nm RMS, 0.5 nm of noise on 9,000 points' fits)."""
    from pointspro.core.explain.slopes import cloud_slopes

    m = model(surface, SPIRAL, [], seed=60)
    s = simulate(m)
    fx, fy = m.build_surface().gradient(s["x"], s["y"])
    gx, gy, how = cloud_slopes(s["x"], s["y"], s["z"], np.argsort(s["t"]))
    exact = 0.5 * (np.sqrt(1 + fx**2 + fy**2) - 1)
    got = 0.5 * (np.sqrt(1 + gx**2 + gy**2) - 1)
    err = (got - exact) - np.mean(got - exact)  # a constant is the piston's
    assert np.sqrt(np.mean(err**2)) < 0.05 * NOISE, (how, np.sqrt(np.mean(err**2)))
    assert how["noise_um"] == pytest.approx(NOISE * 1e3, rel=0.15)


def test_noise_is_estimated_again_without_a_strong_vibration(tmp_path):
    """A 60 nm vibration at 140 Hz (fs 300 Hz) inflates the second differences the noise σ comes from;
    with σ from the gap a 12 nm bump hides below the region test. σ from the residual once the
    vibration is removed is the probe's 2 nm, and the bump is found and located."""
    bump = lambda x, y, t: 1.2e-5 * np.exp(-((x - 4.0) ** 2 + (y + 6.0) ** 2) / (2 * 1.5**2))  # noqa: E731
    rep = run(tmp_path, ASPHERE, SPIRAL, [{"vibration": {"frequency_hz": 140.3, "amplitude": 6e-5}}],
              extra=bump, seed=70)
    assert names(rep)[:1] == ["vibration"]
    assert rep["noise_um_of_gap"] > 3 * NOISE * 1e3
    assert rep["noise_um"] == pytest.approx(NOISE * 1e3, rel=0.1)
    assert rep["verdict"] == "unexplained"
    reg = rep["unexplained"]["regions"][0]
    assert np.hypot(reg["x"] - 4.0, reg["y"] + 6.0) < 1.5


def test_a_catch_all_is_never_named_before_a_physical_effect_that_fits_as_well():
    """The tie rule itself: volumetric (5 parameters, a catch-all) with the lowest ΔBIC and a
    1-parameter probe_radius whose fit is worse by less than the χ² threshold: probe_radius is named,
    volumetric reported with it; a physical effect that fits clearly better still wins."""
    from pointspro.core.explain import select as S

    sigma = 2e-6
    vol = S.Candidate("volumetric", 1.000e-6, 50.0, 1e-30, -300.0, 10, 5, True)
    probe = S.Candidate("probe_radius", 1.000e-6 + 10 * sigma**2, 240.0, 1e-30, -290.0, 10, 1, False)
    far = S.Candidate("z_scale", 1.000e-6 + 100 * sigma**2, 200.0, 1e-30, -200.0, 10, 1, False)
    named, tie = S._choose(None, [vol, probe, far], sigma)
    assert named is probe and tie == [vol]
    better = S.Candidate("probe_radius", 1.000e-6 - 5 * sigma**2, 260.0, 1e-30, -310.0, 10, 1, False)
    named, tie = S._choose(None, [better, vol], sigma)
    assert named is better and tie == [vol]
    # fewer parameters first among physical effects too: a spindle harmonic (2) before a vibration (3)
    harm = S.Candidate("spindle_axial[3]", 1e-6, 9.0, 1e-30, -99.0, 10, 2, False)
    vib = S.Candidate("vibration@0", 1e-6 - sigma**2, 9.0, 1e-30, -100.0, 10, 3, False)
    named, _ = S._choose(None, [vib, harm], sigma)
    assert named is harm


def test_a_z_offset_is_the_piston_s_never_half_of_it_reported_as_the_pose_s_dz(tmp_path):
    """The pose's dz column is a constant, the piston the design always holds: the two split an
    offset evenly (dz 2.5e-5 ± 1e-8 mm for a true 5e-5). A constant column is the piston's now — the
    pose is fitted without dz, its tilt still found."""
    rep = run(tmp_path, STEEP, SPIRAL, [{"pose": {"alpha_deg": 2e-5, "dz": 5e-5}}], seed=26)
    pose = next(f for f in rep["found"] if f["effect"] == "pose")
    assert "dz" not in pose["params"] and "dz" not in pose["uncertainty"]
    assert abs(pose["params"]["alpha_deg"] - 2e-5) < 4 * pose["uncertainty"]["alpha_deg"] + 1e-7


def test_a_vibration_s_amplitude_uncertainty_matches_its_scatter_over_seeds():
    """u(A) by first-order propagation of the cos and sin coefficients: over 30 seeds the reported u
    is the observed scatter to within its sampling error (hypot(σa, σb) was √2 too large: 1.58×)."""
    from pointspro.core.explain.select import select
    from pointspro.core.simulate.effects import ScanContext
    from pointspro.core.simulate.model import effects_dz
    from pointspro.core.simulate.scan import scan_points

    hidden = {"vibration": {"frequency_hz": 13.3, "amplitude": 4e-6, "phase_deg": 30.0}}
    m = model(ASPHERE, {"type": "spiral", "radius": 10.0, "rpm": 60.0, "pitch": 0.5, "fs": 60.0}, [hidden], 1)
    sp = scan_points(m.scan)
    ctx = ScanContext.from_surface(m.build_surface(), sp["x"], sp["y"], sp["t"], sp["c"])
    truth = effects_dz(ctx, [hidden])
    got, u = [], []
    for seed in range(30):
        res = select(ctx, truth + np.random.default_rng(seed).normal(0, NOISE, ctx.x.size), bootstrap=0)
        f = next(f for f in res["found"] if f["effect"] == "vibration")
        got.append(f["params"]["amplitude"])
        u.append(f["uncertainty"]["amplitude"])
    ratio = np.mean(u) / np.std(got, ddof=1)
    assert 0.75 < ratio < 1.35, ratio
    assert abs(np.mean(got) - 4e-6) < 3 * np.std(got) / np.sqrt(30)


@pytest.mark.parametrize("seed", [41, 42])
def test_spindle_harmonics_in_phase_are_all_found(tmp_path, seed):
    """ISO 230-7's multi-lobe case: axial harmonics 2…8 in phase add up in one sector, where each alone
    gains most — each was judged "local" and the search stopped: "unexplained", nothing named
    (an independent review). Judged with the other entering harmonics of its effect, all are found."""
    hidden = {"spindle_axial": {f"a{k}": 3e-6 for k in range(2, 9)}}
    rep = run(tmp_path, ASPHERE, SPIRAL, [hidden], seed=seed)
    assert names(rep) == ["spindle_axial"]
    assert harmonics_of(rep["found"][0]["params"]) == list(range(2, 9))
    assert rep["gap_after"]["rms_um"] < 1.1 * NOISE * 1e3


@pytest.mark.parametrize("d2", [6e-6, 2e-5])
def test_a_quadratic_drift_on_an_inward_spiral_is_found(tmp_path, d2):
    """τ² drift is largest at the end of the scan, the centre of an inward spiral: its gain comes from
    there by its shape (gain share ≈ the share of its own energy), not because a defect is local; it
    was refused as local at any amplitude."""
    rep = run(tmp_path, ASPHERE, SPIRAL, [{"thermal_drift": {"d2": d2}}], seed=43)
    assert "thermal_drift" in names(rep) and rep["verdict"] in ("explained", "ambiguous")
    assert rep["gap_after"]["rms_um"] < 1.1 * NOISE * 1e3


@pytest.mark.parametrize("seed", [44, 45])
def test_a_catch_all_is_judged_again_against_every_physical_effect(tmp_path, seed):
    """Squareness and a tip radius hidden together on an anamorphic part, raster: at the first stage
    the 5-parameter volumetric field took part of the squareness cone and won, the tip radius was
    never in that stage's tie, and the report said "volumetric, squareness" (a review). With the
    other effects in the fit a catch-all is weighed against every physical candidate again."""
    surface = {"type": "xy_polynomial", "c": 0.0005, "k": 0.0, "norm_radius": 20.0,
               "terms": {"x2y0": 0.004, "x0y2": -0.0025}}
    scan = {"type": "raster", "radius": 20.0, "spacing": 0.25, "lines": 121, "speed": 20.0}
    rep = run(tmp_path, surface, scan, [{"squareness": {"eb0c_arcsec": 0.05}}, {"probe_radius": {"radius": 0.3}}],
              seed=seed)
    assert "probe_radius" in names(rep) and "volumetric" not in names(rep)
    assert set(names(rep)) <= {"probe_radius", "squareness"}
    assert rep["gap_after"]["rms_um"] < 1.1 * NOISE * 1e3


def test_an_effect_that_cannot_be_estimated_beside_the_others_never_enters(tmp_path):
    """A 4 nm step in time (out of the library): straightness s2 = 0.32 mm and a tip radius of −36 mm
    entered together, each cancelling the other (VIF 1e11), and went into model.updated.yaml. Whatever
    is named now has an estimable value. (The verdict of this out-of-library step is "unexplained" or
    "ambiguous": effects that each fit a little of it leave 1.07 σ, below the 1.25 σ structure test.)"""
    from pointspro.core.explain.select import VIF_LIMIT

    step = lambda x, y, t: 4e-6 * (t > 0.5 * (t.min() + t.max()))  # noqa: E731
    rep = run(tmp_path, ASPHERE, SPIRAL, [], extra=step, seed=46)
    assert rep["verdict"] != "explained"
    assert all(f["evidence"]["vif_max"] < VIF_LIMIT for f in rep["found"])
    for f in rep["found"]:
        if f["effect"] == "probe_radius":
            assert abs(f["params"]["radius"]) < 1.0  # mm: no absurd tip radius


def test_two_vibration_lines_are_both_named(tmp_path):
    """A machine has more than one resonance: 170.3 Hz at 30 nm and 61.7 Hz at 6 nm were reported as
    one line, the second left as 2.6 σ of "noise" with nothing said (a review). Each line is an
    entry of its own, with its frequency and amplitude, and both go into model.updated.yaml."""
    hidden = [{"vibration": {"frequency_hz": 97.3, "amplitude": 3e-5}},  # below this scan's Nyquist (150 Hz)
              {"vibration": {"frequency_hz": 41.7, "amplitude": 6e-6}}]
    rep = run(tmp_path, ASPHERE, SPIRAL, hidden, seed=47)
    lines = sorted((f["params"]["frequency_hz"], f["params"]["amplitude"]) for f in rep["found"]
                   if f["effect"] == "vibration")
    assert len(lines) == 2 and names(rep).count("vibration") == 2
    assert lines[0][0] == pytest.approx(41.7, abs=0.05) and lines[1][0] == pytest.approx(97.3, abs=0.05)
    assert lines[0][1] == pytest.approx(6e-6, rel=0.1) and lines[1][1] == pytest.approx(3e-5, rel=0.05)
    assert rep["gap_after"]["rms_um"] < 1.1 * NOISE * 1e3
    updated = (tmp_path / "out" / "model.updated.yaml").read_text(encoding="utf-8")
    assert updated.count("vibration:") == 2


def test_a_vibration_is_named_with_its_frequency_on_the_command_line():
    from pointspro.core.explain.workflow import found_name

    assert found_name({"effect": "vibration", "params": {"frequency_hz": 61.7, "amplitude": 6e-6}}) \
        == "vibration 61.7 Hz"
    assert found_name({"effect": "spindle_axial", "params": {"a3": 1e-6}}) == "spindle_axial"
