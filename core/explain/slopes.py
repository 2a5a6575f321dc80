"""Slopes of a simulated cloud, for the signatures that need them (probe_radius, pose) when `explain`
compares with a simulated file instead of a model.

The probe_radius signature ρ(√(1 + f_x² + f_y²) − 1) changes by ρ(f_x δf_x + f_y δf_y) when the
slopes are off by δ: for ρ = 0.5 mm on a slope of 0.1, a slope error of 1e-5 is 0.5 nm — a bias that
300,000 points see against nm noise. A smoothing spline through the cloud (knots at the scan's pitch,
its penalty pulling towards a plane) leaves slope errors of ~2e-5 RMS on an asphere; an optical
surface is smooth over the aperture, so the slopes come from a global least-squares polynomial instead
(Legendre products of total degree D in x, y scaled to [−1, 1]; D = 2…16 by BIC), and only what the
polynomial leaves above the noise is taken up by a smoothing spline. On the surfaces of the tests the
slope error is ~1e-7 (a probe_radius signature right to 0.01 nm). The same fit gives the simulation's
heights and slopes at other positions than its own (smooth_fit; `explain --simulated` on a
measurement taken elsewhere: core.explain.workflow.simulated_heights).
"""
from __future__ import annotations

import numpy as np

DEGREES = range(2, 17, 2)
CHUNK = 50_000


def _terms(D: int) -> list[tuple[int, int]]:
    """(i, j) of the products P_i(u) P_j(v), ordered by total degree so that a lower degree is a prefix."""
    return [(i, d - i) for d in range(D + 1) for i in range(d + 1)]


def _basis(u, v, D, deriv=None):
    """Columns P_i(u)P_j(v) for _terms(D); deriv 'u' or 'v' for their derivatives."""
    from numpy.polynomial import legendre as L

    Pu, Pv = L.legvander(u, D), L.legvander(v, D)
    if deriv == "u":
        Pu = np.column_stack([L.legval(u, L.legder(np.eye(D + 1)[i])) if i else np.zeros_like(u)
                              for i in range(D + 1)])
    elif deriv == "v":
        Pv = np.column_stack([L.legval(v, L.legder(np.eye(D + 1)[j])) if j else np.zeros_like(v)
                              for j in range(D + 1)])
    return np.column_stack([Pu[:, i] * Pv[:, j] for i, j in _terms(D)])


class SmoothFit:
    """The smooth surface through a cloud (smooth_fit): the polynomial, plus the spline of its rest
    when one was needed; values and first derivatives at any points (mm)."""

    def __init__(self, cx, cy, s, D, coef, spline=None):
        self.cx, self.cy, self.s, self.D, self.coef, self.spline = cx, cy, s, D, coef, spline

    def __call__(self, x, y, dx: int = 0, dy: int = 0) -> np.ndarray:
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        u, v = (x - self.cx) / self.s, (y - self.cy) / self.s
        deriv = "u" if dx else "v" if dy else None
        out = np.concatenate([_basis(u[a:a + CHUNK], v[a:a + CHUNK], self.D, deriv) @ self.coef
                              for a in range(0, x.size, CHUNK)] or [np.zeros(0)])
        if deriv:
            out = out / self.s
        if self.spline is not None:
            out = out + self.spline(x, y, dx=dx, dy=dy)
        return out


def smooth_fit(x, y, z, order=None) -> tuple[SmoothFit, dict]:
    """The smooth surface through a cloud (module doc) and how it was found: the degree, the RMS the
    polynomial leaves, the noise σ of that rest along ``order`` (the scan), and whether a spline took
    up a rest above the noise."""
    from .select import noise_sigma

    x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
    n = z.size
    cx, cy = 0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())
    s = 0.5 * max(np.ptp(x), np.ptp(y)) or 1.0
    u, v = (x - cx) / s, (y - cy) / s
    Dmax = max(d for d in DEGREES if len(_terms(d)) <= max(n // 4, 6)) if n >= 24 else 1
    P = len(_terms(Dmax))
    G, b = np.zeros((P, P)), np.zeros(P)
    for a in range(0, n, CHUNK):
        V = _basis(u[a:a + CHUNK], v[a:a + CHUNK], Dmax)
        G += V.T @ V
        b += V.T @ z[a:a + CHUNK]
    best = None
    for D in [d for d in DEGREES if d <= Dmax] or [Dmax]:
        k = len(_terms(D))
        coef = np.linalg.lstsq(G[:k, :k], b[:k], rcond=1e-13)[0]
        rest = np.concatenate([z[a:a + CHUNK] - _basis(u[a:a + CHUNK], v[a:a + CHUNK], D) @ coef
                               for a in range(0, n, CHUNK)])
        ssr = max(float(rest @ rest), 1e-300)
        bic = n * np.log(ssr / n) + k * np.log(n)
        if best is None or bic < best[0]:
            best = (bic, D, coef, rest)
    _, D, coef, rest = best
    rms = float(np.sqrt(np.mean(rest * rest)))
    sigma = noise_sigma(rest if order is None else rest[order])
    spline = rms > 1.5 * sigma and n >= 16
    sp = None
    if spline:
        from ..maps.bspline import fit_bspline

        sp = fit_bspline(x, y, rest)
    return SmoothFit(cx, cy, s, D, coef, sp), {"degree": D, "rest_rms_um": rms * 1e3, "noise_um": sigma * 1e3,
                                               "spline": bool(spline)}


def cloud_slopes(x, y, z, order=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """∂z/∂x and ∂z/∂y of a smooth cloud at its own points, and how they were found (smooth_fit)."""
    fit, how = smooth_fit(x, y, z, order)
    return fit(x, y, dx=1), fit(x, y, dy=1), how
