"""Forbes' Q polynomial aspheres: Q-con and Q-bfs (rotationally symmetric).

Q-con (Forbes, "Shape specification for axially symmetric optical surfaces", Opt. Express 15, 5218,
2007, eq. 2.2):
    z(r) = c r² / (1 + sqrt(1 − (1+k) c² r²)) + u⁴ Σ_m a_m Q_m^con(u²),   u = r / r_n,
    Q_m^con(v) = P_m^(0,4)(2v − 1)                       (Jacobi; scipy.special.eval_jacobi)
Q-bfs (same paper eq. 3.1; the recurrence of Forbes, Opt. Express 18, 19700, 2010, eqs. 2.6, A.14–A.16):
    z(r) = c r² / (1 + sqrt(1 − c² r²)) + u²(1 − u²) / sqrt(1 − c² r²) · Σ_m a_m Q_m^bfs(u²)
    P_0 = 2, P_1 = 6 − 8v, P_n = (2 − 4v) P_{n−1} − P_{n−2}
    Q_0 = 1, Q_1 = (13 − 16v)/√19, Q_n = (P_n − g_{n−1} Q_{n−1} − h_{n−2} Q_{n−2}) / f_n
    f_0 = 2, f_1 = √19/2, h_{n−2} = −n(n−1)/(2 f_{n−2}), g_{n−1} = −(1 + g_{n−2} h_{n−2}) / f_{n−1},
    f_n = sqrt(n(n+1) + 3 − g_{n−1}² − h_{n−2}²),  g_0 = −1/2.
The Q^bfs are slope-orthonormal: (2/π)∫₀¹ S_m'(u) S_n'(u) du / sqrt(1 − u²) = δ_mn with
S_m(u) = u²(1 − u²) Q_m(u²) (tested), so a_m is the RMS slope its term adds (times r_n).
Coefficients a_m in mm. Derivatives in v are carried through the same recurrences, so slopes and
curvatures are exact to rounding (needed by probe-radius compensation and the foot point).
"""
from __future__ import annotations

import numpy as np

from ..errors import DomainError
from .even_asphere import EvenAsphere
from .rotational import SurfaceOfRevolution


def qcon_series(a, v):
    """(Σ, dΣ/dv, d²Σ/dv²) of Σ a_m P_m^(0,4)(2v − 1); d/dt P_n^(α,β) = (n+α+β+1)/2 P_{n−1}^(α+1,β+1)."""
    from scipy.special import eval_jacobi  # lazy: 0.85 s of every batch's start (issue 17)

    t = 2.0 * v - 1.0
    s, s1, s2 = np.zeros_like(v), np.zeros_like(v), np.zeros_like(v)
    for m, am in enumerate(a):
        if am == 0.0:
            continue
        s += am * eval_jacobi(m, 0.0, 4.0, t)
        if m >= 1:
            s1 += am * (m + 5) * eval_jacobi(m - 1, 1.0, 5.0, t)
        if m >= 2:
            s2 += am * (m + 5) * (m + 6) * eval_jacobi(m - 2, 2.0, 6.0, t)
    return s, s1, s2


def qbfs_fgh(M: int):
    f, g, h = {0: 2.0, 1: np.sqrt(19.0) / 2.0}, {0: -0.5}, {}
    for n in range(2, M + 1):
        h[n - 2] = -n * (n - 1) / (2.0 * f[n - 2])
        g[n - 1] = -(1.0 + g[n - 2] * h[n - 2]) / f[n - 1]
        f[n] = np.sqrt(n * (n + 1) + 3.0 - g[n - 1] ** 2 - h[n - 2] ** 2)
    return f, g, h


def qbfs_polynomials(M: int, v):
    """[(Q_m, Q_m', Q_m'')] for m = 0..M at v = u² (derivatives in v)."""
    v = np.asarray(v, dtype=np.float64)
    one, zero = np.ones_like(v), np.zeros_like(v)
    out = [(one, zero, zero)]
    if M >= 1:
        out.append(((13.0 - 16.0 * v) / np.sqrt(19.0), np.full_like(v, -16.0 / np.sqrt(19.0)), zero))
    if M < 2:
        return out[: M + 1]
    f, g, h = qbfs_fgh(M)
    P = [(2.0 * one, zero, zero), (6.0 - 8.0 * v, np.full_like(v, -8.0), zero)]
    c = 2.0 - 4.0 * v
    for n in range(2, M + 1):
        (p1, d1, e1), (p2, d2, e2) = P[-1], P[-2]
        P.append((c * p1 - p2, -4.0 * p1 + c * d1 - d2, -8.0 * d1 + c * e1 - e2))
        (q1, q1d, q1e), (q2, q2d, q2e) = out[-1], out[-2]
        pn = P[-1]
        out.append(tuple((pn[i] - g[n - 1] * (q1, q1d, q1e)[i] - h[n - 2] * (q2, q2d, q2e)[i]) / f[n]
                         for i in range(3)))
    return out


