"""Dynamics review 3 (a review of review 2's fixes): the pre-roll of LoopModel.apply on a noisy
encoder at rest, the file lines of a scan that carries its own index column, the dominant frequency
of a smooth motion with no line, and small simulated scans. Fixed seeds throughout."""
from __future__ import annotations

import numpy as np
import pytest

NOISE = 2e-6  # mm, the encoder's


def _loop(fs, fn, zeta):
    from scipy import signal

    from pointspro.core.dynamics.identify import LoopModel

    wn = 2 * np.pi * fn
    b, a, _ = signal.cont2discrete(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), 1.0 / fs, method="zoh")
    return LoopModel(np.ravel(b), np.asarray(a, float), fs)


def _loop_004(fs):
    from scipy import signal

    from pointspro.core.dynamics.identify import LoopModel
    from tests.paper004 import GM_DEN, GM_NUM

    b, a, _ = signal.cont2discrete((GM_NUM, GM_DEN), 1.0 / fs, method="zoh")
    return LoopModel(np.ravel(b), np.asarray(a, float), fs)


def _start_errors(m, make, seeds=100, n=1000, head=200):
    """Max |error| over the first ``head`` samples, per seed, of apply() and of the filter started at
    rest, against the truth: the axis's motion ``make(k)`` (samples k < 0 included) filtered from long
    before the scan, plus the encoder noise filtered from the scan's start (the loop is linear)."""
    from scipy.signal import lfilter

    pad = 20000
    clean = make(np.arange(-pad, n, dtype=np.float64))
    truth = lfilter(m.b, m.a, clean - clean[0])[pad:] + clean[0]
    new, old = [], []
    for seed in range(seeds):
        noise = np.random.default_rng(seed).normal(0, NOISE, n)
        xd = clean[pad:] + noise
        exact = truth + lfilter(m.b, m.a, noise - noise[0]) + noise[0]
        new.append(np.abs(m.apply(xd) - exact)[:head].max())
        old.append(np.abs(lfilter(m.b, m.a, xd - xd[0]) + xd[0] - exact)[:head].max())
    return np.asarray(new), np.asarray(old)


@pytest.mark.parametrize("loop", ["100hz_z0.5_10khz", "004_10khz", "40hz_z0.7_1khz", "10hz_z0.7_1khz"])
def test_a_noisy_encoder_at_rest_starts_without_a_pre_roll_transient(loop):
    """The pre-roll's velocity was a 3-point difference of the raw samples: 2 nm of encoder noise at
    rest became a velocity, and the correction started with a transient (100 Hz, ζ 0.5 at 10 kHz:
    median 57 nm, 95 % 151 nm against 1.3 and 3.6 nm from rest; 004's Gm at 10 kHz 17 nm against 2.2).
    The velocity is now fitted over the loop's settling window and used only where significant: no
    worse than the filter started at rest, over 100 seeds."""
    m = {"100hz_z0.5_10khz": lambda: _loop(10000.0, 100.0, 0.5), "004_10khz": lambda: _loop_004(10000.0),
         "40hz_z0.7_1khz": lambda: _loop(1000.0, 40.0, 0.7), "10hz_z0.7_1khz": lambda: _loop(1000.0, 10.0, 0.7)}[loop]()
    new, old = _start_errors(m, lambda k: np.full(k.size, 3.0))
    assert np.median(new) <= np.median(old) * 1.001, (np.median(new), np.median(old))
    assert np.percentile(new, 95) <= np.percentile(old, 95) * 1.05, (np.percentile(new, 95), np.percentile(old, 95))


def test_a_noisy_encoder_that_starts_moving_is_still_pre_rolled():
    """At 1.8 mm/s with 2 nm of encoder noise the start transient without a pre-roll is ~3 µm through a
    100 Hz, ζ 0.5 loop at 10 kHz; with it, nm."""
    m = _loop(10000.0, 100.0, 0.5)
    new, old = _start_errors(m, lambda k: 3.0 + 1.8e-4 * k, seeds=40)
    assert np.median(old) > 1e-3 and np.median(new) < 5e-6, (np.median(new), np.median(old))


