"""z_scale after a review: an ISO 5436-1 type A1 groove (one certified depth, given for both edges)
read amplification 0.5005 for 1.001 — a degenerate line fit — and doubled the heights it corrected;
a scan tilted 2 mrad or more was refused; the amplification had no uncertainty. Fixed seeds."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.calibration.zscale import calibrate
from pointspro.core.step import Context
from pointspro.plugins.z_scale import ZScaleStep

X = np.arange(0.0, 10.0, 0.001)                     # mm, 1 µm sampling
NOISE = 2e-6                                         # mm


def grooves(spec, amp, seed, scans=3, tilt=1e-4):
    """Scans of grooves (a, b, depth µm) as an axis of amplification ``amp`` reads them (the review's
    generator)."""
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(scans):
        z = tilt * X + 1e-3 * s + rng.normal(0, NOISE, X.size)
        for a, b, d in spec:
            z = z - amp * d * 1e-3 * ((X > a) & (X < b))
        rows.append(np.column_stack([X, z, np.full(X.size, s)]))
    return np.vstack(rows)


def staircase(heights_um, amp, seed, scans=3, theta=1e-4, edges=(2.0, 4.0, 6.0, 8.0)):
    """Scans of a staircase rotated by ``theta`` (a tilted artefact: x and z both turn), read by an
    axis of amplification ``amp``."""
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(scans):
        v = sum(h * 1e-3 * (X > e) for h, e in zip(heights_um, edges)) + rng.normal(0, NOISE, X.size) \
            + 1e-3 * s
        x = X * np.cos(theta) - v * np.sin(theta)
        z = amp * (X * np.sin(theta) + v * np.cos(theta))
        rows.append(np.column_stack([x, z, np.full(X.size, s)]))
    return np.vstack(rows)


def run_step(tmp_path, rows, heights):
    np.savetxt(tmp_path / "steps.csv", rows, delimiter=",", header="x,z,scan", comments="", fmt="%.12g",
               encoding="utf-8")
    g = np.linspace(-5, 5, 41)
    gx, gy = np.meshgrid(g, g)
    bump = 0.010 * np.exp(-(gx ** 2 + gy ** 2) / 4)           # a 10 µm bump
    cloud = PointCloud.from_xyz(gx.ravel(), gy.ravel(), bump.ravel())
    res = ZScaleStep().run(cloud, ZScaleStep.Params(calibration="steps.csv", heights=heights),
                           Context(base_dir=tmp_path))
    return res, float(np.ptp(res.cloud.z)) * 1e3


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_a1_single_groove_gives_its_amplification(tmp_path, seed):
    """The review's case (seed 3): groove 4–6 mm, 3 µm deep, amplification 1.001, 3 scans, heights
    [3, 3] — read 0.5005 with linearity 0.14 nm, and a 10 µm bump became 19.98 µm."""
    res, bump_um = run_step(tmp_path, grooves([(4.0, 6.0, 3.0)], 1.001, seed), [3.0, 3.0])
    rep = res.report
    assert rep["amplification"] == pytest.approx(1.001, abs=3e-4)
    assert bump_um == pytest.approx(10 / 1.001, abs=0.003)      # 10 µm → 9.990 µm (not 19.98)
    assert rep["fit"] == "through origin" and rep["linearity_um"] is None and rep["offset_um"] == 0.0
    assert rep["dof"] == 5 and 0 < rep["amplification_u"] < 2e-4
    assert abs(rep["amplification"] - 1.001) <= rep["amplification_U95"]
    assert abs(bump_um - 10 / 1.001) <= 10 * rep["amplification_U95"] + 1e-9


def test_equal_heights_are_not_a_degenerate_line():
    """Two grooves of the same certified depth (four edges, one distinct height): a line through four
    equal abscissae trades its slope for its offset (0.49 for 0.98); through the origin it is 0.98."""
    rows = grooves([(2.0, 3.5, 2.0), (6.0, 7.5, 2.0)], 0.98, seed=11)
    cal = calibrate(rows[:, 0], rows[:, 1], rows[:, 2], np.full(4, 2e-3))
    assert cal.amplification == pytest.approx(0.98, abs=3e-4)
    assert cal.fit == "through origin" and np.isnan(cal.linearity) and cal.offset == 0.0
    assert cal.dof == 11
    assert abs(cal.amplification - 0.98) <= cal.U95 < 2e-4
    # one step, one height: the same fit (the core takes it; the step asks for two edges)
    one = staircase([3.0], 1.002, seed=12, edges=(5.0,))
    cal = calibrate(one[:, 0], one[:, 1], one[:, 2], [3e-3])
    assert cal.fit == "through origin" and cal.dof == 2
    assert abs(cal.amplification - 1.002) <= cal.U95


def test_two_distinct_heights_keep_the_line_and_its_linearity(tmp_path):
    """Grooves of 1 and 5 µm (heights [1, 1, 5, 5]): the line, its linearity, and an uncertainty."""
    res, bump_um = run_step(tmp_path, grooves([(2.0, 3.5, 1.0), (6.0, 7.5, 5.0)], 1.001, seed=3),
                            [1.0, 1.0, 5.0, 5.0])
    rep = res.report
    assert rep["fit"] == "line" and rep["dof"] == 10
    assert 0 <= rep["linearity_um"] < 0.002
    assert abs(rep["amplification"] - 1.001) <= rep["amplification_U95"] < 3e-4
    assert abs(bump_um - 10 / 1.001) <= 10 * rep["amplification_U95"] + 1e-9
    assert not rep["warnings"]


@pytest.mark.parametrize("theta", [3e-3, 20e-3])
def test_tilted_staircase_is_accepted(theta):
    """Tilts of 2 mrad and more were refused ("found 3 steps where 4 heights were given": each window's
    tilt × width raised the threshold above the 0.5 µm step). At 20 mrad the vertical offset of the
    planes is h / cos θ (+200 ppm): heights are read perpendicularly to the fitted line (ISO 5436-1)."""
    heights = np.array([0.5, 2.0, 5.0, 11.0])
    rows = staircase(heights, 1.002, seed=21, theta=theta)
    cal = calibrate(rows[:, 0], rows[:, 1], rows[:, 2], heights * 1e-3)
    assert cal.amplification == pytest.approx(1.002, abs=1e-4)
    assert cal.fit == "line"
    assert abs(cal.amplification - 1.002) <= cal.U95 < 1e-4
    assert cal.linearity < 0.002e-3


def test_uncertainty_covers_the_truth():
    """40 seeds of the review's four-step case (0.5–11 µm, amplification 1.002, 2 nm noise, 3 scans):
    U95 = t(ν)·u covers the truth in ≥ 90 %, and u is the scatter's size, not a multiple of it."""
    heights = np.array([0.5, 2.0, 5.0, 11.0])
    err, u, U = [], [], []
    for seed in range(100, 140):
        rows = staircase(heights, 1.002, seed=seed)
        cal = calibrate(rows[:, 0], rows[:, 1], rows[:, 2], heights * 1e-3)
        err.append(cal.amplification - 1.002)
        u.append(cal.u_amplification)
        U.append(cal.U95)
    err, u, U = map(np.asarray, (err, u, U))
    assert np.mean(np.abs(err) <= U) >= 0.9
    assert 0.6 < np.mean(u) / np.std(err) < 1.6


def test_no_residual_degrees_of_freedom_is_said(tmp_path):
    """Two heights in one scan: the line goes through both, its uncertainty is not known."""
    res, _ = run_step(tmp_path, staircase([1.0, 3.0], 1.0, seed=5, scans=1, edges=(3.0, 6.0)), [1.0, 3.0])
    assert res.report["dof"] == 0 and res.report["amplification_u"] is None
    assert any("uncertainty is not known" in w for w in res.report["warnings"])


def test_heights_are_positive():
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="positive"):
        ZScaleStep.Params(calibration="x.csv", heights=[3.0, -3.0])
