"""Issue 23: honest coverage. Repeated simulated CMM measurements of three parts (the issue's asphere
on a raster, a star scan with probe compensation, a radial scan with mid-spatial form), each with a
fresh pose and fresh noise: the 95 % interval must contain the noise-free value (the same recipe on
the noise-free measurement) about 95 % of the time, the bias correction must remove the noise's
inflation, and u must agree with the repeats' scatter. Kept affordable (60 samples per measurement);
the full figures with 200 samples are in benchmarks/bench_uncertainty.py."""
from __future__ import annotations

import numpy as np
import pytest

from .test_uncertainty_sim import run_coverage

#: repeats per part, and the noise given in the recipe (None: noise: auto). The radial scan's rings
#: are at the neighbours' scale along its rays: noise: auto reads them as noise (σ 15 % high, which
#: over-corrects the bias — docs/uncertainty.md, Noise), so that part is run with its σ given
RUNS = {"issue": (24, None), "star_probe": (16, None), "radial_mid": (16, "40 nm")}


@pytest.fixture(scope="module")
def runs():
    return {name: run_coverage(name, n, 50, workers=2, noise=noise) for name, (n, noise) in RUNS.items()}


@pytest.mark.parametrize("figure", ["rms_um", "pvr_um", "slope_rms_urad", "zernike.Z5_nm", "zernike.Z9_nm"])
def test_the_95_percent_interval_covers_the_noise_free_value(runs, figure):
    """Pooled over 56 measurements: ≥ 85 % (3 binomial standard deviations below 95 % at this size;
    the benchmark's repeats give the ≥ 93 % figure)."""
    hits = np.concatenate([r["rows"][figure]["hit"] for r in runs.values()])
    per_case = {n: round(r[figure]["coverage"], 3) for n, r in runs.items()}
    assert hits.mean() >= 0.85, per_case
    for name, r in runs.items():  # no part on its own far below (binomial slack at 16 repeats)
        assert r[figure]["coverage"] >= 0.75, (name, per_case)


def test_the_bias_correction_removes_the_noise_inflation(runs):
    """The issue's set-up: the plain RMS reads ~6.4 nm high; the corrected one within 1 nm, and on
    every part the corrected RMS, PVr and slope RMS are unbiased within their standard error or a fifth
    of the plain bias. (On the star scan with probe compensation the plain RMS is not inflated —
    probe_radius's refined normals absorb part of the noise — and the correction must not add a bias.)"""
    issue = runs["issue"]
    assert issue["rms_um"]["plain_bias"] * 1e3 > 4.0
    assert abs(issue["rms_um"]["corrected_bias"]) * 1e3 < 1.0
    for fig in ("rms_um", "pvr_um", "slope_rms_urad"):
        assert issue[fig]["plain_bias"] > 0, fig
    for name, r in runs.items():
        for fig in ("rms_um", "pvr_um", "slope_rms_urad"):
            if (name, fig) in OVER_CORRECTED:
                continue  # test_known_gap_the_star_scans_pvr_and_pv_are_over_corrected
            plain, corr = r[fig]["plain_bias"], r[fig]["corrected_bias"]
            se = r[fig]["scatter"] / np.sqrt(r["repeats"])
            assert abs(corr) < max(0.2 * abs(plain), 3 * se), (name, fig, plain, corr, se)


def test_u_agrees_with_the_scatter_of_the_repeats(runs):
    for name, r in runs.items():
        for fig in ("rms_um", "pvr_um", "zernike.Z5_nm", "zernike.Z9_nm"):
            assert 0.7 <= r[fig]["u_over_scatter"] <= 1.5, (name, fig, r[fig]["u_over_scatter"])


def test_pv_is_corrected_and_its_coverage_stated(runs):
    """PV is an extreme value (Evans): its correction is approximate; the test asks that it lowers
    the bias and records the coverage measured (the benchmark states it)."""
    for name, r in runs.items():
        pv = r["pv_um"]
        if (name, "pv_um") not in OVER_CORRECTED:
            assert abs(pv["corrected_bias"]) < abs(pv["plain_bias"]), (name, pv)
        assert pv["coverage"] >= 0.5, (name, pv)


#: (part, figure) whose noise-bias correction overshoots: the star scan with probe compensation, since
#: its recipe runs misalignment after probe_radius as it must (2026-11-26: the test's recipe lacked it,
#: so zernike had fitted the contact points' heights — the sag — and these figures were of that).
#: Measured then (16 repeats, 50 samples): PVr plain +54 nm, corrected −62 nm (scatter 56 nm); PV
#: +52 → −130 nm (scatter 188 nm); coverage PVr 94 %, PV 100 %, RMS 88 %, slope 81 %.
#: Why (docs/uncertainty.md, "Known gap"): with probe compensation PVr's and slope RMS's bias grows
#: faster than σ² (+70 → +163 nm from σ² to 2σ²), so the samples' step over-estimates it; PV's grows as
#: σ² where its correction may assume σ.
OVER_CORRECTED = {("star_probe", "pvr_um"), ("star_probe", "pv_um")}


@pytest.mark.xfail(strict=True, reason="known gap: on the star scan with probe compensation the noise-bias "
                                       "correction of PVr and PV overshoots (see OVER_CORRECTED)")
def test_known_gap_the_star_scans_pvr_and_pv_are_over_corrected(runs):
    r = runs["star_probe"]
    for fig in sorted(f for n, f in OVER_CORRECTED):
        plain, corr = r[fig]["plain_bias"], r[fig]["corrected_bias"]
        assert abs(corr) < abs(plain), (fig, plain, corr)


def test_noise_is_estimated_within_a_few_percent(runs):
    for name, r in runs.items():
        if RUNS[name][1] is None:
            est, true = r["sigma_nm"]
            assert est == pytest.approx(true, rel=0.05), name


def test_noise_auto_reads_form_at_the_neighbour_scale_as_noise():
    """The known limit, stated: on the radial scan with rings at the neighbours' scale σ reads high."""
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.uncertainty.noise import estimate_sigma

    from .test_uncertainty_sim import CASES

    case = CASES["radial_mid"]
    noisy, _ = case.measure(1000)
    c = run_pipeline(noisy, case.recipe()).cloud
    assert estimate_sigma(c.x, c.y, c["residual"]) > 1.05 * case.noise_nm * 1e-6