def test_004_s_spiral_cropped_where_the_axis_moves_has_no_start_transient():
    """004's spiral cropped at its fastest Z (1.8 mm/s): 609 nm in the first 20 ms from rest, ~10 nm
    (the sensor's noise) with the pre-roll."""
    from pointspro.core.dynamics.identify import identify
    from tests import paper004 as p4

    m = identify(*p4.calibration())
    s = p4.spiral_scan(radius=3.0)
    v = np.abs(np.gradient(s["xd"]))
    k0 = int(np.argmax(v[1000:])) + 1000
    e = m.apply(s["xd"][k0:]) + s["xc"][k0:] - s["h"][k0:]
    e = e - np.median(e)
    assert np.abs(e[:20]).max() < 25e-6, np.abs(e[:20]).max()


def _start_error_vs_3_point(m, make, noise, seed=0, n=2000, head=500):
    """Max |error| over the first ``head`` samples of apply() and of the same pre-roll at the
    3-point difference's velocity (−3u₀ + 4u₁ − u₂)/2 (the version before the fitted one), against the
    truth: ``make(k)`` (k < 0 included) filtered from long before the scan, plus the encoder noise
    filtered from the scan's start."""
    from scipy.signal import lfilter

    pad = 20000
    clean = make(np.arange(-pad, n, dtype=np.float64))
    e = np.random.default_rng(seed).normal(0, noise, n)
    xd = clean[pad:] + e
    exact = lfilter(m.b, m.a, clean - clean[0])[pad:] + clean[0] + lfilter(m.b, m.a, e - e[0]) + e[0]
    u, L = xd - xd[0], m._preroll_samples()
    v3 = (-3.0 * u[0] + 4.0 * u[1] - u[2]) / 2.0
    ref = lfilter(m.b, m.a, np.r_[v3 * np.arange(-L, 0, dtype=np.float64), u])[L:] + xd[0]
    return np.abs(m.apply(xd) - exact)[:head].max(), np.abs(ref - exact)[:head].max()


@pytest.mark.parametrize("fn, f", [(10.0, 5.0), (3.0, 2.0)], ids=["10hz_loop_5hz_sine", "3hz_loop_2hz_sine"])
@pytest.mark.parametrize("noise", [0.0, NOISE], ids=["clean", "noisy"])
def test_a_slow_loop_s_start_on_a_motion_of_its_window_s_period_is_no_worse_than_the_3_point_difference(
        fn, f, noise):
    """A slow loop (ζ 0.7 at 1 kHz) and a 0.2 mm sine started at its fastest: over 4 of the loop's
    settling times (92, 304 samples) the sine is no cubic, whose slope read 23 %, 54 % high (start
    errors 40.5 µm, 130 µm against 9.1 µm, 29 µm at the 3-point difference's velocity; a review). The
    window is now shortened where its halvings disagree: as the 3-point difference, to 1 %."""
    m = _loop(1000.0, fn, 0.7)
    new, ref = _start_error_vs_3_point(m, lambda k: 0.2 * np.sin(2 * np.pi * f * k / 1000.0), noise)
    assert ref > 5e-3, ref  # µm-level: the motion's jerk, not extrapolated, whichever the velocity
    assert new <= ref * 1.01 + 5e-6, (new, ref)


