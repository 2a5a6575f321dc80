"""Dynamics review 2: the vibration's phase uncertainty in explain (its frequency is estimated), a
simulated scan with no samples, the dynamic step's vibration list, line numbers after NaN rows, the
model's phase lag on slow and constant-feed scans, and a scan that starts while the axis moves.
Fixed seeds throughout; the coverage of an uncertainty is checked as a rate over seeds.
"""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core.simulate.model import ModelSpec

NOISE = 2e-6  # mm
ASPHERE = {"type": "even_asphere", "R": 200.0, "k": -0.5, "A": {4: 2e-8}, "aperture": 50.0}


def _model(scan, effects, seed=1):
    return ModelSpec.model_validate({"pointspro_model": 1, "surface": ASPHERE, "scan": scan,
                                     "probe": {"noise": NOISE}, "seed": seed, "effects": effects})


@pytest.mark.parametrize("scan", [
    {"type": "spiral", "radius": 10.0, "rpm": 60.0, "pitch": 0.5, "fs": 60.0},
    {"type": "raster", "radius": 8.0, "spacing": 0.2, "lines": 9, "speed": 8.0},
], ids=["spiral", "raster"])
def test_vibration_phase_and_frequency_uncertainties_cover_their_scatter(scan):
    """The phase is quoted at t = 0, the record's edge, and the frequency is estimated from the same
    record: an error δf moves it by 2π·δf·T/2. u(φ) with f taken as known was half the scatter (a
    review: 60 % of 40 seeds within ±2u). Over 40 seeds, ≈ 95 % lie within ±2u (≥ 34 of 40: the
    binomial's 1 % tail at 95 %), and the mean u(φ), u(f) match the scatter."""
    from pointspro.core.explain.select import select
    from pointspro.core.simulate.effects import ScanContext
    from pointspro.core.simulate.model import effects_dz
    from pointspro.core.simulate.scan import scan_points

    truth = {"frequency_hz": 13.3, "amplitude": 4e-6, "phase_deg": 30.0}
    m = _model(scan, [{"vibration": truth}])
    sp = scan_points(m.scan)
    ctx = ScanContext.from_surface(m.build_surface(), sp["x"], sp["y"], sp["t"], sp["c"])
    dz = effects_dz(ctx, [{"vibration": truth}])
    dph, uph, fr, uf = [], [], [], []
    for seed in range(40):
        res = select(ctx, dz + np.random.default_rng(seed).normal(0, NOISE, ctx.x.size), bootstrap=0)
        f = next(f for f in res["found"] if f["effect"] == "vibration")
        dph.append((f["params"]["phase_deg"] - truth["phase_deg"] + 180) % 360 - 180)
        uph.append(f["uncertainty"]["phase_deg"])
        fr.append(f["params"]["frequency_hz"])
        uf.append(f["uncertainty"].get("frequency_hz", np.nan))
    dph, uph, fr, uf = map(np.asarray, (dph, uph, fr, uf))
    assert np.sum(np.abs(dph) < 2 * uph) >= 34, (np.mean(np.abs(dph) < 2 * uph), np.std(dph), uph.mean())
    assert 0.75 < uph.mean() / np.sqrt(np.mean(dph**2)) < 1.35
    assert np.sum(np.abs(fr - truth["frequency_hz"]) < 2 * uf) >= 34
    assert 0.75 < uf.mean() / np.sqrt(np.mean((fr - truth["frequency_hz"]) ** 2)) < 1.35


@pytest.mark.parametrize("scan, keys", [
    ("{type: spiral, radius: 10.0, rpm: 60, pitch: 0.5, fs: 0.001}", ("scan.fs", "fs: 1000", "0 sample")),
    ("{type: spiral, radius: 0.05, rpm: 60, pitch: 0.5, fs: 5}", ("scan.radius", "scan.pitch", "0 sample")),
    ("{type: raster, radius: 0.4, lines: 2}", ("scan.spacing", "scan.lines", "2 point")),
], ids=["fs_as_interval", "tiny_spiral", "tiny_raster"])
def test_simulate_refuses_a_scan_with_too_few_samples(run_cli, tmp_path, scan, keys):
    """`fs: 0.001` (a sampling interval for the rate) gave a spiral of 0 samples: a header-only CSV,
    exit 0. Refused with exit 2, the file, the keys and the likely unit slip named; nothing written.
    Fewer than 3 points make no scan; a small scan (a 36-point raster) is simulated with a warning
    (tests/test_dynamics_review3.py)."""
    from pointspro.core.simulate.scan import MIN_SAMPLES

    assert MIN_SAMPLES == 3
    (tmp_path / "m.yaml").write_text("pointspro_model: 1\nsurface: {type: even_asphere, R: 150.0, k: -0.8, "
                                     f"aperture: 40.0}}\nscan: {scan}\n", encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "m.yaml", "--out", tmp_path / "s.csv")
    assert code == 2 and "m.yaml" in err and "internal error" not in err
    assert all(k in err for k in keys), err
    assert not (tmp_path / "s.csv").exists()