class _QSurface(SurfaceOfRevolution):
    def __init__(self, c, k, a, norm_radius, aperture=None):
        if not norm_radius > 0:
            raise ValueError("norm_radius must be > 0")
        self.c, self.k = float(c), float(k)
        self.a = [float(x) for x in a]
        self.rn = float(norm_radius)
        self.aperture = None if aperture is None else float(aperture)
        self._base = EvenAsphere(self.c, self.k)

    @property
    def radius(self) -> float:
        return np.inf if self.c == 0 else 1.0 / self.c

    def sag_r(self, r):
        r = np.asarray(r, dtype=np.float64)
        return self._base.sag_r(r) + self._departure(r)[0]

    def slope_over_r(self, r):
        r = np.asarray(r, dtype=np.float64)
        return self._base.slope_over_r(r) + self._departure(r)[1]

    def curvature_r(self, r):
        r = np.asarray(r, dtype=np.float64)
        return self._base.curvature_r(r) + self._departure(r)[2]

    def describe(self) -> dict:
        d = {"type": self.kind, "c": self.c, "R": self.radius, "norm_radius": self.rn, "a": self.a}
        if self.kind == "qcon":
            d["k"] = self.k
        if self.aperture is not None:
            d["aperture"] = self.aperture
        return d


class QConAsphere(_QSurface):
    kind = "qcon"

    def __init__(self, c, k, a, norm_radius, aperture=None):
        super().__init__(c, k, a, norm_radius, aperture)

    def _departure(self, r):
        """(T, T'/r, T'') of T = v² Σ(v), v = r²/r_n²."""
        q = 1.0 / (self.rn * self.rn)
        v = r * r * q
        s, s1, s2 = qcon_series(self.a, v)
        G = 2.0 * v * s + v * v * s1                     # dT/dv
        G1 = 2.0 * s + 4.0 * v * s1 + v * v * s2          # d²T/dv²
        return v * v * s, 2.0 * q * G, G1 * (2.0 * r * q) ** 2 + 2.0 * q * G


class QBfsAsphere(_QSurface):
    kind = "qbfs"

    def __init__(self, c, a, norm_radius, aperture=None):
        super().__init__(c, 0.0, a, norm_radius, aperture)

    def _departure(self, r):
        """(D, D'/r, D'') of D = A(v)/φ(r), A = v(1 − v) Σ a_m Q_m(v), φ = sqrt(1 − c²r²)."""
        q = 1.0 / (self.rn * self.rn)
        v = r * r * q
        c2 = self.c * self.c
        arg = 1.0 - c2 * r * r
        if np.any(arg <= 0):
            raise DomainError(f"Q-bfs surface (R = {self.radius:.6g} mm): points beyond |R| where "
                              "the best-fit sphere does not exist")
        phi = np.sqrt(arg)
        s = s1 = s2 = 0.0
        for am, (Q, Qd, Qdd) in zip(self.a, qbfs_polynomials(len(self.a) - 1, v) if self.a else []):
            s = s + am * Q
            s1 = s1 + am * Qd
            s2 = s2 + am * Qdd
        s, s1, s2 = (np.broadcast_to(np.asarray(t, dtype=np.float64), v.shape) for t in (s, s1, s2))
        A = v * (1 - v) * s
        A1 = (1 - 2 * v) * s + v * (1 - v) * s1
        A2 = -2 * s + 2 * (1 - 2 * v) * s1 + v * (1 - v) * s2
        vr = 2.0 * r * q
        dphi = -c2 * r / phi
        ddphi = -c2 / phi**3
        D = A / phi
        g = A1 * 2.0 * q / phi + A * c2 / phi**3
        D2 = (A2 * vr * vr / phi + A1 * 2.0 * q / phi - 2.0 * A1 * vr * dphi / phi**2
              - A * ddphi / phi**2 + 2.0 * A * dphi**2 / phi**3)
        return D, g, D2
