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
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def residual_slopes(xy: np.ndarray, e: np.ndarray, k: int = 16) -> np.ndarray:
    """(N, 2) slopes (∂e/∂x, ∂e/∂y) from local plane fits over the k nearest neighbours."""
    n = len(xy)
    k = int(min(k, n))
    _, idx = cKDTree(xy).query(xy, k=k)
    nb = xy[idx] - xy[idx].mean(axis=1, keepdims=True)  # (N, k, 2)
    ev = e[idx] - e[idx].mean(axis=1, keepdims=True)  # (N, k)
    cov = np.einsum("nki,nkj->nij", nb, nb)  # (N, 2, 2)
    rhs = np.einsum("nki,nk->ni", nb, ev)  # (N, 2)
    w, v = np.linalg.eigh(cov)  # ascending eigenvalues
    keep = w >= 0.04 * w[:, -1:]  # spread ≥ 1/5 of the largest (variance ratio 1/25)
    inv = np.where(keep, 1.0 / np.where(w > 0, w, 1.0), 0.0)
    proj = np.einsum("nji,nj->ni", v, rhs) * inv  # coefficients in the eigenbasis
    return np.einsum("nij,nj->ni", v, proj)


def refined_normals(n_design: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    m = np.column_stack([n_design[:, 0] - slopes[:, 0], n_design[:, 1] - slopes[:, 1], n_design[:, 2]])
    return m / np.linalg.norm(m, axis=1)[:, None]
