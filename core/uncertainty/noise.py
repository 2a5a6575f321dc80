"""σ of the measurement noise from the data itself (``noise: auto``; docs/uncertainty.md, Noise).

Each point's height is predicted, leaving it out, by a least-squares quadratic in (x, y) over its K
nearest neighbours (x, y distance). The prediction error e_i = v_i − p_i has variance σ²(1 + w_i), where
w_i = ‖g_i‖² is the prediction's own variance factor (g_i the row of the design's pseudo-inverse that
gives the value at the point: its leverage); e_i/√(1 + w_i) are then N(0, σ²) for a smooth form, and
σ = 1.4826 · median|e/√(1 + w) − median| (the MAD: the outliers a denoising step left do not inflate
it). Form structure at the neighbours' scale that a quadratic cannot follow adds to e: the estimate is
then biased high, never low — a wider interval, but a bias correction too large (the corrected RMS
reads low): where a sparse scan leaves the form's structure at the neighbours' scale (rings between
the points of a radial ray), give ``noise:`` from repeated measurements instead (docs/uncertainty.md). Points whose neighbours lie on one line (a
star or raster scan's line) get a quadratic along that line: the design's pseudo-inverse is taken over
its non-zero singular values.
"""
from __future__ import annotations

import numpy as np

from ..errors import PointsProError

#: neighbours per local quadratic (6 coefficients): few, so the quadratic spans little of the form —
#: on sparse scans (a star's or radial pattern's lines) 20 neighbours read the form's curvature as noise
NEIGHBOURS = 8
MIN_POINTS = 30
MAD_TO_SIGMA = 1.482602218505602
#: the MAD's σ has a variance 1.36 σ²/N for Gaussian data (its efficiency is 37 %: Huber & Ronchetti,
#: Robust Statistics, 2009, §5.1); the neighbours' shared points raise it a little more (measured: 1.16 →
#: 1.2 /√N on the tests' patterns)
U_REL_FACTOR = 1.2


def relative_uncertainty(n: int) -> float:
    """The relative standard uncertainty of ``estimate_sigma`` from n points."""
    return U_REL_FACTOR / np.sqrt(max(n, 1))


def method_text(k: int = NEIGHBOURS) -> str:
    return (f"σ from the final residual: leave-one-out prediction errors of a local quadratic over the "
            f"{k} nearest neighbours, divided by √(1 + leverage), robust by the MAD (docs/uncertainty.md)")


def estimate_sigma(x, y, v, k: int = NEIGHBOURS) -> float:
    """σ (unit of v) of independent noise on v at points (x, y); see the module doc."""
    from scipy.spatial import cKDTree

    x, y, v = (np.asarray(a, dtype=np.float64) for a in (x, y, v))
    n = v.size
    if n < MIN_POINTS:
        raise PointsProError(f"uncertainty: noise: auto needs at least {MIN_POINTS} points to estimate the "
                             f"noise (the cloud has {n}); give noise: \"50 nm\" (its σ) instead")
    k = min(k, n - 1)
    pts = np.column_stack([x, y])
    _, idx = cKDTree(pts).query(pts, k=k + 1)
    nb = idx[:, 1:]  # the point itself is its own nearest neighbour (duplicates: any one of them)
    own = idx[:, 0]
    # a duplicate x, y may come first: then the point is among nb; swap it for the duplicate
    same = nb == np.arange(n)[:, None]
    rows = np.flatnonzero(same.any(axis=1))
    for i in rows:
        nb[i, same[i]] = own[i]
    du = x[nb] - x[:, None]
    dv = y[nb] - y[:, None]
    h = np.sqrt(np.max(du * du + dv * dv, axis=1))
    h[h == 0] = 1.0
    du /= h[:, None]
    dv /= h[:, None]
    A = np.stack([np.ones_like(du), du, dv, du * du, du * dv, dv * dv], axis=2)  # (n, k, 6)
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    tol = s[:, :1] * 1e-8
    inv = np.where(s > tol, 1.0 / np.where(s > tol, s, 1.0), 0.0)
    # g = e0ᵀ A⁺ = (V[0, :] / s) Uᵀ: the weights that give the fitted value at the point
    g = np.einsum("nj,nkj->nk", Vt[:, :, 0] * inv, U)
    pred = np.einsum("nk,nk->n", g, v[nb])
    w = np.einsum("nk,nk->n", g, g)
    e = (v - pred) / np.sqrt(1.0 + w)
    e = e[np.isfinite(e)]
    return float(MAD_TO_SIGMA * np.median(np.abs(e - np.median(e))))
