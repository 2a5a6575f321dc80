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

from dataclasses import dataclass
from typing import Literal

import numpy as np

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
    from scipy.special import eval_jacobi  # lazy: 0.3 s of a batch's start; the fits use zernike_rows

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


#: points per chunk: the chunk's design block, 36 rows of 2¹³ float64 (2.4 MB), stays in the
#: cache while it is built and reduced (2¹⁶ rows ran 2× slower), and memory is bounded whatever the
#: number of points (a 12.6M-point map never holds its 3.6 GB design matrix)
CHUNK = 1 << 13


def _jacobi_0b(kmax: int, beta: int, t: np.ndarray) -> list[np.ndarray]:
    """[P_0, …, P_kmax] of P_k^(0, β)(t) by the three-term recurrence (DLMF 18.9.1 with α = 0):

        2k(k+β)(2k+β−2) P_k = (2k+β−1)[(2k+β)(2k+β−2) t − β²] P_{k−1} − 2(k−1)(k+β−1)(2k+β) P_{k−2},
        P_0 = 1,  P_1 = 1 + (β+2)(t−1)/2."""
    out = [np.ones_like(t)]
    if kmax >= 1:
        out.append(1.0 + 0.5 * (beta + 2) * (t - 1.0))
    tmp = np.empty_like(t)
    for k in range(2, kmax + 1):
        c = 2 * k + beta
        a1 = 2.0 * k * (k + beta) * (c - 2)
        # P_k = (α t + β') P_{k−1} − γ P_{k−2}, in place (no temporaries of the chunk's length)
        pk = np.multiply(t, (c - 1) * c * (c - 2) / a1)
        pk -= (c - 1) * beta * beta / a1
        pk *= out[-1]
        np.multiply(out[-2], 2.0 * (k - 1) * (k + beta - 1) * c / a1, out=tmp)
        pk -= tmp
        out.append(pk)
    return out


