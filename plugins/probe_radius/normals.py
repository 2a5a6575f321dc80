"""Surface normals refined from the data, for probe-radius compensation on parts with form error.

The envelope of probe-ball centres has, at each centre, the normal of the *real* part at the contact
point (paper 002 §3). The design normal misses the form error's slope θ_e, which moves the compensated
point sideways by ρ_ball·θ_e (4 mm × 3·10⁻⁴ rad ≈ 1.2 µm). We estimate the slope of the distance
residual eᵢ = dᵢ − s·ρ_ball (the form error along the normal) by a local linear least-squares fit over
the k nearest neighbours (in the part frame's x, y) and tilt the design normal accordingly:

    z_real ≈ f + e / n_z   ⇒   n̂_real ∝ (n_x − e_x, n_y − e_y, n_z).

On a star pattern a point's neighbours lie mostly along its own line, so the slope across the line is
not determined there: directions in which the neighbourhood's spread is below a fifth of its largest
spread are left at the design normal (truncated pseudo-inverse) instead of being invented.

Spikes and low points (dust, the probe slipping off an edge) would tilt their neighbours' normals by
hundreds of µrad, so before the slope fits each eᵢ farther than 6 robust σ from its neighbourhood's
median is replaced by that median (σ from the median absolute deviation of all points).

Noise makes slopes too: 0.3 µm over 0.4 mm (the points where a star's lines meet) is 750 µrad, or
3 µm sideways under a 4 mm ball. Each slope component b (in the eigenbasis of its neighbourhood)
has the standard error σ_b = σ_e / sqrt(w), w the spread along that direction and σ_e the noise of
the local plane fits; it is shrunk to b·max(0, 1 − 4σ_b²/b²), so slopes the data show well beyond 2σ are
kept nearly whole and slopes that noise could have made are dropped.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def residual_slopes(xy: np.ndarray, e: np.ndarray, k: int = 16) -> tuple[np.ndarray, int]:
    """(N, 2) slopes (∂e/∂x, ∂e/∂y) from local plane fits over the k nearest neighbours, and the
    number of outlying residuals set aside."""
    n = len(xy)
    k = int(min(k, n))
    _, idx = cKDTree(xy).query(xy, k=k)
    local = np.median(e[idx], axis=1)
    dev = e - local
    sigma = 1.4826 * np.median(np.abs(dev))
    outlier = np.abs(dev) > 6.0 * sigma if sigma > 0 else np.zeros(n, dtype=bool)
    e = np.where(outlier, local, e)
    nb = xy[idx] - xy[idx].mean(axis=1, keepdims=True)  # (N, k, 2)
    ev = e[idx] - e[idx].mean(axis=1, keepdims=True)  # (N, k)
    cov = np.einsum("nki,nkj->nij", nb, nb)  # (N, 2, 2)
    rhs = np.einsum("nki,nk->ni", nb, ev)  # (N, 2)
    w, v = np.linalg.eigh(cov)  # ascending eigenvalues
    keep = w >= 0.04 * w[:, -1:]  # spread ≥ 1/5 of the largest (variance ratio 1/25)
    inv = np.where(keep, 1.0 / np.where(w > 0, w, 1.0), 0.0)
    b = np.einsum("nji,nj->ni", v, rhs) * inv  # slope components in the eigenbasis
    slope = np.einsum("nij,nj->ni", v, b)
    # noise of the local plane fits (3 parameters on k points), then shrink what noise could make
    fit_res = ev - np.einsum("nki,ni->nk", nb, slope)
    sigma_e = np.median(np.sqrt(np.sum(fit_res ** 2, axis=1) / max(k - 3, 1)))
    var_b = sigma_e ** 2 * inv
    with np.errstate(divide="ignore", invalid="ignore"):
        shrink = np.where(b != 0, np.clip(1.0 - 4.0 * var_b / (b * b), 0.0, 1.0), 0.0)
    return np.einsum("nij,nj->ni", v, b * shrink), int(outlier.sum())


def refined_normals(n_design: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    m = np.column_stack([n_design[:, 0] - slopes[:, 0], n_design[:, 1] - slopes[:, 1], n_design[:, 2]])
    return m / np.linalg.norm(m, axis=1)[:, None]
