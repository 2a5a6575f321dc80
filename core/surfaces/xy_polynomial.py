"""XY-polynomial freeform: a conic base plus a polynomial in normalised x and y.

    z(x, y) = c r² / (1 + sqrt(1 − (1+k) c² r²)) + Σ_{i,j} C_ij (x/ρ)^i (y/ρ)^j

as in the "XY polynomial"/"extended polynomial" surfaces of optical design programs (ρ the
normalisation radius, 1 mm by default so that C_ij are in mm^(1−i−j)). The conic part is the even
asphere's, with the same domain check.
"""
from __future__ import annotations

import numpy as np

from .base import NominalSurface
from .even_asphere import EvenAsphere


class XYPolynomial(NominalSurface):
    kind = "xy_polynomial"

    def __init__(self, terms: dict[tuple[int, int], float], c: float = 0.0, k: float = 0.0,
                 norm_radius: float = 1.0, aperture: float | None = None):
        self.base = EvenAsphere(c, k)
        self.terms = {(int(i), int(j)): float(v) for (i, j), v in terms.items() if v != 0.0}
        self.norm_radius = float(norm_radius)
        if self.norm_radius <= 0:
            raise ValueError("norm_radius must be > 0")
        self.aperture = None if aperture is None else float(aperture)

    def is_flat(self) -> bool:
        """A plane: no base curvature and only terms of degree ≤ 1 (a tilted plane)."""
        return self.base.is_flat() and all(i + j <= 1 for i, j in self.terms)

    def sag(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        z = self.base.sag(x, y)
        u, v = x / self.norm_radius, y / self.norm_radius
        for (i, j), cij in self.terms.items():
            z = z + cij * u ** i * v ** j
        return z

    def gradient(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        fx, fy = self.base.gradient(x, y)
        u, v = x / self.norm_radius, y / self.norm_radius
        s = 1.0 / self.norm_radius
        for (i, j), cij in self.terms.items():
            if i:
                fx = fx + cij * i * u ** (i - 1) * v ** j * s
            if j:
                fy = fy + cij * j * u ** i * v ** (j - 1) * s
        return fx, fy

    def describe(self) -> dict:
        d = {"type": self.kind, "c": self.base.c, "k": self.base.k, "norm_radius": self.norm_radius,
             "terms": {f"x{i}y{j}": v for (i, j), v in sorted(self.terms.items())}}
        if self.aperture is not None:
            d["aperture"] = self.aperture
        return d