def _dyn_run(tmp_path, cloud, **kw):
    from pointspro.core.dynamics.identify import write_example_calibration
    from pointspro.core.step import Context
    from pointspro.plugins.dynamic import DynamicStep

    write_example_calibration(tmp_path)
    return DynamicStep().run(cloud, DynamicStep.Params(calibration="calibration.csv", **kw), Context(base_dir=tmp_path))


def _moving_cloud(n=3000, fs=1000.0):
    from pointspro.core import PointCloud

    t = np.arange(n) / fs
    xd = 2 + 0.01 * np.sin(2 * np.pi * 2 * t)
    return PointCloud.from_xyz(np.linspace(0, 10, n), np.zeros(n), xd, t=t, xd=xd, xc=np.zeros(n))


@pytest.mark.parametrize("bad", [[0.0], [-5.0], [50.0, -1.0]])
def test_dynamic_vibrations_must_be_positive(bad):
    """[0] was an internal ZeroDivisionError ("please report"), [-5] advised a spatial period of
    −667 µm: refused with the parameter's message."""
    from pydantic import ValidationError

    from pointspro.plugins.dynamic import DynamicStep

    with pytest.raises(ValidationError, match="each vibration frequency must be > 0 Hz"):
        DynamicStep.Params(calibration="calibration.csv", vibrations=bad)


def test_dynamic_vibration_at_the_sampling_rate_reads_as_an_offset(tmp_path):
    """1000 Hz sampled at 1 kHz aliases to 0 Hz: "a false spatial period of inf µm" before."""
    rep = _dyn_run(tmp_path, _moving_cloud(), vibrations=[1000.0, 680.0]).report
    assert "inf" not in rep["advice"][0] and "constant offset or a slow drift" in rep["advice"][0]
    assert "appears at 320 Hz" in rep["advice"][1]


def _scan_csv(path, n=3000, fs=1000.0, edit=None):
    """A scan file (header on line 1, sample k on line k + 2): x, y, z, t, xd, xc; ``edit`` changes the
    columns first."""
    t = np.arange(n) / fs
    xd = 2 + 0.01 * np.sin(2 * np.pi * 2 * t)
    cols = {"x": np.linspace(0, 10, n), "y": np.zeros(n), "z": xd.copy(), "t": t, "xd": xd, "xc": np.zeros(n)}
    if edit:
        edit(cols)
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    return path


def _line_of_error(tmp_path, edit):
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud

    cloud = read_cloud(_scan_csv(tmp_path / "scan.csv", edit=edit))
    with pytest.raises(InputError) as e:
        _dyn_run(tmp_path, cloud)
    return str(e.value)


def test_time_stamp_errors_name_the_file_line_after_a_dropped_nan_row(tmp_path):
    """A NaN z on line 102 (dropped on reading) and a duplicated stamp on line 1003: named on line 1002
    (the array position + 2) before."""
    def edit(c):
        c["z"][100] = np.nan       # line 102
        c["t"][1001] = c["t"][1000]  # line 1003
    msg = _line_of_error(tmp_path, edit)
    assert "line 1003: duplicated time stamp" in msg, msg


def test_a_gap_left_by_a_dropped_nan_row_is_said(tmp_path):
    """A NaN on line 502 read as "line 502: the sampling interval changes": it is line 503 whose
    interval is 2 ms, because line 502 was dropped on reading."""
    def edit(c):
        c["xd"][500] = np.nan  # line 502
    msg = _line_of_error(tmp_path, edit)
    assert "line 503: the sampling interval changes" in msg, msg
    assert "line 502 was dropped on reading for a NaN or infinite value" in msg, msg


def test_a_gap_in_the_time_stamps_alone_is_not_blamed_on_dropped_rows(tmp_path):
    def edit(c):
        c["t"][1500:] += 0.01  # line 1502
    msg = _line_of_error(tmp_path, edit)
    assert "line 1502: the sampling interval changes" in msg and "dropped" not in msg, msg


