"""Dynamic identification review: the reference's zero, poles that do not decay, a reversed reference,
forced orders, real poles and the scan's phase lag (core/dynamics/identify.py, plugins dynamic_id and
dynamic).

Own generator: a continuous 2nd-order loop wn²/(s² + 2ζwn s + wn²) run on a grid 20× finer than the
samples (exact first-order-hold filter there), fed with steps shaped as raised-cosine ramps, then
sampled — so the fits never see their own model class, and a 4 ms ramp at 1 kHz has the content
between samples that made the fit put a pole at z ≈ −1.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from pointspro.core import PointCloud
from pointspro.core.dynamics.identify import LoopModel, identify
from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context
from pointspro.plugins.dynamic import DynamicStep
from pointspro.plugins.dynamic_id import DynamicIdStep

OVER = 20


def _sampled_response(fn, zeta, fs, u_fun, n):
    """(u, Gm·u) sampled at fs for the smooth input u_fun(t), Gm from rest at u(0)."""
    wn = 2 * np.pi * fn
    b, a, _ = signal.cont2discrete(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), 1.0 / (fs * OVER), method="foh")
    tf = np.arange(n * OVER) / (fs * OVER)
    uf = u_fun(tf)
    return uf[::OVER], (signal.lfilter(np.ravel(b), a, uf - uf[0]) + uf[0])[::OVER]


def _calibration(fn, zeta, fs, nsteps, period, ref_zero, seed, rise=0.004, noise=2e-6, amp=0.01):
    """t, xd, ref: half the steps up, half down, the axis at 5 mm, ref reading about ref_zero mm."""
    first = 0.3

    def u(t):
        out = np.full_like(t, 5.0)
        for k in range(nsteps):
            s = np.clip((t - first - k * period) / rise, 0.0, 1.0)
            out += (1 if k < nsteps // 2 else -1) * amp * (0.5 - 0.5 * np.cos(np.pi * s))
        return out

    n = int((first + nsteps * period) * fs)
    xd, sp = _sampled_response(fn, zeta, fs, u, n)
    ref = sp - 5.0 + ref_zero + np.random.default_rng(seed).normal(0.0, noise, n)
    return np.arange(n) / fs, xd, ref


def _scan(fn, zeta, fs, dur=4.0, noise=1e-6, seed=2):
    """An on-machine scan: the encoder follows a slow trend and a 12 Hz form; xc = h − Gm·xd + noise."""
    def xd_fun(t):
        return 3.0 + 0.02 * (t / dur) ** 2 + 0.002 * np.sin(2 * np.pi * 12.0 * t) * (1 - t / dur)

    n = int(dur * fs)
    xd, sp = _sampled_response(fn, zeta, fs, xd_fun, n)
    t = np.arange(n) / fs
    h = 3.0 + 50e-6 * np.sin(2 * np.pi * 1.7 * t)
    xc = h - sp + np.random.default_rng(seed).normal(0.0, noise, n)
    return t, xd, xc, h


H1 = dict(fn=338.0, zeta=0.1, fs=10000.0, nsteps=6, period=0.25, seed=1)   # 18,000 samples
S1 = dict(fn=300.0, zeta=0.2, fs=1000.0, nsteps=10, period=0.5, seed=1)    # 5,300 samples


def test_identification_does_not_depend_on_the_reference_zero():
    """The output-error fit started its offset at the ARX intercept, offset·Σa: with ref 5 or 25 mm
    from zero the start was far above the 'unstable' penalty, and the fit stopped in it — order 4 with
    a 3.5 kHz resonance that is not there, order 2 refused 'unstable (a pole at |z| = 0 ≥ 1)'."""
    got = {}
    for zero in (0.0, 5.0, 25.0):
        t, xd, ref = _calibration(ref_zero=zero, **H1)
        m = identify(t, xd, ref)
        assert abs(np.mean(ref) - zero) < 0.1
        got[zero] = m
        assert m.order == 2, (zero, m.order, m.modes())
        (mode,) = m.modes()
        assert mode["frequency_hz"] == pytest.approx(338.0, rel=0.01)
        assert mode["damping"] == pytest.approx(0.1, rel=0.02)
        forced = identify(t, xd, ref, order=2)  # was refused at 5 and 25 mm
        assert forced.modes()[0]["frequency_hz"] == pytest.approx(338.0, rel=0.01)
    f0 = got[0.0].modes()[0]["frequency_hz"]
    for zero in (5.0, 25.0):
        assert got[zero].order == got[0.0].order
        assert got[zero].modes()[0]["frequency_hz"] == pytest.approx(f0, rel=1e-6)
        assert np.allclose(got[zero].response([1.0, 15.0, 50.0]), got[0.0].response([1.0, 15.0, 50.0]),
                           atol=1e-6)


def test_forced_order_refused_for_what_it_is():
    """Order 1 of a damped 338 Hz loop: its ARX start is unstable (biased by the noise) — the message
    said the data do not describe a damped loop."""
    t, xd, ref = _calibration(ref_zero=5.0, **H1)
    with pytest.raises(StepError, match="order 1 cannot be fitted: its ARX start") as e:
        identify(t, xd, ref, order=1)
    msg = str(e.value)
    assert "try another order, or leave order empty" in msg and "1.01" in msg
    assert "do not describe a damped" not in msg


def test_a_pole_that_does_not_decay_is_not_accepted_and_the_scan_is_corrected(tmp_path):
    """4 ms ramps at 1 kHz: orders 3–5 fitted a real pole at z = −(1 − 1e-8), which no report showed
    and which rang at the Nyquist frequency through the corrected scan (7 nm RMS, sensor noise 1 nm)."""
    t, xd, ref = _calibration(ref_zero=5.0, **S1)
    np.savetxt(tmp_path / "cal.csv", np.column_stack([t, xd, ref]), delimiter=",", header="t,xd,ref",
               comments="", fmt="%.17g", encoding="utf-8")
    rep = DynamicIdStep().run(PointCloud.from_xyz([0.0], [0.0], [0.0]),
                              DynamicIdStep.Params(calibration="cal.csv"), Context(base_dir=tmp_path)).report
    m = LoopModel.from_json(json.dumps({"pointspro_dynamic_model": 1, **rep}))
    n = len(t)
    # the margin: every pole decays (1/e) within a quarter of the record, |z| ≤ exp(−4/N)
    assert np.all(np.abs(m.poles_z) <= np.exp(-4.0 / n)), m.poles_z
    assert np.abs(m.poles_z).max() < 0.9  # the loop's own poles, |z| 0.68
    assert m.order == 2 and m.modes()[0]["frequency_hz"] == pytest.approx(300.0, rel=0.02)
    _, xds, xc, h = _scan(300.0, 0.2, 1000.0)
    err = m.apply(xds) + xc - h
    assert np.std(err) < 2e-6  # within 2× the sensor's 1 nm
    assert rep["slowest_decay_s"] <= 0.25 * rep["record_s"] and rep["real_poles"] == []
    assert rep["orders_set_aside"] and all("z = -1" in v for v in rep["orders_set_aside"].values())
    assert any("set aside" in w and "order 2 is used" in w for w in rep["warnings"])
    # the order forced to one that puts the pole there: refused, naming it
    with pytest.raises(StepError, match=r"order 3: a pole at z = -1 .* ringing at the Nyquist frequency"):
        identify(t, xd, ref, order=3)


def test_real_poles_reported_and_a_model_file_that_does_not_decay():
    fs = 1000.0
    wn, zeta = 2 * np.pi * 300.0, 0.2
    p = np.exp((-zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)) / fs)
    a = np.real(np.poly([p, np.conj(p), -(1 - 1e-8)]))
    m = LoopModel(np.array([a.sum(), 0.0, 0.0, 0.0]), a, fs)
    (real,) = m.describe()["real_poles"]
    assert real["z"] == pytest.approx(-(1 - 1e-8), abs=1e-12) and real["alternating"]
    assert real["decay_time_s"] > 1e4
    assert len(m.modes()) == 1
    # a model file stating its record: a pole decaying over more than a quarter of it is refused
    d = {"pointspro_dynamic_model": 1, "fs_hz": fs, "b": m.b.tolist(), "a": m.a.tolist(), "record_s": 10.0}
    with pytest.raises(InputError, match="decaying in .* s, more than 0.25 of its 10 s calibration record"):
        LoopModel.from_json(json.dumps(d), "m.json")


def test_reference_with_the_opposite_sign_refused_and_a_far_dc_gain_warned():
    t, xd, ref = _calibration(ref_zero=5.0, **S1)
    with pytest.raises(StepError, match=r"DC gain is -1 ≤ 0 .* the reference sensor's sign is likely reversed"):
        identify(t, xd, -ref)
    with pytest.raises(StepError, match="sign is likely reversed"):
        identify(t, xd, -ref, order=2)
    from pointspro.core.dynamics.identify import model_warnings

    assert model_warnings(identify(t, xd, ref)) == []
    (w,) = model_warnings(identify(t, xd, 3.0 * ref))
    assert w.startswith("the DC gain is 3 (1.5× the largest plausible, 0.5–2)") and "units" in w


def test_dynamic_reports_the_model_lag_at_the_scan_frequency_and_warns_of_a_ringing_model(tmp_path):
    """phase_lag_scan_deg, a Hilbert median, follows the scan's slow trend (0.16° here, where the 12 Hz
    form lags 0.9°): the model's lag at the encoder's dominant frequency is reported beside it."""
    t, xd, ref = _calibration(ref_zero=5.0, **S1)
    m = identify(t, xd, ref)
    (tmp_path / "m.json").write_text(m.to_json(), encoding="utf-8")
    ts, xds, xc, h = _scan(300.0, 0.2, 1000.0)
    x = np.linspace(0.0, 8.0, ts.size)
    cloud = PointCloud.from_xyz(x, np.zeros_like(x), xds + xc, t=ts, xd=xds, xc=xc)
    rep = DynamicStep().run(cloud, DynamicStep.Params(model="m.json"), Context(base_dir=tmp_path)).report
    lag = rep["phase_lag_model_deg"]
    assert lag["frequency_hz"] == pytest.approx(12.0, abs=0.3)
    assert lag["lag_deg"] == pytest.approx(float(m.phase_lag_deg([lag["frequency_hz"]])[0]))
    assert 0.8 < lag["lag_deg"] < 1.0 and abs(rep["phase_lag_scan_deg"]) < 0.5 * lag["lag_deg"]
    assert rep["warnings"] == [] and rep["model"]["real_poles"] == []
    # a model file of the earlier version (no record stated) with the pole at z ≈ −1: warned of
    fs = 1000.0
    a = np.real(np.poly(np.r_[m.poles_z, -(1 - 1e-8)]))
    old = {"pointspro_dynamic_model": 1, "fs_hz": fs, "b": [a.sum(), 0.0, 0.0, 0.0], "a": a.tolist()}
    (tmp_path / "old.json").write_text(json.dumps(old), encoding="utf-8")
    rep = DynamicStep().run(cloud, DynamicStep.Params(model="old.json"), Context(base_dir=tmp_path)).report
    assert any("longer than the scan" in w for w in rep["warnings"])


def test_a_reference_sampled_slower_than_the_record_is_warned_of(tmp_path):
    """A review: a 250 Hz reference sensor held over 4 rows of a 1000 Hz record identified a loop with
    a 4× wrong phase lag (order 3, a pole at z = −0.69) and said nothing; now a warning names it."""
    import numpy as np

    from pointspro.core import PointCloud
    from pointspro.core.dynamics.identify import write_example_calibration
    from pointspro.core.step import Context
    from pointspro.plugins.dynamic_id import DynamicIdStep

    p = write_example_calibration(tmp_path)
    cloud = PointCloud.from_xyz([0.0], [0.0], [0.0])
    rep = DynamicIdStep().run(cloud, DynamicIdStep.Params(calibration=p), Context(base_dir=tmp_path)).report
    assert not any("repeats its value" in w for w in rep["warnings"]), rep["warnings"]
    d = np.loadtxt(p, delimiter=",", skiprows=1)
    d[:, 2] = np.repeat(d[::4, 2], 4)[: len(d)]
    np.savetxt(tmp_path / "held.csv", d, delimiter=",", header="t,xd,ref", comments="")
    rep = DynamicIdStep().run(cloud, DynamicIdStep.Params(calibration="held.csv"), Context(base_dir=tmp_path)).report
    assert any("the reference 'ref' repeats its value in runs of ~4 samples while 'xd' moves" in w
               for w in rep["warnings"]), rep["warnings"]
