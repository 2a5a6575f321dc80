"""Even asphere (ISO 10110-12; paper 002 eq 1; DESIGN "Conventions").

    z(r) = c r² / (1 + sqrt(1 − (1+k) c² r²)) + Σ_n A_n rⁿ,     r² = x² + y²,  c = 1/R.

The first term is written in the rationalised form above (not R − sqrt(R² − r²)), which has no
cancellation near the vertex, so it is exact to float64 at every r. Its radial slope is

    dz/dr = c r / sqrt(1 − (1+k) c² r²) + Σ_n n A_n r^(n−1),

and we evaluate g(r) = (dz/dr)/r = c / sqrt(...) + Σ n A_n r^(n−2) so that ∂z/∂x = g·x, ∂z/∂y = g·y
stay exact (and zero) on the axis. The domain is (1+k) c² r² ≤ 1; beyond it the conic does not exist
and we raise DomainError naming how many points and the largest admissible radius.
"""
from __future__ import annotations

import numpy as np

from ..errors import DomainError
from .base import NominalSurface


class EvenAsphere(NominalSurface):
    kind = "even_asphere"

    def __init__(self, c: float, k: float = 0.0, A: dict[int, float] | None = None,
                 aperture: float | None = None):
        self.c = float(c)
        self.k = float(k)
        self.A = {int(n): float(a) for n, a in (A or {}).items() if a != 0.0}
        for n in self.A:
            if n < 2:
                raise ValueError(f"asphere coefficient A{n}: powers start at 2")
        self.aperture = None if aperture is None else float(aperture)

    @property
    def radius(self) -> float:
        """Vertex radius R = 1/c (mm); inf for a flat."""
        return np.inf if self.c == 0 else 1.0 / self.c

    @property
    def r_max(self) -> float:
        """Largest radius where the conic exists (mm)."""
        q = (1.0 + self.k) * self.c * self.c
        return np.inf if q <= 0 else 1.0 / np.sqrt(q)

    def _root(self, r2: np.ndarray) -> np.ndarray:
        arg = 1.0 - (1.0 + self.k) * self.c * self.c * r2
        bad = arg < 0
        if np.any(bad):
            rb = np.sqrt(r2[bad])
            raise DomainError(
                f"even asphere (R = {self.radius:.6g} mm, k = {self.k:.6g}): {int(bad.sum())} point(s) "
                f"at r up to {rb.max():.6g} mm lie outside the conic's domain r ≤ {self.r_max:.6g} mm "
                "(the square root turns negative) — check the surface's c/k and the data's units/frame")
        return np.sqrt(arg)

    def sag_r(self, r) -> np.ndarray:
        r = np.asarray(r, dtype=np.float64)
        r2 = r * r
        z = self.c * r2 / (1.0 + self._root(r2))
        for n, a in self.A.items():
            z = z + a * r ** n
        return z

    def sag(self, x, y) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        return self.sag_r(np.hypot(x, y))

    def slope_over_r(self, r) -> np.ndarray:
        """g(r) = (dz/dr) / r (1/mm), finite on the axis."""
        r = np.asarray(r, dtype=np.float64)
        r2 = r * r
        g = self.c / self._root(r2)
        for n, a in self.A.items():
            g = g + n * a * r ** (n - 2)
        return g

    def slope_r(self, r) -> np.ndarray:
        """dz/dr (dimensionless)."""
        r = np.asarray(r, dtype=np.float64)
        return self.slope_over_r(r) * r

    def gradient(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        g = self.slope_over_r(np.hypot(x, y))
        return g * x, g * y

    def describe(self) -> dict:
        d = {"type": self.kind, "c": self.c, "R": self.radius, "k": self.k,
             "A": {str(n): a for n, a in sorted(self.A.items())}}
        if self.aperture is not None:
            d["aperture"] = self.aperture
        return d