def _cloud_of(t, xd):
    from pointspro.core import PointCloud

    return PointCloud.from_xyz(np.linspace(0, 10, t.size), np.zeros(t.size), xd, t=t, xd=xd, xc=np.zeros(t.size))


def test_the_model_lag_is_quoted_at_a_slow_scan_s_own_frequency(tmp_path):
    """Main content at 0.1 Hz (6 rpm), a weak 3 Hz beside: Welch's 8192-sample segments at 1 kHz cut
    below ~0.25 Hz and the lag was quoted at 3.05 Hz."""
    t = np.arange(40000) / 1000.0
    xd = 2 + 0.05 * np.sin(2 * np.pi * 0.1 * t) + 0.0005 * np.sin(2 * np.pi * 3 * t)
    rep = _dyn_run(tmp_path, _cloud_of(t, xd)).report
    assert rep["phase_lag_model_deg"]["frequency_hz"] == pytest.approx(0.1, abs=0.005)


@pytest.mark.parametrize("kind", ["constant", "ramp_with_noise"])
def test_no_model_lag_is_quoted_on_a_constant_feed(tmp_path, kind):
    """The encoder at a constant feed has no dominant frequency: "3.33 Hz, 0.60°" was quoted from the
    spectrum's rounding noise. None, and the report says why."""
    t = np.arange(3000) / 1000.0
    xd = (np.full(t.size, 2.0) if kind == "constant"
          else 2 + 0.5 * t + np.random.default_rng(3).normal(0, 1e-6, t.size))
    rep = _dyn_run(tmp_path, _cloud_of(t, xd)).report
    assert rep["phase_lag_model_deg"] is None
    assert "no dominant frequency" in rep["phase_lag_model_note"]


@pytest.mark.parametrize("rpm", [0.14, 15.0])
def test_the_dominant_frequency_resolves_004_s_spindle_speeds(rpm):
    """004 Table 1: 0.14–15 rpm. Three turns at 100 Hz, a 0.2 µm form at the spindle and noise."""
    from pointspro.core.dynamics.vibration import dominant_frequency

    fs, f0 = 100.0, rpm / 60.0
    t = np.arange(int(3.5 / f0 * fs)) / fs
    xd = 5 + 0.01 * t + 2e-4 * np.sin(2 * np.pi * f0 * t + 0.3) + np.random.default_rng(1).normal(0, 2e-6, t.size)
    f, why = dominant_frequency(xd, fs)
    assert f == pytest.approx(f0, rel=0.03) and why == ""


def _loop_300hz(fs=1000.0, fn=300.0, zeta=0.2):
    from scipy import signal

    from pointspro.core.dynamics.identify import LoopModel

    wn = 2 * np.pi * fn
    b, a, _ = signal.cont2discrete(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), 1.0 / fs, method="zoh")
    return LoopModel(np.ravel(b), np.asarray(a, float), fs)


def test_a_scan_that_starts_while_the_axis_moves_carries_no_start_transient():
    """LoopModel.apply started the filter at rest: a scan cropped where the axis moves at 2.5 mm/s
    began with the loop's start transient (hundreds of nm; 609 nm on 004's spiral). Started in the
    steady state of the initial motion, the cropped scan's correction is the whole scan's."""
    m = _loop_300hz()
    t = np.arange(2000) / m.fs
    xd = 3.0 + 0.2 * (1 - np.cos(2 * np.pi * 2.0 * t))  # from rest, 2.5 mm/s at t = 0.125 s
    whole = m.apply(xd)
    for k0, tol in ((125, 1e-6), (625, 1e-6), (1125, 1e-6), (300, 1e-5)):
        # 1.8 µm at full speed before, now < 1 nm; where the axis also accelerates (300: 25 mm/s²) a
        # pre-roll at constant velocity leaves 5 nm (1.06 µm before): a start at rest must stay at rest
        err = m.apply(xd[k0:]) - whole[k0:]
        assert np.abs(err).max() < tol, (k0, np.abs(err).max())


def test_a_scan_that_starts_at_rest_is_corrected_as_before():
    from scipy.signal import lfilter

    m = _loop_300hz()
    t = np.arange(2000) / m.fs
    for xd in (3.0 + 0.2 * (1 - np.cos(2 * np.pi * 2.0 * t)), np.r_[np.full(100, 3.0), 3.0 + 0.5 * t[:1900]]):
        at_rest = lfilter(m.b, m.a, xd - xd[0]) + xd[0]
        assert np.abs(m.apply(xd) - at_rest).max() < 1e-9  # 1 pm
