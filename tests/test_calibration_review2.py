"""Calibration defects found by a second independent review (fiducials, volumetric, z_scale, kinematic)."""
from __future__ import annotations

import numpy as np

from pointspro.core.calibration.fiducial_sim import machine_frame
from pointspro.core.calibration.fiducials import fit_affine


def test_chi2_counts_the_reference_noise_on_a_null_field():
    """No volumetric error, the defaults σ_r 0.2 µm and σ_m 0.1 µm: χ²/ν ≈ 1 over many seeds (with σ_m
    alone it read ~5)."""
    sm, sr = 0.1e-3, 0.2e-3
    red = []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        ref_true = np.column_stack([rng.uniform(-100, 100, 24), rng.uniform(-20, 20, 24), rng.uniform(0, 50, 24)])
        meas = machine_frame(ref_true) + rng.normal(0, sm, ref_true.shape)
        ref = ref_true + rng.normal(0, sr, ref_true.shape)
        fit = fit_affine(ref, meas, sm, sr)
        red.append(fit.chi2 / fit.dof)
    # ν = 60 per fit: χ²/ν has σ ≈ 0.18, its mean over 30 fits ≈ 0.033
    assert 0.85 < np.mean(red) < 1.15, np.mean(red)
