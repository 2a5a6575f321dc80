"""Dynamic error calibration (paper 004): identification from steps, correction of a spiral scan,
vibration analysis, bad time series."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from pointspro.core import PointCloud
from pointspro.core.dynamics.identify import LoopModel, identify
from pointspro.core.dynamics.vibration import aliased_frequency, phase_lag_hilbert_deg
from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context
from pointspro.plugins.dynamic import DynamicStep
from pointspro.plugins.dynamic_id import DynamicIdStep

from . import paper004 as p4


@pytest.fixture(scope="module")
def model():
    t, xd, ref = p4.calibration()
    return identify(t, xd, ref)


@pytest.fixture(scope="module")
def scan():
    return p4.spiral_scan()


def test_identification_recovers_the_loop(model):
    # the steps, smoothed by a 40 Hz servo, excite the loop up to ~50 Hz: compare there
    f = np.array([1.0, 5.0, 15.0, 50.0])
    _, h = signal.freqs(p4.GM_NUM, p4.GM_DEN, 2 * np.pi * f)
    assert model.stable and model.steps == 20
    assert model.dc_gain == pytest.approx(1.26e12 / 1.27e12, abs=2e-5)
    # phase lag: the paper reads ~2° at 15 Hz; eq 12 gives 1.84°
    assert np.allclose(model.phase_lag_deg(f[:3]), -np.degrees(np.angle(h[:3])), atol=0.05)
    assert model.phase_lag_deg(f[3:]) == pytest.approx(-np.degrees(np.angle(h[3:])), abs=0.5)
    # against the exact sampled equivalent of the simulated loop (lsim holds the input linear between
    # samples, i.e. a first-order hold): right to 3e-5 up to 15 Hz, 3e-4 at 50 Hz
    bd, ad, _ = signal.cont2discrete((p4.GM_NUM, p4.GM_DEN), 1 / p4.FS, method="foh")
    _, hd = signal.freqz(np.ravel(bd), ad, worN=2 * np.pi * f / p4.FS)
    assert np.allclose(model.response(f), hd, atol=3e-4)
    assert np.allclose(model.response(f[:3]), hd[:3], atol=3e-5)
    assert model.fit_rms < 3e-6  # the reference's 2 nm noise
    assert min(model.bic, key=model.bic.get) == model.order


def test_spiral_scan_corrected_to_paper_level(model, scan):
    """004: 2.3 µm RMS / 6 µm PV → 20 nm RMS / 0.5 µm PV. Here 2.1 µm / 9 µm before."""
    before = scan["z"] - scan["h"]
    assert 1.5e-3 < np.std(before) < 3e-3 and np.ptp(before) > 5e-3
    z = model.apply(scan["xd"]) + scan["xc"]
    after = z - scan["h"]
    assert np.sqrt(np.mean((after - after.mean()) ** 2)) <= 20e-6
    assert np.ptp(after) <= 0.5e-3
    assert abs(after.mean()) < 20e-6


def test_dynamic_step_from_calibration_file(tmp_path, scan):
    t, xd, ref = p4.calibration()
    np.savetxt(tmp_path / "cal.csv", np.column_stack([t, xd, ref]), delimiter=",", header="t,xd,ref",
               comments="", fmt="%.10g")
    cloud = PointCloud.from_xyz(scan["x"], scan["y"], scan["z"], t=scan["t"], c=scan["c"],
                                xd=scan["xd"], xc=scan["xc"])
    res = DynamicStep().run(cloud, DynamicStep.Params(calibration="cal.csv", vibrations=[680.0, 15.0]),
                            Context(base_dir=tmp_path))
    err = res.cloud.z - scan["h"]
    assert np.std(err) < 20e-6 and np.ptp(err) < 0.5e-3
    assert np.allclose(res.cloud["z_raw"], scan["z"])
    rep = res.report
    assert rep["dynamic_error_rms_um"] == pytest.approx(np.std(scan["z"] - res.cloud.z) * 1e3)
    assert rep["vibrations"][0]["aliased_hz"] == pytest.approx(320.0)
    assert rep["vibrations"][0]["above_nyquist"] and not rep["vibrations"][1]["above_nyquist"]
    assert "sample at ≥ 1360 Hz" in rep["advice"][0]
    assert 0 < rep["phase_lag_scan_deg"] < 0.5  # 0.5–1.5 Hz content: hundredths of a degree
    # the saved model replays identically
    (tmp_path / "m.json").write_text(res.artifacts["dynamic_model.json"], encoding="utf-8")
    res2 = DynamicStep().run(cloud, DynamicStep.Params(model="m.json"), Context(base_dir=tmp_path))
    assert np.array_equal(res2.cloud.z, res.cloud.z)
    # dynamic_id gives the same model and a figure
    rid = DynamicIdStep().run(cloud, DynamicIdStep.Params(calibration="cal.csv"), Context(base_dir=tmp_path))
    assert rid.report["order"] == rep["model"]["order"] and "dynamic_fit.png" in rid.artifacts
    rid.artifacts["dynamic_fit.png"](tmp_path / "fit.png")
    assert (tmp_path / "fit.png").read_bytes()[:4] == b"\x89PNG"


def test_aliasing_and_hilbert_phase_lag(model):
    assert aliased_frequency(680.0, 1000.0) == pytest.approx(320.0)
    assert aliased_frequency(1680.0, 1000.0) == pytest.approx(320.0)
    assert aliased_frequency(400.0, 1000.0) == pytest.approx(400.0)
    assert aliased_frequency(500.0, 1000.0) == pytest.approx(500.0)
    t = np.arange(20000) / 1000.0
    u = np.sin(2 * np.pi * 15.0 * t)
    y = model.apply(u)
    assert phase_lag_hilbert_deg(u, y) == pytest.approx(model.phase_lag_deg([15.0])[0], abs=0.02)


def test_bad_time_series_and_calibrations(tmp_path):
    t, xd, ref = p4.calibration()
    t2 = t.copy()
    t2[100] = t2[99]
    with pytest.raises(InputError, match="line 102: duplicated time stamp"):
        identify(t2, xd, ref)
    t3 = t.copy()
    t3[200], t3[201] = t3[201], t3[200]
    with pytest.raises(InputError, match="line 203: time goes backwards"):
        identify(t3, xd, ref)
    t4 = np.r_[t[:5000], t[4999] + 0.002 * np.arange(1, len(t) - 4999)]
    with pytest.raises(InputError, match="the sampling interval changes"):
        identify(t4, xd, ref)
    flat = np.full_like(xd, 12.5)
    with pytest.raises(StepError, match="no step in xd"):
        identify(t, flat, ref)
    # a loop that runs away: y[k] = 1.02 y[k−1] + 0.01 u[k]
    bad = signal.lfilter([0.01], [1.0, -1.02], xd - xd[0])
    with pytest.raises(StepError, match="the identified model is unstable"):
        identify(t, xd, bad)
    with pytest.raises(InputError, match="not a PointsPro dynamic model"):
        LoopModel.from_json("{}", "m.json")
    # scan channels that do not add up
    cloud = PointCloud.from_xyz(np.zeros(50), np.zeros(50), np.ones(50), t=np.arange(50) / 1e3,
                                xd=np.zeros(50), xc=np.zeros(50))
    (tmp_path / "m.json").write_text(identify(t, xd, ref).to_json(), encoding="utf-8")
    with pytest.raises(StepError, match=r"z ≠ xd \+ xc"):
        DynamicStep().run(cloud, DynamicStep.Params(model="m.json"), Context(base_dir=tmp_path))
    with pytest.raises(StepError, match="no xd/xc channel"):
        DynamicStep().run(PointCloud.from_xyz(np.zeros(5), np.zeros(5), np.zeros(5), t=np.arange(5.0)),
                          DynamicStep.Params(model="m.json"), Context(base_dir=tmp_path))


def test_a_real_pole_is_no_resonance_not_even_a_negative_one():
    """ln z of a real negative pole has the imaginary part π·fs: it was a 'mode' at the Nyquist
    frequency and tripped the advice to sample faster. Only complex pairs are modes."""
    from pointspro.core.dynamics.identify import LoopModel

    assert LoopModel(np.array([0.7, 0.0]), np.array([1.0, -0.3]), 1000.0).modes() == []
    assert LoopModel(np.array([1.3, 0.0]), np.array([1.0, 0.3]), 1000.0).modes() == []
    # a 60 Hz pair, ζ 0.15, and a real negative pole: one mode, 60 Hz
    fs, f, zeta = 2000.0, 60.0, 0.15
    wn = 2 * np.pi * f
    s = -zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)
    z = np.exp(s / fs)
    a = np.real(np.poly([z, np.conj(z), -0.006]))
    modes = LoopModel(np.array([a.sum()]), a, fs).modes()
    assert len(modes) == 1 and modes[0]["frequency_hz"] == pytest.approx(f, rel=1e-9)
    assert modes[0]["damping"] == pytest.approx(zeta, rel=1e-9)


def test_time_read_in_the_unit_its_header_states(tmp_path):
    """`t [ms]` was read as seconds: dynamic_id identified a 1 Hz loop and dynamic refused a 1 kHz scan
    as 'sampled at 1 Hz'. Now converted (ms, µs, min, h), or refused naming the file and the column."""
    from pointspro.core.dynamics.identify import write_example_calibration
    from pointspro.core.io import read_cloud

    write_example_calibration(tmp_path)  # t in s, 1 kHz
    a = np.loadtxt(tmp_path / "calibration.csv", delimiter=",", skiprows=1)
    k = np.arange(len(a), dtype=np.float64)  # the example's t is k / 1000 s
    assert np.array_equal(a[:, 0], k / 1000.0)
    for name, header, t in (("ms.csv", "t [ms],xd,ref", k), ("us.csv", "t [µs],xd,ref", k * 1000.0)):
        np.savetxt(tmp_path / name, np.column_stack([t, a[:, 1:]]), delimiter=",", header=header,
                   comments="", fmt="%.17g", encoding="utf-8")
    ctx, one = Context(base_dir=tmp_path), PointCloud.from_xyz([0.0], [0.0], [0.0])
    s = DynamicIdStep().run(one, DynamicIdStep.Params(calibration="calibration.csv"), ctx).report
    for name in ("ms.csv", "us.csv"):
        r = DynamicIdStep().run(one, DynamicIdStep.Params(calibration=name), ctx).report
        assert r["fs_hz"] == s["fs_hz"] == pytest.approx(1000.0)
        assert r["b"] == s["b"] and r["a"] == s["a"]
    np.savetxt(tmp_path / "bad.csv", np.column_stack([k, a[:, 1:]]), delimiter=",", header="t [mm],xd,ref",
               comments="", fmt="%.17g")
    with pytest.raises(InputError, match=r"bad\.csv, line 1: column 't': the unit stated is a length \(mm\); "
                                         "the dynamic_id step reads this column as a time in s"):
        DynamicIdStep().run(one, DynamicIdStep.Params(calibration="bad.csv"), ctx)
    # a scan at 1 kHz written in ms, corrected as the same scan in s
    rng = np.random.default_rng(4)
    n = 600
    xd = 12.5 + 0.01 * np.sin(2 * np.pi * 3.0 * k[:n] / 1000.0)
    xc = 1e-5 * rng.normal(size=n)
    x, y, z = np.linspace(0, 6, n), np.zeros(n), xd + xc
    in_s = DynamicStep().run(PointCloud.from_xyz(x, y, z, t=k[:n] / 1000.0, xd=xd, xc=xc),
                             DynamicStep.Params(calibration="calibration.csv"), ctx)
    for unit in ("ms", "furlong"):
        np.savetxt(tmp_path / "scan.csv", np.column_stack([x, y, z, k[:n], xd, xc]), delimiter=",",
                   header=f"x,y,z,t [{unit}],xd,xc", comments="", fmt="%.17g")
        scan = read_cloud(tmp_path / "scan.csv")
        if unit == "furlong":
            with pytest.raises(InputError, match=r"scan\.csv: column 't \[furlong\]': the unit stated is "
                                                 "'furlong', a unit PointsPro does not know; the dynamic step "
                                                 "reads this column as a time in s"):
                DynamicStep().run(scan, DynamicStep.Params(calibration="calibration.csv"), ctx)
            continue
        out = DynamicStep().run(scan, DynamicStep.Params(calibration="calibration.csv"), ctx)
        assert out.report["fs_hz"] == pytest.approx(1000.0)
        assert out.report["scan_speed_mm_s"] == pytest.approx(in_s.report["scan_speed_mm_s"])
        assert np.array_equal(out.cloud.z, in_s.cloud.z)
