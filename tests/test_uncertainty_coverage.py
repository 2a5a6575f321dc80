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

RUNS = {"issue": 40, "star_probe": 25, "radial_mid": 25}


@pytest.fixture(scope="module")
def runs():
    return {name: run_coverage(name, n, 60, workers=2) for name, n in RUNS.items()}


@pytest.mark.parametrize("figure", ["rms_um", "pvr_um", "slope_rms_urad", "zernike.Z5_nm", "zernike.Z9_nm"])
def test_the_95_percent_interval_covers_the_noise_free_value(runs, figure):
    """Pooled over 90 measurements: ≥ 87 % (3 binomial standard deviations below 95 % at this size;
    the benchmark's 100 repeats × 200 samples per part give the ≥ 93 % figure)."""
    hits = np.concatenate([r["rows"][figure]["hit"] for r in runs.values()])
    per_case = {n: round(r[figure]["coverage"], 3) for n, r in runs.items()}
    assert hits.mean() >= 0.87, per_case
    for name, r in runs.items():  # no part on its own far below (binomial slack at 25 repeats)
        assert r[figure]["coverage"] >= 0.80, (name, per_case)


def test_the_bias_correction_removes_the_noise_inflation(runs):
    """The issue's set-up: the plain RMS reads ~6.4 nm high; the corrected one within 1 nm, and PVr's
    and slope RMS's bias shrinks to a small part of the plain one on every part."""
    issue = runs["issue"]
    assert issue["rms_um"]["plain_bias"] * 1e3 > 4.0
    assert abs(issue["rms_um"]["corrected_bias"]) * 1e3 < 1.0
    for name, r in runs.items():
        for fig in ("rms_um", "pvr_um", "slope_rms_urad"):
            plain, corr = r[fig]["plain_bias"], r[fig]["corrected_bias"]
            assert plain > 0, (name, fig)
            # within 3 standard errors of zero, or a fifth of the plain bias
            assert abs(corr) < max(0.2 * plain, 3 * r[fig]["scatter"] / np.sqrt(r["repeats"])), (name, fig, plain, corr)


def test_u_agrees_with_the_scatter_of_the_repeats(runs):
    for name, r in runs.items():
        for fig in ("rms_um", "pvr_um", "zernike.Z5_nm", "zernike.Z9_nm"):
            assert 0.7 <= r[fig]["u_over_scatter"] <= 1.5, (name, fig, r[fig]["u_over_scatter"])


def test_pv_is_corrected_and_its_coverage_stated(runs):
    """PV is an extreme value (Evans): its correction is approximate; the test asks that it lowers
    the bias and records the coverage measured (the benchmark states it)."""
    for name, r in runs.items():
        pv = r["pv_um"]
        assert abs(pv["corrected_bias"]) < abs(pv["plain_bias"]), (name, pv)
        assert pv["coverage"] >= 0.5, (name, pv)


def test_noise_is_estimated_within_a_few_percent(runs):
    for name, r in runs.items():
        est, true = r["sigma_nm"]
        assert est == pytest.approx(true, rel=0.05), name