def _design_rows(u: np.ndarray, v: np.ndarray, pairs, normalization: str, out: np.ndarray) -> None:
    """Fill ``out`` (len(pairs), len(u)), one C-contiguous row per term, with the terms at
    normalised coordinates (u, v) = (x, y)/R.

    No arctan2, powers or trigonometry: ρ^|m| cos(mθ) + i ρ^|m| sin(mθ) = (u + iv)^|m| by repeated
    complex multiplication, and R_n^|m|(ρ)/ρ^|m| = P_k^(0,|m|)(2ρ² − 1) by the Jacobi recurrence
    (tests/test_metrics.py checks both against scipy's eval_jacobi and the closed forms). Rows, not
    columns: writing a term is one contiguous pass (a column of an (n, p) block is strided, 2× slower)."""
    t = u * u
    t += v * v
    t *= 2.0
    t -= 1.0
    mmax = max(abs(m) for _, m in pairs)
    cos_m, sin_m = [None, u], [None, v]  # ρ^m cos mθ, ρ^m sin mθ (m = 0: 1, 0)
    for _ in range(2, mmax + 1):
        c, s = cos_m[-1], sin_m[-1]
        cos_m.append(c * u - s * v)
        sin_m.append(s * u + c * v)
    kmax: dict[int, int] = {}
    for n, m in pairs:
        kmax[abs(m)] = max(kmax.get(abs(m), 0), (n - abs(m)) // 2)
    for am, km in kmax.items():
        radial_k = _jacobi_0b(km, am, t)
        for j, (n, m) in enumerate(pairs):
            if abs(m) != am:
                continue
            w = norm(n, m, normalization)
            if am == 0:
                np.multiply(radial_k[n // 2], w, out=out[j])
            else:
                np.multiply(radial_k[(n - am) // 2], cos_m[am] if m >= 0 else sin_m[am], out=out[j])
                if w != 1.0:
                    out[j] *= w


def design_matrix(x, y, radius: float, pairs, normalization: str = "rms",
                  center=(0.0, 0.0)) -> np.ndarray:
    """(N, len(pairs)) values of the terms at points (x, y) (mm) normalised by ``radius`` (mm).

    Holds N × p floats: for millions of points use ``fit`` and ``evaluate``, which work in chunks."""
    x, y = np.asarray(x), np.asarray(y)
    At = np.empty((len(pairs), len(x)))
    for s in range(0, len(x), CHUNK):
        if len(pairs):
            u, v = _normalised(x, y, center, radius, s, s + CHUNK)
            _design_rows(u, v, pairs, normalization, At[:, s:s + CHUNK])
    return At.T


def _normalised(x, y, center, radius, s: int, e: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) of points s:e: only a chunk is normalised at a time (no full-length copies)."""
    u = np.asarray(x[s:e], dtype=np.float64) - center[0]
    u /= radius
    v = np.asarray(y[s:e], dtype=np.float64) - center[1]
    v /= radius
    return u, v


def evaluate(x, y, coef, radius: float, pairs, normalization: str = "rms",
             center=(0.0, 0.0)) -> np.ndarray:
    """Σ_j coef_j Z_j(x, y), in chunks (never the whole design matrix)."""
    x, y = np.asarray(x), np.asarray(y)
    coef = np.asarray(coef, dtype=np.float64)
    out = np.zeros(len(x))
    if not len(pairs):
        return out
    block = np.empty((len(pairs), min(CHUNK, len(x))))
    for s in range(0, len(x), CHUNK):
        u, v = _normalised(x, y, center, radius, s, s + CHUNK)
        b = block[:, :len(u)]
        _design_rows(u, v, pairs, normalization, b)
        np.dot(coef, b, out=out[s:s + CHUNK])
    return out


@dataclass(frozen=True)
class ZernikeFit:
    """A least-squares Zernike fit: coefficients and standard uncertainties (unit of z), the
    residual z − fit at every point, the condition number of the design matrix."""
    coef: np.ndarray
    sd: np.ndarray
    residual: np.ndarray
    cond: float

    def __iter__(self):  # coef, sd, residual, cond = fit(...)
        return iter((self.coef, self.sd, self.residual, self.cond))


#: below this condition number of the design matrix the normal equations (one pass of BLAS
#: products) lose at most cond²·ε ≈ 2·10⁻¹⁰ relative; above it, the fit is done by QR (TSQR)
_NORMAL_EQUATIONS_MAX_COND = 1e3


def fit(x, y, z, radius: float, pairs, normalization: str = "rms", center=(0.0, 0.0)) -> ZernikeFit:
    """Least-squares coefficients (same unit as z) with standard uncertainties and the residual.

    On a discrete, possibly irregular sampling the terms are not exactly orthogonal, so all are fitted
    together (not by projection). Uncertainty: σ² (AᵀA)⁻¹ with σ² = SSR / (N − p).

    Memory and time are linear in N with a p × p working set: the design matrix is built and reduced
    in chunks of CHUNK rows. Pass 1 accumulates the Gram matrix [A z]ᵀ[A z]; a well-conditioned
    pupil (a centred disk: cond ≈ 1–10) is solved from it; an ill-conditioned one (cond > 10³: the
    data in one corner of the disk) is solved by TSQR — the R factors of the chunks' QR stacked and
    factored again, R of [A z] giving Qᵀz in its last column — which is as accurate as a QR of the
    whole matrix. Pass 2 forms the residual."""
    x, y = np.asarray(x), np.asarray(y)
    z = np.asarray(z, dtype=np.float64)
    npts, p = len(z), len(pairs)
    if npts < p:
        raise ValueError(f"{npts} points cannot determine {p} Zernike terms")
    if p == 0:
        return ZernikeFit(np.zeros(0), np.zeros(0), z.copy(), 1.0)
    block = np.empty((p + 1, min(CHUNK, npts)))  # rows: the p terms, then z
    gram = np.zeros((p + 1, p + 1))
    for s in range(0, npts, CHUNK):
        u, v = _normalised(x, y, center, radius, s, s + CHUNK)
        b = block[:, :len(u)]
        _design_rows(u, v, pairs, normalization, b[:p])
        b[p] = z[s:s + CHUNK]
        gram += b @ b.T
    G = gram[:p, :p]
    scale = np.sqrt(np.diag(G))
    scale[scale == 0] = 1.0
    lam = np.linalg.eigvalsh(G / np.outer(scale, scale))
    cond_scaled = float(np.sqrt(lam[-1] / lam[0])) if lam[0] > 0 else np.inf
    if cond_scaled < _NORMAL_EQUATIONS_MAX_COND:
        Gs = G / np.outer(scale, scale)
        coef = np.linalg.solve(Gs, gram[:p, p] / scale) / scale
        ginv = np.linalg.inv(Gs) / np.outer(scale, scale)
        sv = np.sqrt(np.clip(np.linalg.eigvalsh(G), 0, None))[::-1]
    else:
        coef, ginv, sv = _fit_tsqr(x, y, z, radius, center, pairs, normalization, block)
    # the residual z − A·coef in place, chunk by chunk (pass 2)
    resid = z.copy()
    for s in range(0, npts, CHUNK):
        u, v = _normalised(x, y, center, radius, s, s + CHUNK)
        b = block[:p, :len(u)]
        _design_rows(u, v, pairs, normalization, b)
        resid[s:s + CHUNK] -= coef @ b
    dof = max(npts - p, 1)
    s2 = float(resid @ resid) / dof
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    return ZernikeFit(coef, np.sqrt(np.clip(np.diag(ginv) * s2, 0, None)), resid, cond)


def _fit_tsqr(x, y, z, radius, center, pairs, normalization, block):
    """(coef, (AᵀA)⁺, singular values of A) by a tall-skinny QR of [A z] over chunks."""
    p = len(pairs)
    rs = []
    for s in range(0, len(z), CHUNK):
        u, v = _normalised(x, y, center, radius, s, s + CHUNK)
        b = block[:, :len(u)]
        _design_rows(u, v, pairs, normalization, b[:p])
        b[p] = z[s:s + CHUNK]
        rs.append(np.linalg.qr(b.T, mode="r"))
        if len(rs) >= 64:  # bound the stack: 64 R factors of (p+1)² are reduced to one
            rs = [np.linalg.qr(np.vstack(rs), mode="r")]
    r = np.linalg.qr(np.vstack(rs), mode="r")
    R, qz = r[:p, :p], r[:p, p]
    coef, _, _, sv = np.linalg.lstsq(R, qz, rcond=None)  # the singular values of R are those of A
    rinv = np.linalg.pinv(R)
    return coef, rinv @ rinv.T, sv
