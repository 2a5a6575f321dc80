"""The guarded rule at the limit for an extreme value (irregularity B), over seeds: an independent
review found "does not conform" 6 times in 30 for a part whose true B was exactly the limit (ISO
14253-1's guarded acceptance and rejection allow ~2.5 %). The corrected B scattered 3× more than the
Monte Carlo samples (the SIMEX extrapolant's form swings between its ends from one measurement to
the next) and the interval's lower half was the noise's short side (core/uncertainty/estimate.py)."""
from __future__ import annotations

import numpy as np

from pointspro.core.cloud import PointCloud
from pointspro.core.metrics import zernike as zk
from pointspro.core.pipeline import run_pipeline
from pointspro.core.recipe import parse_recipe

R, SIGMA = 20.0, 20e-6  # mm


def _part(n=41):
    g = np.linspace(-R, R, n)
    X, Y = np.meshgrid(g, g)
    m = X**2 + Y**2 <= R * R * (1 + 1e-9)
    x, y = X[m], Y[m]
    # 50 nm of power, 20 nm spherical, 15 nm astigmatism, 10 nm coma (Fringe, rms-normalised)
    w = sum(a * zk.zernike(nn, mm, np.hypot(x, y) / R, np.arctan2(y, x))
            for (nn, mm), a in (((2, 0), 50e-6), ((4, 0), 20e-6), ((2, 2), 15e-6), ((3, 1), 10e-6)))
    c = 0.01
    r2 = x * x + y * y
    return x, y, c * r2 / (1 + np.sqrt(1 - c * c * r2)) + w


def test_irregularity_at_its_limit_is_rarely_rejected_under_the_guarded_rule():
    x, y, z = _part()
    surf = {"type": "even_asphere", "R": 100.0, "aperture": 40.0}
    steps = [{"misalignment": {"dof": ["dz"]}}]
    truth = run_pipeline(PointCloud.from_xyz(x, y, z), parse_recipe(
        {"pointspro": 1, "surface": surf, "steps": steps, "tolerance": {"irr_um": 100.0, "rule": "simple"}}
    )).summary()["tolerance"]["items"][0]["value_um"]
    recipe = parse_recipe({"pointspro": 1, "surface": surf, "steps": steps, "tolerance": {"irr_um": truth},
                           "uncertainty": {"samples": 50, "seed": 7, "noise": "20 nm", "workers": 1}})
    verdicts = []
    for seed in range(30):
        noisy = z + np.random.default_rng(1000 + seed).normal(0, SIGMA, x.size)
        verdicts.append(run_pipeline(PointCloud.from_xyz(x, y, noisy), recipe)
                        .summary()["tolerance"]["items"][0]["verdict"])
    assert verdicts.count("does not conform") <= 2, verdicts  # was 6 of 30 on the review's part
    assert verdicts.count("conforms") <= 2, verdicts
