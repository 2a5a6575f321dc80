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
#: pure-noise draws through the data's own neighbourhoods that give σ's relative uncertainty, and the
#: points they are judged on (the nearest to the sampling's centre: a compact patch keeps the
#: neighbours' shared points, which a random subset would lose)
SCATTER_DRAWS = 160
SCATTER_POINTS = 20_000


def relative_uncertainty(n: int, factor: float) -> float:
    """The relative standard uncertainty of ``estimate_sigma`` from n points whose sampling gives the
    scatter ``factor`` (the standard deviation of σ̂/σ times √n: ``sigma_with_uncertainty``)."""
    return factor / np.sqrt(max(n, 1))


def method_text(k: int = NEIGHBOURS) -> str:
    return (f"σ from the final residual: leave-one-out prediction errors of a local quadratic over the "
            f"{k} nearest neighbours, divided by √(1 + leverage), robust by the MAD (docs/uncertainty.md)")


def estimate_sigma(x, y, v, k: int = NEIGHBOURS) -> float:
    """σ (unit of v) of independent noise on v at points (x, y); see the module doc."""
    return sigma_with_uncertainty(x, y, v, k, draws=0)[0]


def sigma_with_uncertainty(x, y, v, k: int = NEIGHBOURS, draws: int = SCATTER_DRAWS,
                           seed: int = 0) -> tuple[float, float]:
    """(σ, its relative standard uncertainty) of independent noise on v at points (x, y).

    The MAD's σ has a variance 1.36 σ²/N for N independent values (efficiency 37 %: Huber & Ronchetti,
    Robust Statistics, 2009, §5.1), but the leave-one-out errors here share their neighbours' noise,
    and how much depends on the sampling: measured over 100 seeds the scatter of σ̂/σ was 1.90/√N on
    a raster, 1.52 on random points, 1.60 on a spiral and 1.59 on a star (a review; the former
    constant 1.2/√N understated u where the noise bias's correction dominates it). So the scatter is
    measured on the data's own neighbourhoods: ``draws`` standard-normal noise vectors go through the
    same leave-one-out weights and MAD (on the ``SCATTER_POINTS`` points nearest the sampling's centre
    for a large cloud), and the standard deviation of their σ̂ times √n is the factor (fixed seed:
    the same cloud gives the same u)."""
    x, y, v = (np.asarray(a, dtype=np.float64) for a in (x, y, v))
    nb, g, w, tree = _loo_design(x, y, v.size, k)
    sigma = _mad_sigma(v, nb, g, w)
    if draws <= 1:
        return sigma, float("nan")
    n = v.size
    rows = np.arange(n) if n <= SCATTER_POINTS else np.sort(
        tree.query([np.median(x), np.median(y)], k=SCATTER_POINTS)[1])
    need = np.unique(np.concatenate([rows, nb[rows].ravel()]))
    rng = np.random.default_rng(seed)
    noise = np.zeros(n)
    est = np.empty(draws)
    for d in range(draws):
        noise[need] = rng.standard_normal(need.size)
        est[d] = _mad_sigma(noise, nb[rows], g[rows], w[rows], own=rows)
    factor = float(np.std(est, ddof=1) / np.mean(est) * np.sqrt(rows.size))
    return sigma, relative_uncertainty(n, factor)


def _mad_sigma(v, nb, g, w, own=None) -> float:
    """σ from the leave-one-out errors of the points ``own`` (all by default) — module doc."""
    pred = np.einsum("nk,nk->n", g, v[nb])
    e = ((v if own is None else v[own]) - pred) / np.sqrt(1.0 + w)
    e = e[np.isfinite(e)]
    return float(MAD_TO_SIGMA * np.median(np.abs(e - np.median(e))))


def _loo_design(x, y, n: int, k: int):
    """The neighbours (n, k) of each point, the weights g (n, k) that predict its value from theirs by
    the local quadratic, the prediction's variance factor w = ‖g‖², and the k-d tree."""
    from scipy.spatial import cKDTree

    if n < MIN_POINTS:
        raise PointsProError(f"uncertainty: noise: auto needs at least {MIN_POINTS} points to estimate the "
                             f"noise (the cloud has {n}); give noise: \"50 nm\" (its σ) instead")
    k = min(k, n - 1)
    pts = np.column_stack([x, y])
    tree = cKDTree(pts)
    _, idx = tree.query(pts, k=k + 1)
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
    w = np.einsum("nk,nk->n", g, g)
    return nb, g, w, tree
