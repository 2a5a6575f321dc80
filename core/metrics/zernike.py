"""Zernike polynomials over the unit disk: radial part by Jacobi polynomials, three orderings.

Why our own numpy implementation: prysm's last PyPI release dates from 2022 and hcipy is sized for
astronomy (and brings its own field machinery); what we need is ~60 lines tested below against the
standard's fixed points (tests/test_metrics.py).

Definitions (Noll 1976, J. Opt. Soc. Am. 66, 207; ANSI Z80.28-2017):

    Z_n^m(ρ, θ) = N_n^m R_n^|m|(ρ) · { cos(mθ)  m ≥ 0 ;  sin(|m|θ)  m < 0 }
    R_n^m(ρ)    = ρ^m P_k^(0, m)(2ρ² − 1),   k = (n − m)/2          (Jacobi polynomial P_k^(α, β))
    N_n^m       = sqrt(2(n + 1) / (1 + δ_m0))                        ("rms" normalisation)

so that (1/π) ∬_disk Z_i Z_j = δ_ij: a coefficient is the RMS its term contributes. With
``normalization="peak"`` N = 1 (each term peaks at ±1 on the edge, the traditional Fringe usage).

Orderings (single index j of a pair (n, m)):
    ANSI/OSA  j = (n(n + 2) + m) / 2, from 0                   (ANSI 12 → (4, 0))
    Noll      from 1, |m| ascending within n, even j cos / odd j sin   (Noll 4 → (2, 0), 11 → (4, 0))
    Fringe    j = (1 + (n + |m|)/2)² − 2|m| + [m < 0], from 1  (Fringe 9 → (4, 0); Z1…Z36 are the
              classical set; beyond, the formula continues ((6, 6) is 37), not Code V's Z37 = (12, 0))
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.special import eval_jacobi

Ordering = Literal["ansi", "noll", "fringe"]
ORDERINGS = ("ansi", "noll", "fringe")

#: optician's names of the low-order terms → (n, m) pairs they cover
TERM_NAMES: dict[str, tuple[tuple[int, int], ...]] = {
    "piston": ((0, 0),),
    "tilt": ((1, 1), (1, -1)),
    "power": ((2, 0),),
    "defocus": ((2, 0),),
    "astigmatism": ((2, 2), (2, -2)),
    "coma": ((3, 1), (3, -1)),
    "trefoil": ((3, 3), (3, -3)),
    "spherical": ((4, 0),),
}


def first_index(ordering: Ordering) -> int:
    return 0 if ordering == "ansi" else 1


def index_of(n: int, m: int, ordering: Ordering) -> int:
    """The single index j of (n, m) in ``ordering``."""
    _check_nm(n, m)
    if ordering == "ansi":
        return (n * (n + 2) + m) // 2
    if ordering == "fringe":
        return (1 + (n + abs(m)) // 2) ** 2 - 2 * abs(m) + (1 if m < 0 else 0)
    if ordering == "noll":
        # terms of lower radial order come first: n(n+1)/2 of them
        j0 = n * (n + 1) // 2
        ms = sorted({abs(mm) for mm in range(-n, n + 1, 2)})
        # positions within order n: pairs (|m|, two slots) in ascending |m|; m = 0 takes one slot
        pos = 0
        for am in ms:
            if am == abs(m):
                break
            pos += 1 if am == 0 else 2
        if m == 0:
            return j0 + pos + 1
        j = j0 + pos + 1  # first of the two slots
        want_even = m > 0  # Noll: even j ↔ cos (m > 0), odd j ↔ sin (m < 0)
        if (j % 2 == 0) != want_even:
            j += 1
        return j
    raise ValueError(f"unknown ordering {ordering!r}; use one of {', '.join(ORDERINGS)}")


def nm_of(j: int, ordering: Ordering) -> tuple[int, int]:
    """(n, m) of index j in ``ordering``."""
    if j < first_index(ordering):
        raise ValueError(f"{ordering} indices start at {first_index(ordering)}, got {j}")
    n = 0
    while True:
        for m in range(-n, n + 1, 2):
            if index_of(n, m, ordering) == j:
                return n, m
        # Fringe indices of order n+|m| ≤ 2s lie below (s+2)²; no pair of n > 2√j can hold j
        n += 1
        if n > 4 * int(np.sqrt(j)) + 4:
            raise ValueError(f"no Zernike term has {ordering} index {j}")


def terms(count: int, ordering: Ordering) -> list[tuple[int, int]]:
    """The first ``count`` (n, m) pairs in ``ordering``."""
    start = first_index(ordering)
    return [nm_of(j, ordering) for j in range(start, start + count)]


def _check_nm(n: int, m: int) -> None:
    if n < 0 or abs(m) > n or (n - m) % 2:
        raise ValueError(f"(n={n}, m={m}) is not a Zernike term (need |m| ≤ n, n − m even)")


def radial(n: int, m: int, rho) -> np.ndarray:
    """R_n^|m|(ρ) = ρ^|m| P_k^(0,|m|)(2ρ² − 1), k = (n − |m|)/2."""
    _check_nm(n, m)
    am = abs(m)
    rho = np.asarray(rho, dtype=np.float64)
    return rho**am * eval_jacobi((n - am) // 2, 0.0, float(am), 2.0 * rho * rho - 1.0)


def norm(n: int, m: int, normalization: str = "rms") -> float:
    if normalization == "peak":
        return 1.0
    return float(np.sqrt(2.0 * (n + 1) / (1.0 + (m == 0))))


def zernike(n: int, m: int, rho, theta, normalization: str = "rms") -> np.ndarray:
    """Z_n^m at polar coordinates (ρ ≤ 1 on the disk, θ in rad)."""
    ang = np.cos(m * np.asarray(theta)) if m >= 0 else np.sin(-m * np.asarray(theta))
    return norm(n, m, normalization) * radial(n, m, rho) * ang


def name_of(n: int, m: int) -> str:
    for name, pairs in TERM_NAMES.items():
        if (n, m) in pairs and name != "defocus":
            suffix = "" if len(pairs) == 1 else (" x" if m > 0 else " y")
            return name + suffix
    return f"Z({n},{m})"


def design_matrix(x, y, radius: float, pairs, normalization: str = "rms",
                  center=(0.0, 0.0)) -> np.ndarray:
    """(N, len(pairs)) values of the terms at points (x, y) (mm) normalised by ``radius`` (mm)."""
    dx = np.asarray(x, dtype=np.float64) - center[0]
    dy = np.asarray(y, dtype=np.float64) - center[1]
    rho = np.hypot(dx, dy) / radius
    theta = np.arctan2(dy, dx)
    return np.column_stack([zernike(n, m, rho, theta, normalization) for n, m in pairs]) \
        if len(pairs) else np.empty((len(dx), 0))


def fit(x, y, z, radius: float, pairs, normalization: str = "rms", center=(0.0, 0.0)):
    """Least-squares coefficients (same unit as z) with standard uncertainties and the residual.

    On a discrete, possibly irregular sampling the terms are not exactly orthogonal, so all are fitted
    together (not by projection). Uncertainty: σ² (AᵀA)⁻¹ with σ² = SSR / (N − p)."""
    A = design_matrix(x, y, radius, pairs, normalization, center)
    z = np.asarray(z, dtype=np.float64)
    npts, p = A.shape
    if npts < p:
        raise ValueError(f"{npts} points cannot determine {p} Zernike terms")
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    resid = z - A @ coef
    dof = max(npts - p, 1)
    s2 = float(resid @ resid) / dof
    cov = np.linalg.pinv(A.T @ A) * s2
    cond = float(np.linalg.cond(A)) if p else 1.0
    return coef, np.sqrt(np.clip(np.diag(cov), 0, None)), resid, A, cond