@pytest.mark.parametrize("loop", ["100hz_z0.5_10khz", "10hz_z0.7_1khz"])
def test_a_noisy_encoder_that_starts_moving_keeps_the_settling_window(loop):
    """The adaptive window cuts a motion that is a cubic short by chance in under 1 start in 100: at
    1.8 mm/s with 2 nm of noise the velocity is the whole settling window's in 99 of 100 seeds here,
    and the start error as before (median 0.55 nm, 95 % 1.45 nm through the 100 Hz loop; 2.2, 4.6 nm
    through the 10 Hz one; the same 100 seeds)."""
    from pointspro.core.dynamics.identify import LoopModel

    fs, fn, zeta = {"100hz_z0.5_10khz": (10000.0, 100.0, 0.5), "10hz_z0.7_1khz": (1000.0, 10.0, 0.7)}[loop]
    m = _loop(fs, fn, zeta)
    w, n = m._velocity_window(), 2000
    same = []
    for seed in range(100):
        xd = 3.0 + 1.8 * np.arange(n) / fs + np.random.default_rng(seed).normal(0, NOISE, n)
        u = xd - xd[0]
        same.append(LoopModel._initial_velocity(u, w) == LoopModel._cubic_slope(u[:w])[0])
    assert np.mean(same) >= 0.97, np.mean(same)
    new, _ = _start_errors(m, lambda k: 3.0 + 1.8 * k / fs, seeds=100)
    assert np.median(new) < 2.5e-6 and np.percentile(new, 95) < 6e-6, (np.median(new), np.percentile(new, 95))


def _scan_file(path, index0=None, n=3000, dup=1001, header="x [mm],y [mm],z [mm],{}t [s],xd [mm],xc [mm]"):
    """A scan whose data row k is on line k + 2, with a duplicated time stamp on data row ``dup``
    (line dup + 2); an ``index`` column from ``index0`` when given."""
    t = np.arange(n) / 1000.0
    xd = 2 + 0.01 * np.sin(2 * np.pi * 2 * t)
    t[dup] = t[dup - 1]
    with open(path, "w") as f:
        f.write(header.format("index," if index0 is not None else "") + "\n")
        for i in range(n):
            idx = f"{i + index0}," if index0 is not None else ""
            f.write(f"{i * 0.01!r},0.0,{float(xd[i])!r},{idx}{float(t[i])!r},{float(xd[i])!r},0.0\n")
    return path


def _error_of(tmp_path, path):
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud
    from tests.test_dynamics_review2 import _dyn_run

    with pytest.raises(InputError) as e:
        _dyn_run(tmp_path, read_cloud(path))
    return str(e.value)


@pytest.mark.parametrize("index0", [None, 0, 1, 20000], ids=["no_index", "index_from_0", "index_from_1",
                                                             "cloud_csv_of_a_crop"])
def test_a_file_s_own_index_column_is_not_taken_for_its_rows(tmp_path, index0):
    """The dynamic step named lines as index + header line + 1: a file whose own index counts from 1
    read "line 1004", a cloud.csv of a crop (index: the original input's row, from 20000) "line
    21003" of a 3001-line file. The duplicate is on line 1003."""
    msg = _error_of(tmp_path, _scan_file(tmp_path / "scan.csv", index0))
    assert "line 1003: duplicated time stamp (the same as the line before)" in msg, msg


def test_a_cloud_csv_written_by_pointspro_names_its_own_lines(tmp_path):
    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    n = 3000
    t = np.arange(n) / 1000.0
    t[1001] = t[1000]
    xd = 2 + 0.01 * np.sin(2 * np.pi * 2 * t)
    cloud = PointCloud.from_xyz(np.linspace(0, 10, n), np.zeros(n), xd, t=t, xd=xd, xc=np.zeros(n),
                                index=np.arange(n) + 20000)
    cloud.meta["channel_units"] = {"t": "s"}
    write_csv(cloud, tmp_path / "cloud.csv")
    msg = _error_of(tmp_path, tmp_path / "cloud.csv")
    assert "line 1003: duplicated time stamp" in msg, msg


def test_the_text_reader_says_whether_the_index_is_the_file_s_own(tmp_path):
    """meta ``index_in_file``: the dynamic step maps through the index only where the reader made it.
    With the file's own index and a NaN row dropped, the lines are array positions (the mapping before
    the index was used): a line of this file, never the index's number."""
    import re

    from pointspro.core.io import read_cloud

    assert read_cloud(_scan_file(tmp_path / "plain.csv")).meta["index_in_file"] is False
    p = _scan_file(tmp_path / "own.csv", 20000)
    assert read_cloud(p).meta["index_in_file"] is True
    text = p.read_text().splitlines()
    text[502] = text[502].replace(",0.0\n", "").rsplit(",", 1)[0] + ",nan"  # line 503: xc NaN
    p.write_text("\n".join(text) + "\n")
    assert read_cloud(p).meta["invalid_dropped"] == 1
    msg = _error_of(tmp_path, p)
    line = int(re.search(r"line (\d+): duplicated", msg).group(1))
    assert line in (1002, 1003), msg


