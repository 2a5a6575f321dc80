"""knn_denoise, review 7 of issue 16 part 3: small windows, noise-free form, digs, floor, heavy tails."""
from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pointspro.core import PointCloud
from pointspro.core.step import Context
from pointspro.plugins.knn_denoise import KnnDenoiseStep


def run(cloud, **params):
    return KnnDenoiseStep().run(cloud, KnnDenoiseStep.Params(**params), Context())


def disc_raster(R, s):
    g = np.arange(-R, R + s / 2, s)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    k = np.hypot(x, y) <= R
    return x[k], y[k]


def test_a_window_below_one_mm_needs_no_spacing_for_robust():
    """robust does not use `spacing`: a 10 mm part's 0.12 mm raster with a = 0.5 mm ran into 'spacing
    must not exceed window' for the default 1 mm nobody set. The check stays where the grid is used
    (paper) or a spacing other than the default was given."""
    rng = np.random.default_rng(7)
    x, y = disc_raster(5.0, 0.12)
    d = rng.normal(0, 2e-6, len(x))
    d[len(x) // 2] += 1e-3
    res = run(PointCloud.from_xyz(x, y, d), window=0.5)
    assert res.report["removed"] == 1
    with pytest.raises(ValidationError, match=r"spacing must not exceed window.*by default"):
        KnnDenoiseStep.Params(window=0.5, method="paper")
    with pytest.raises(ValidationError, match="spacing must not exceed window"):
        KnnDenoiseStep.Params(window=0.5, spacing=2.0)
    KnnDenoiseStep.Params(window=0.5, spacing=0.25, method="paper")
    KnnDenoiseStep.Params(window=0.5, spacing=1.0)  # a full recipe's default, written out: not refused
