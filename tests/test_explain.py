"""The discrepancy workflow: each library effect hidden in a "measurement" is named and removes the
gap to the noise; nothing missing; a bump no effect explains; two effects at once; the spiral's
time-versus-radius ambiguity; the simulate/explain commands."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml

from pointspro.core import PointCloud
from pointspro.core.explain.workflow import explain
from pointspro.core.io import write_csv
from pointspro.core.simulate.model import ModelSpec, simulate

NOISE = 2e-6  # mm: 2 nm
SURFACE = {"type": "even_asphere", "R": 200.0, "k": -0.5, "A": {4: 2e-8}, "aperture": 50.0}
SPIRAL = {"type": "spiral", "radius": 20.0, "rpm": 60.0, "pitch": 0.4, "fs": 400.0}
RASTER = {"type": "raster", "radius": 20.0, "spacing": 0.05, "lines": 25, "speed": 10.0}
BASE_EFFECTS = [{"pose": {"alpha_deg": 0.001, "dz": 0.001}}]

# effect → (hidden parameters with the papers' magnitudes, scan)
HIDDEN = {
    "pose": ({"beta_deg": 0.002, "dy": 0.002}, SPIRAL),
    "z_scale": ({"scale": 3e-4}, SPIRAL),
    "probe_radius": ({"radius": 0.5}, SPIRAL),
    "squareness": ({"eb0c_arcsec": 0.5}, SPIRAL),
    "spindle_tilt": ({"a2_arcsec": 0.3, "b3_arcsec": -0.1}, SPIRAL),
    "spindle_axial": ({"a1": 1e-5, "b2": -6e-6}, SPIRAL),
    "straightness": ({"s2": 1e-4, "s4": -8e-5}, SPIRAL),
    "thermal_drift": ({"d1": 5e-5}, RASTER),
    "dynamic_lag": ({"tau_s": 0.002}, RASTER),
    "vibration": ({"frequency_hz": 37.0, "amplitude": 1e-5, "phase_deg": 30.0}, SPIRAL),
    "volumetric": ({"cxy": 1e-6, "cxz": -2e-6}, SPIRAL),
}


def model(effects, scan=SPIRAL, seed=1):
    return ModelSpec.model_validate({"pointspro_model": 1, "surface": SURFACE, "scan": scan,
                                     "probe": {"noise": NOISE}, "seed": seed, "effects": effects})


def write_model(path, m):
    path.write_text(m.to_yaml(), encoding="utf-8")
    return path


def measure(tmp_path, truth, extra=None):
    sim = simulate(truth)
    z = sim["z"] + (extra(sim) if extra else 0.0)
    write_csv(PointCloud.from_xyz(sim["x"], sim["y"], z, t=sim["t"], c=sim["c"]), tmp_path / "meas.csv")
    return tmp_path / "meas.csv"


def run(tmp_path, truth, base, extra=None, bootstrap=2):
    meas = measure(tmp_path, truth, extra)
    mp = write_model(tmp_path / "base.yaml", base)
    return explain(meas, tmp_path / "out", mp, bootstrap=bootstrap)


@pytest.mark.parametrize("name", sorted(HIDDEN))
def test_each_hidden_effect_is_named_first_and_closes_the_gap(tmp_path, name):
    params, scan = HIDDEN[name]
    truth = model(BASE_EFFECTS + [{name: params}], scan)
    rep = run(tmp_path, truth, model(BASE_EFFECTS, scan))
    assert rep["found"], rep
    assert rep["found"][0]["effect"] == name, [f["effect"] for f in rep["found"]]
    assert rep["gap_before"]["rms_um"] > 3 * NOISE * 1e3
    assert rep["gap_after"]["rms_um"] <= 1.5 * NOISE * 1e3, rep["gap_after"]
    assert rep["verdict"] in ("explained", "ambiguous")
    ev = rep["found"][0]["evidence"]
    assert ev["p"] < 1e-6 and ev["delta_bic"] < -10 and ev["vif_max"] >= 1.0
    fitted = rep["found"][0]["params"]
    for k, v in params.items():
        if name == "pose" or k == "phase_deg":
            continue  # pose: its own columns are nearly collinear on an asphere; checked by the gap
        assert fitted[k] == pytest.approx(v, rel=0.05, abs=0.05 * max(abs(x) for x in params.values())), k
    upd = yaml.safe_load((tmp_path / "out" / "model.updated.yaml").read_text(encoding="utf-8"))
    assert name in {next(iter(e)) for e in upd["effects"]}
    html = (tmp_path / "out" / "explain.html").read_text(encoding="utf-8")
    assert html.count("data:image/png;base64,") == 2 and name in html
    # lengths in the unit their size asks for: the gap in nm, a length parameter with its unit
    assert re.search(r"gap [0-9.]+ (nm|µm) RMS before, [0-9.]+ (nm|µm) after", html)
    found = html.split("<h2>Found")[1].split("<h2>")[0]
    assert re.search(r"gap after</th><td>RMS [0-9.]+ (nm|µm), PV", found)
    from pointspro.core.simulate.effects import LIBRARY

    if "mm" in getattr(LIBRARY[name], "units", ()) or getattr(LIBRARY[name], "unit", "") == "mm":
        assert re.search(r"<td>-?[0-9.]+ (nm|µm)", found), found  # a length parameter in nm or µm


def test_nothing_missing(tmp_path):
    m = model(BASE_EFFECTS)
    rep = run(tmp_path, m, m)
    assert rep["verdict"] == "nothing_missing" and rep["found"] == []
    assert rep["gap_before"]["rms_um"] < 1.2 * NOISE * 1e3
    assert rep["checks"]["chi2_p"] > 1e-3


def test_a_local_bump_is_unexplained_and_located(tmp_path):
    m = model(BASE_EFFECTS)
    bump = lambda s: 4e-5 * np.exp(-((s["x"] - 8) ** 2 + (s["y"] + 5) ** 2) / (2 * 1.5**2))  # noqa: E731
    rep = run(tmp_path, m, m, extra=bump)
    assert rep["verdict"] == "unexplained"
    reg = rep["unexplained"]["regions"][0]
    assert np.hypot(reg["x"] - 8, reg["y"] + 5) < 2.0 and 1.0 < reg["radius"] < 6.0
    assert reg["mean_um"] > 0 and reg["shape"] == "patch"


def test_the_command_says_where_the_unexplained_structure_is(tmp_path, run_cli):
    """`pointspro explain` printed the verdict and the gap only: where the unexplained structure lies
    (a zone at r = 12 mm: a ring, with its radii) was in explain.json alone."""
    m = model(BASE_EFFECTS)
    measure(tmp_path, m, lambda s: 2e-5 * np.exp(-((np.hypot(s["x"], s["y"]) - 12) ** 2) / 2.0))
    write_model(tmp_path / "base.yaml", m)
    code, out, _ = run_cli("explain", "--model", tmp_path / "base.yaml", "--measured", tmp_path / "meas.csv",
                           "--out", tmp_path / "o", "--bootstrap", "0")
    assert code == 0 and "verdict unexplained" in out
    ring = re.search(r"unexplained: ring r = ([\d.]+)–([\d.]+) mm about \(", out)
    assert ring and float(ring[1]) < 12 < float(ring[2]), out
    page = (tmp_path / "o" / "explain.html").read_text(encoding="utf-8")  # the window shows this page
    assert f"<li>ring r = {ring[1]}–{ring[2]} mm about (" in page


def test_correlated_noise_names_nothing_and_says_why_it_reads_as_structure(tmp_path):
    """A gap of AR(1) noise (ρ = 0.6, the probe's white noise set to zero): no effect is named (two
    vibration lines and a spindle harmonic were, by the white-noise tests), and the report says the
    residual is correlated and that its σ and regions assume white noise — not just "unexplained"."""
    from scipy.signal import lfilter

    m = model(BASE_EFFECTS).model_copy(update={"probe": model(BASE_EFFECTS).probe.model_copy(
        update={"noise": 0.0})})

    def ar1(sim):
        order = np.argsort(sim["t"], kind="stable")
        e = lfilter([1.0], [1.0, -0.6], np.random.default_rng(5).normal(0, NOISE * 0.8, order.size))
        out = np.empty(order.size)
        out[order] = e
        return out

    rep = run(tmp_path, m, m, extra=ar1)
    assert rep["found"] == [] and rep["verdict"] == "unexplained"
    assert rep["checks"]["residual_lag1_autocorrelation"] > 0.5
    assert "correlated along the scan" in rep["unexplained"]["note"]
    assert rep["checks"]["dropped_under_correlated_noise"]
    html = (tmp_path / "out" / "explain.html").read_text(encoding="utf-8")
    assert "correlated along the scan" in html


def test_two_hidden_effects_are_both_found(tmp_path):
    hidden = [{"spindle_tilt": {"a2_arcsec": 0.3}},
              {"vibration": {"frequency_hz": 61.0, "amplitude": 8e-6}}]
    rep = run(tmp_path, model(BASE_EFFECTS + hidden), model(BASE_EFFECTS))
    assert {f["effect"] for f in rep["found"][:2]} == {"spindle_tilt", "vibration"}
    assert rep["gap_after"]["rms_um"] <= 1.5 * NOISE * 1e3
    vib = next(f for f in rep["found"] if f["effect"] == "vibration")
    assert vib["params"]["frequency_hz"] == pytest.approx(61.0, abs=0.01)


def test_time_versus_radius_on_a_spiral_is_ambiguous(tmp_path):
    """On a spiral r falls linearly with t: a drift linear in time and an X–C cone look alike."""
    rep = run(tmp_path, model(BASE_EFFECTS + [{"thermal_drift": {"d1": 5e-5}}]), model(BASE_EFFECTS))
    assert rep["verdict"] == "ambiguous"
    pair = {frozenset(a["effects"]) for a in rep["ambiguous_with"]}
    assert frozenset({"thermal_drift", "squareness"}) in pair
    a = next(a for a in rep["ambiguous_with"] if set(a["effects"]) == {"thermal_drift", "squareness"})
    assert "outward" in a["separate_by"] or "raster" in a["separate_by"]
    assert rep["gap_after"]["rms_um"] <= 1.5 * NOISE * 1e3


def test_scan_paths():
    from pointspro.core.simulate.scan import ScanSpec, scan_points

    sp = scan_points(ScanSpec(type="spiral", radius=10, rpm=60, pitch=0.5, fs=100))
    assert sp["x"].size == 2000 and np.hypot(sp["x"], sp["y"]).max() <= 10
    assert np.allclose(np.diff(sp["t"]), 0.01)
    ra = scan_points(ScanSpec(type="raster", radius=10, spacing=0.5, lines=11, speed=5))
    assert np.all(np.diff(ra["t"]) >= 0) and np.hypot(ra["x"], ra["y"]).max() <= 10 + 1e-9
    fi = scan_points(ScanSpec(type="fiducials", radius=50, centers=[(20, 0), (-20, 10)], patch=6, points=20))
    assert fi["x"].size == 40 and set(fi["fiducial"]) == {1, 2}
    assert np.abs(fi["x"][fi["fiducial"] == 1] - 20).max() <= 3 + 1e-9
    with pytest.raises(ValueError, match="needs `centers`"):
        scan_points(ScanSpec(type="fiducials", radius=5))


def test_commands_and_simulated_file(tmp_path, run_cli):
    truth = model(BASE_EFFECTS + [{"spindle_axial": {"a1": 1e-5, "b2": -6e-6}}])
    write_model(tmp_path / "truth.yaml", truth)
    write_model(tmp_path / "base.yaml", model(BASE_EFFECTS, seed=2))  # its own noise
    code, out, err = run_cli("simulate", tmp_path / "truth.yaml", "--out", tmp_path / "meas.csv")
    assert code == 0, err
    code, out, err = run_cli("simulate", tmp_path / "base.yaml", "--out", tmp_path / "sim.csv")
    assert code == 0, err
    code, out, err = run_cli("explain", "--simulated", tmp_path / "sim.csv", "--measured", tmp_path / "meas.csv",
                             "--out", tmp_path / "o", "--bootstrap", "2")
    assert code == 0, err
    rep = json.loads((tmp_path / "o" / "explain.json").read_text(encoding="utf-8"))
    assert rep["found"][0]["effect"] == "spindle_axial" and rep["match"].startswith("by row")
    assert rep["found"][0]["evidence"]["stability"] == 1.0
    code, out, err = run_cli("explain", "--model", tmp_path / "base.yaml", "--measured", tmp_path / "meas.csv",
                             "--out", tmp_path / "o2")
    assert code == 0 and "spindle_axial" in out
    # bad input: unknown effect, unknown parameter, no source
    (tmp_path / "bad.yaml").write_text("pointspro_model: 1\nsurface: {type: even_asphere, R: 100}\n"
                                       "scan: {type: spiral, radius: 5}\neffects:\n  - wobble: {a: 1}\n", encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "bad.yaml", "--out", tmp_path / "x.csv")
    assert code == 2 and "unknown effect 'wobble'" in err and "Traceback" not in err
    (tmp_path / "bad2.yaml").write_text("pointspro_model: 1\nsurface: {type: even_asphere, R: 100}\n"
                                        "scan: {type: spiral, radius: 5}\neffects:\n  - pose: {gamma: 1}\n", encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "bad2.yaml", "--out", tmp_path / "x.csv")
    assert code == 2 and "unknown parameter(s) ['gamma']" in err
    code, _, err = run_cli("explain", "--measured", tmp_path / "meas.csv", "--out", tmp_path / "o3")
    assert code == 2 and "--model" in err
    # outputs never replace what is not theirs; too few points; simulate's --out checked
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "keep.txt").write_text("precious", encoding="utf-8")
    for out, want in ((tmp_path / "meas.csv", "holds the input"), (notes, "not an explain output folder"),
                      (tmp_path, "holds the input")):
        code, _, err = run_cli("explain", "--model", tmp_path / "base.yaml", "--measured", tmp_path / "meas.csv",
                               "--out", out)
        assert code == 2 and want in err, err
    assert (notes / "keep.txt").read_text(encoding="utf-8") == "precious" and (tmp_path / "meas.csv").is_file()
    code, _, err = run_cli("explain", "--model", tmp_path / "base.yaml", "--measured", tmp_path / "meas.csv",
                           "--out", tmp_path / "o2")  # an earlier explain output is replaced
    assert code == 0, err
    (tmp_path / "few.csv").write_text("x,y,z\n1,2,3\n4,5,6\n7,8,10\n", encoding="utf-8")
    code, _, err = run_cli("explain", "--model", tmp_path / "base.yaml", "--measured", tmp_path / "few.csv",
                           "--out", tmp_path / "o4")
    assert code == 2 and "3 point(s); explain compares" in err and not (tmp_path / "o4").exists()
    for out, want in ((tmp_path / "nodir" / "s.csv", "does not exist"), (notes, "is a folder"),
                      (tmp_path / "base.yaml", "is the model file itself"),
                      (tmp_path / "base.yaml" / "s.csv", "base.yaml is a file, not a folder")):
        code, _, err = run_cli("simulate", tmp_path / "base.yaml", "--out", out)
        assert code == 2 and want in err and "internal error" not in err, err


def test_zdot_is_taken_in_time_order_whatever_the_rows_order_and_with_repeated_time_stamps():
    """In row order, a shuffled or x-sorted file lost the dynamic lag (a 'vibration at 0.335 Hz'
    named instead); a repeated time stamp made the rate NaN."""
    from pointspro.core.simulate.effects import ScanContext

    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 10.0, 2001)
    f = 0.3 * np.sin(0.7 * t) + 0.01 * t**2
    ones = np.ones_like(t)
    ref = ScanContext(ones, ones, f, ones, ones, t, ones).zdot
    assert ref == pytest.approx(np.gradient(f, t), abs=0)  # time order: as before, bit for bit
    p = rng.permutation(t.size)
    shuffled = ScanContext(ones, ones, f[p], ones, ones, t[p], ones).zdot
    assert np.array_equal(shuffled, ref[p])
    tr = np.round(t, 1)  # 10 points a time stamp
    dup = ScanContext(ones, ones, f, ones, ones, tr, ones).zdot
    assert np.all(np.isfinite(dup))
    inner = slice(100, -100)  # one-sided differences at the ends
    assert dup[inner] == pytest.approx((0.3 * 0.7 * np.cos(0.7 * t) + 0.02 * t)[inner], abs=0.02)


def test_explain_reads_t_and_c_in_the_units_their_header_states(tmp_path):
    """`t [ms]` and `c [rad]` were used as s and degrees (a 23.3 Hz vibration read 0.0233 Hz); they
    are converted, an unknown unit refused naming the column; simulate writes `t [s]`, `c [deg]`."""
    from pointspro.core.errors import InputError
    from pointspro.core.explain.workflow import clock_of
    from pointspro.core.io import read_cloud

    t = np.linspace(0.0, 2.0, 50)
    c = np.linspace(0.0, 350.0, 50)
    for head, tv, cv in (("t [ms],c [rad]", t * 1000, np.radians(c)), ("t,c", t, c), ("t [s],c [deg]", t, c),
                         ("t [min],c [gon]", t / 60, c / 0.9)):
        p = tmp_path / "m.csv"
        p.write_text(f"x,y,z,{head}\n" + "\n".join(f"{i},{i},0,{a!r},{b!r}" for i, (a, b) in
                                                     enumerate(zip(tv.tolist(), cv.tolist()))), encoding="utf-8")
        ts, cs = clock_of(read_cloud(p), p)
        assert ts == pytest.approx(t, rel=1e-12, abs=1e-12) and cs == pytest.approx(c, rel=1e-12, abs=1e-9), head
    p.write_text("x,y,z,t [fortnight],c\n0,0,0,1,2\n1,1,0,2,3\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"column 't \[fortnight\]'"):
        clock_of(read_cloud(p), p)


@pytest.mark.parametrize("truth_effects, want", [
    # an independent review's cases (R 100 mm sphere, 20 mm raster / spiral, 2 nm noise): a choice made
    # early — a catch-all's place re-judged to a dynamic_lag of ΔBIC +8.7; a 0.9 nm vibration at 3 ×
    # the spindle frequency — stayed named first though the effects found after it made it redundant
    ([{"spindle_tilt": {"a2_arcsec": 0.2}}, {"thermal_drift": {"d1": 2e-5}}],
     {"spindle_tilt", "thermal_drift"}),
    ([{"spindle_axial": {"a3": 1e-5}}, {"spindle_tilt": {"b3_arcsec": 0.15}}],
     {"spindle_axial", "spindle_tilt"}),
])
def test_an_effect_made_redundant_by_later_ones_is_dropped(tmp_path, truth_effects, want):
    sphere = {"type": "even_asphere", "R": 100.0, "k": 0.0, "aperture": 50.0}
    raster = {"type": "raster", "radius": 20.0, "spacing": 0.2, "lines": 60, "speed": 10.0}
    scan = raster if "thermal_drift" in want else {"type": "spiral", "radius": 20.0, "rpm": 60.0,
                                                    "pitch": 0.2, "fs": 1000.0}
    base = [{"pose": {"alpha_deg": 0.0005, "dx": 0.0005, "dz": 0.001}}]

    def spec(effects, seed):
        return ModelSpec.model_validate({"pointspro_model": 1, "surface": sphere, "scan": scan,
                                         "probe": {"noise": NOISE}, "seed": seed, "effects": effects})

    rep = run(tmp_path, spec(base + truth_effects, 72), spec(base, 7), bootstrap=0)
    assert {f["effect"] for f in rep["found"]} == want, [f["effect"] for f in rep["found"]]
    assert rep["gap_after"]["rms_um"] <= 1.2 * NOISE * 1e3


def test_effects_named_beside_unexplained_structure_are_said_to_need_a_check(tmp_path):
    """A hidden vibration and a local bump: the verdict is "unexplained", the vibration is named and goes
    into model.updated.yaml — a warning says the effects beside structure left may be fitting part of it (a
    review saw a 4 mm ripple taken up by three vibrations and spindle-tilt harmonics, unremarked);
    the bump alone names nothing and needs no such warning."""
    bump = lambda s: 4e-5 * np.exp(-((s["x"] - 8) ** 2 + (s["y"] + 5) ** 2) / (2 * 1.5**2))  # noqa: E731
    truth = model(BASE_EFFECTS + [{"vibration": HIDDEN["vibration"][0]}])
    rep = run(tmp_path, truth, model(BASE_EFFECTS), extra=bump)
    assert rep["verdict"] == "unexplained" and rep["found"], rep["found"]
    assert any("may be fitting part of it" in w and "vibration" in w for w in rep["warnings"])
    (tmp_path / "b").mkdir()
    m = model(BASE_EFFECTS)
    rep = run(tmp_path / "b", m, m, extra=bump)
    assert rep["verdict"] == "unexplained" and not any("may be fitting" in w for w in rep["warnings"])