# -- the dominant frequency ---------------------------------------------------------------------------

def _sphere_spiral(noise, R=50.0, radius=12.7, fs=1000.0, tilt=0.0):
    """xd on 004's spiral (30 rpm, 0.1 mm/rev) over a sphere: smooth and monotone, no line (a tilt
    adds one at 1/rev, 0.5 Hz)."""
    t = np.arange(int(radius / 0.1 * 2.0 * fs)) / fs
    r = radius - 0.05 * t
    xd = 3.0 + r**2 / (R + np.sqrt(R**2 - r**2)) + tilt * r * np.cos(np.pi * t)
    return xd + np.random.default_rng(0).normal(0, noise, t.size)


_T2 = np.arange(20000) / 1000.0


@pytest.mark.parametrize("xd", [
    _sphere_spiral(NOISE), _sphere_spiral(0.0), _sphere_spiral(0.0, R=10.0, radius=9.5),
    0.5 * _T2**2 + np.random.default_rng(1).normal(0, NOISE, _T2.size),
    _T2**3 / 100 + np.random.default_rng(2).normal(0, NOISE, _T2.size),
    np.exp(_T2 / 5) + np.random.default_rng(3).normal(0, NOISE, _T2.size),
    np.sqrt(1 + _T2) + np.random.default_rng(4).normal(0, NOISE, _T2.size),
], ids=["sphere_spiral_noise", "sphere_spiral", "sphere_R10_spiral", "accelerating", "cubic", "exponential",
        "sqrt"])
def test_a_smooth_motion_with_no_line_has_no_dominant_frequency(xd):
    """After a linear detrend the power of a smooth non-linear motion stood at the first allowed bin,
    > 100× the median of its steep spectrum: the lag was quoted at exactly 3/T (0.0118 Hz on a
    sphere's spiral, 0.15 Hz on an accelerating axis)."""
    from pointspro.core.dynamics.vibration import dominant_frequency

    f, why = dominant_frequency(xd, 1000.0)
    assert f is None and "no dominant frequency" in why, (f, why)


@pytest.mark.parametrize("rpm", [0.14, 1.0, 5.0, 15.0])
@pytest.mark.parametrize("turns", [3.2, 3.5, 10.0])
def test_slow_spindles_are_still_resolved(rpm, turns):
    from pointspro.core.dynamics.vibration import dominant_frequency

    fs, f0 = 100.0, rpm / 60.0
    t = np.arange(int(turns / f0 * fs)) / fs
    xd = 5 + 0.01 * t + 2e-4 * np.sin(2 * np.pi * f0 * t + 0.3) + np.random.default_rng(1).normal(0, NOISE, t.size)
    f, why = dominant_frequency(xd, fs)
    assert f == pytest.approx(f0, rel=0.03) and why == ""


def test_a_tilted_part_s_line_on_a_sphere_s_spiral_is_found():
    """The cubic trend takes the sag off: a 0.1 µm/mm tilt's 1/rev line (0.5 Hz at 30 rpm)."""
    from pointspro.core.dynamics.vibration import dominant_frequency

    f, why = dominant_frequency(_sphere_spiral(NOISE, tilt=1e-4 / 12.7), 1000.0)
    assert f == pytest.approx(0.5, rel=0.01) and why == ""


