"""Chunked forms of full-length computations (issue 26) give the numbers of the plain forms: the
spline's gradient in one pass, the figures' binned images, the pupil's radius."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_spline_gradient_is_both_derivative_calls_bit_for_bit(seed):
    from pointspro.core.maps import fit_bspline
    from pointspro.core.maps.bspline import CHUNK

    rng = np.random.default_rng(seed)
    n = CHUNK + 1234  # more than one chunk
    x, y = rng.uniform(-30, 30, n), rng.uniform(-20, 25, n)
    z = 1e-4 * np.sin(x / (5 + seed)) * np.cos(y / 4) + rng.normal(0, 1e-6, n)
    s = fit_bspline(x, y, z)
    xo, yo = rng.uniform(-40, 40, 500), rng.uniform(-40, 40, 500)  # beyond the domain too
    for px, py in ((x, y), (xo, yo)):
        gx, gy = s.gradient(px, py)
        assert np.array_equal(gx, s(px, py, dx=1)) and np.array_equal(gy, s(px, py, dy=1))


@pytest.mark.parametrize("seed", [0, 3])
def test_binned_image_in_chunks_is_the_plain_mean_per_bin(seed):
    from pointspro.core.figures import binned_image

    rng = np.random.default_rng(seed)
    n = (1 << 20) + 4321
    x, y = rng.uniform(-50, 50, n), rng.uniform(-40, 60, n)
    v = rng.normal(size=n)
    img, ext, k = binned_image(x, y, v)
    bins = img.shape[0]
    span = ext[1] - ext[0]
    ix = np.clip(((x - ext[0]) / span * bins).astype(np.intp), 0, bins - 1)
    iy = np.clip(((y - ext[2]) / span * bins).astype(np.intp), 0, bins - 1)
    kk = iy * bins + ix
    cnt = np.bincount(kk, minlength=bins * bins)
    ref = np.where(cnt > 0, np.bincount(kk, weights=v, minlength=bins * bins) / np.maximum(cnt, 1), np.nan)
    assert np.array_equal(k, kk)
    assert np.array_equal(np.isnan(img.ravel()), np.isnan(ref))
    assert np.allclose(img.ravel()[cnt > 0], ref[cnt > 0], rtol=0, atol=1e-13)
    img2, ext2, none = binned_image(x, y, v, return_bins=False)
    assert none is None and ext2 == ext and np.array_equal(img2, img, equal_nan=True)


def test_pupil_radius_in_chunks_is_the_plain_maximum():
    from pointspro.core.metrics.pupil import pupil_of

    rng = np.random.default_rng(5)
    x, y = rng.uniform(-50, 70, 700_001), rng.uniform(-30, 50, 700_001)
    p = pupil_of(x, y)
    assert p.radius == float(np.sqrt(np.max((x - p.center[0]) ** 2 + (y - p.center[1]) ** 2)))
