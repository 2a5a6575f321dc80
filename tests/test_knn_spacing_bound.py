"""knn_denoise's spacing check passes a window above an upper bound of the sampling spacing without
the k-d tree of every point (plugins/knn_denoise `_subset_pitch_bound`): the bound must never fall
below the exact median nearest-neighbour distance, or a too-small window would pass unrefused."""
import numpy as np
from scipy.spatial import cKDTree

from pointspro.plugins.knn_denoise import _sampled, _subset_pitch_bound


def _exact(x, y, idx):
    pts = np.column_stack([x, y])
    d, _ = cKDTree(pts).query(pts[idx], k=2)
    return float(np.median(d[:, 1]))


def test_the_subset_bound_is_never_below_the_exact_spacing():
    for seed in range(8):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(200, 60_000))
        kind = seed % 3
        if kind == 0:  # scattered, shuffled
            x, y = rng.uniform(-50, 50, (2, n))
        elif kind == 1:  # a raster, shuffled
            g = np.arange(int(np.sqrt(n))) * 0.7
            x, y = (a.ravel() for a in np.meshgrid(g, g))
            order = rng.permutation(x.size)
            x, y = x[order], y[order]
        else:  # clusters of very different density
            x = np.concatenate([rng.normal(0, 1, n // 2), rng.uniform(-100, 100, n - n // 2)])
            y = np.concatenate([rng.normal(0, 1, n // 2), rng.uniform(-100, 100, n - n // 2)])
        idx = _sampled(x.size)
        assert _subset_pitch_bound(x, y, idx) >= _exact(x, y, idx) - 1e-12, seed


def test_a_too_small_window_is_still_refused_on_a_shuffled_cloud():
    import pytest

    import pointspro.core as pp
    from pointspro.core.errors import StepError
    from pointspro.core.step import Context
    from pointspro.plugins.knn_denoise import KnnDenoiseStep

    rng = np.random.default_rng(2)
    x, y = rng.uniform(-50, 50, (2, 40_000))  # spacing ~0.5 mm
    cloud = pp.PointCloud.from_numpy(np.c_[x, y, np.zeros_like(x)], residual=np.zeros_like(x))
    with pytest.raises(StepError, match="smaller than the sampling spacing"):
        KnnDenoiseStep().run(cloud, KnnDenoiseStep.Params(window=0.05), Context())