def test_the_dynamic_step_quotes_no_lag_on_a_sphere_s_spiral(tmp_path):
    from pointspro.core import PointCloud
    from tests.test_dynamics_review2 import _dyn_run

    xd = _sphere_spiral(NOISE)[:30000]
    t = np.arange(xd.size) / 1000.0
    rep = _dyn_run(tmp_path, PointCloud.from_xyz(np.linspace(0, 10, t.size), np.zeros(t.size), xd, t=t, xd=xd,
                                                 xc=np.zeros(t.size))).report
    assert rep["phase_lag_model_deg"] is None and "no dominant frequency" in rep["phase_lag_model_note"]


# -- small simulated scans ----------------------------------------------------------------------------

SMALL = [({"type": "star", "radius": 10.0, "spacing": 1.0, "lines": 4}, 84),
         ({"type": "raster", "radius": 10.0, "spacing": 2.0, "lines": 11}, 85),
         ({"type": "spiral", "radius": 5.0, "pitch": 0.5, "rpm": 60, "fs": 9.0}, 90),
         ({"type": "raster", "radius": 1.0}, 36)]


def _yaml(scan: dict) -> str:
    body = ", ".join(f"{k}: {v}" for k, v in scan.items())
    return ("pointspro_model: 1\nsurface: {type: even_asphere, R: 150.0, k: -0.8, aperture: 40.0}\n"
            f"scan: {{{body}}}\nprobe: {{noise: 2.0e-6}}\nseed: 1\n")


@pytest.mark.parametrize("scan, n", SMALL, ids=["star_84", "raster_85", "spiral_90", "raster_36"])
def test_a_small_scan_is_simulated_with_a_warning_naming_explain(run_cli, tmp_path, scan, n):
    """Ordinary small CMM scans were refused ("fewer than the 100 a simulated measurement needs"):
    the 100 is explain's, for a measurement. Simulated, exit 0, with a warning saying so."""
    from pointspro.core.io import read_cloud
    from pointspro.core.simulate.scan import ScanSpec, scan_points

    assert scan_points(ScanSpec(**scan))["x"].size == n
    (tmp_path / "m.yaml").write_text(_yaml(scan), encoding="utf-8")
    code, out, err = run_cli("simulate", tmp_path / "m.yaml", "--out", tmp_path / "s.csv")
    assert code == 0, err
    assert read_cloud(tmp_path / "s.csv").n == n
    assert "warning" in err and f"has {n} point(s)" in err and "pointspro explain" in err and "100" in err, err


def test_a_dense_scan_warns_nothing(run_cli, tmp_path):
    (tmp_path / "m.yaml").write_text(_yaml({"type": "star", "radius": 10.0, "spacing": 0.5, "lines": 4}),
                                     encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "m.yaml", "--out", tmp_path / "s.csv")
    assert code == 0 and err == "", err


def test_explain_takes_a_coarse_model_scan_with_a_dense_measurement(run_cli, tmp_path):
    """explain's check_scan refused a model whose own scan is a 4-spoke star of 84 points although the
    measurement held 2000; explain evaluates the model at the measured points."""
    dense = {"type": "spiral", "radius": 10.0, "rpm": 60, "pitch": 0.5, "fs": 100.0}
    (tmp_path / "dense.yaml").write_text(_yaml(dense), encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "dense.yaml", "--out", tmp_path / "meas.csv")
    assert code == 0, err
    (tmp_path / "coarse.yaml").write_text(_yaml(SMALL[0][0]), encoding="utf-8")
    code, _, err = run_cli("explain", "--model", tmp_path / "coarse.yaml", "--measured", tmp_path / "meas.csv",
                           "--out", tmp_path / "o", "--bootstrap", "0")
    assert code == 0, err
    assert (tmp_path / "o" / "explain.json").exists()


def test_explain_still_refuses_a_small_measurement(run_cli, tmp_path):
    (tmp_path / "m.yaml").write_text(_yaml(SMALL[0][0]), encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "m.yaml", "--out", tmp_path / "meas.csv")
    assert code == 0, err
    code, _, err = run_cli("explain", "--model", tmp_path / "m.yaml", "--measured", tmp_path / "meas.csv",
                           "--out", tmp_path / "o", "--bootstrap", "0")
    assert code == 2 and "84 point(s)" in err and "needs 100 points" in err, err
