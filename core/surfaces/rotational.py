"""Surfaces of revolution z = f(r): what follows from the radial profile alone.

A subclass gives the profile f(r) (``sag_r``), its slope over r, g(r) = f'(r)/r (``slope_over_r``,
finite on the axis) and f''(r) (``curvature_r``); this class turns them into the gradient, the
principal curvatures (probe-radius compensation) and the exact foot point (1-D Newton in the
meridian plane).
"""
from __future__ import annotations

from abc import abstractmethod

import numpy as np

from .base import NominalSurface


class SurfaceOfRevolution(NominalSurface):
    @abstractmethod
    def sag_r(self, r) -> np.ndarray:
        """f(r) (mm)."""

    @abstractmethod
    def slope_over_r(self, r) -> np.ndarray:
        """g(r) = f'(r) / r (1/mm), finite on the axis."""

    @abstractmethod
    def curvature_r(self, r) -> np.ndarray:
        """f''(r) (1/mm)."""

    def sag(self, x, y) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        return self.sag_r(np.hypot(x, y))

    def slope_r(self, r) -> np.ndarray:
        """dz/dr (dimensionless)."""
        r = np.asarray(r, dtype=np.float64)
        return self.slope_over_r(r) * r

    def profile_r(self, r) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f, f', f'') at r together — what a Newton step on the profile needs. Subclasses may share
        work between the three (EvenAsphere: one square root instead of three)."""
        r = np.asarray(r, dtype=np.float64)
        return self.sag_r(r), self.slope_r(r), self.curvature_r(r)

    def principal_curvatures(self, r) -> tuple[np.ndarray, np.ndarray]:
        """(meridional, sagittal) curvatures (1/mm), positive when the centre of curvature is on +z.

        κ_m = z'' / (1 + z'²)^(3/2),  κ_s = (z'/r) / (1 + z'²)^(1/2)  (κ_s → z''(0) on the axis).
        """
        r = np.asarray(r, dtype=np.float64)
        zr = self.slope_r(r)
        w = 1.0 + zr * zr
        return self.curvature_r(r) / w ** 1.5, self.slope_over_r(r) / np.sqrt(w)

    def foot_point(self, xyz):
        """Exact foot point on the surface of revolution: a 1-D Newton solve in the meridian plane.

        For p at radius ρ_p and height z_p, the foot radius ρ makes p − foot parallel to the normal:
            h(ρ) = (ρ_p − ρ) + (z_p − z(ρ)) z'(ρ) = 0,   h'(ρ) = −1 − z'² + (z_p − z(ρ)) z''.
        Started from ρ_p − (z_p − z(ρ_p)) z'(ρ_p) / (1 + z'²); quadratic convergence to float64 in a
        few iterations. Then d = (z_p − z(ρ)) sqrt(1 + z'²) and n̂ = (−z' cos φ, −z' sin φ, 1)/sqrt(1 + z'²).
        """
        p = np.asarray(xyz, dtype=np.float64)
        rho_p = np.sqrt(p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1])
        zp = p[:, 2]
        dz = zp - self.sag_r(rho_p)
        zr = self.slope_r(rho_p)
        rho = rho_p - dz * zr / (1.0 + zr * zr)
        for _ in range(30):
            z, zr, zrr = self.profile_r(rho)
            e = zp - z
            h = (rho_p - rho) + e * zr
            dh = -1.0 - zr * zr + e * zrr
            step = h / dh
            rho = rho - step
            if np.max(np.abs(step), initial=0.0) <= 1e-15 * (1.0 + np.max(rho_p, initial=0.0)):
                break
        z = self.sag_r(rho)
        zr = self.slope_r(rho)
        w = np.sqrt(1.0 + zr * zr)
        with np.errstate(invalid="ignore", divide="ignore"):
            cphi = np.where(rho_p > 0, p[:, 0] / rho_p, 1.0)
            sphi = np.where(rho_p > 0, p[:, 1] / rho_p, 0.0)
        n = np.empty((len(rho), 3))
        np.multiply(-zr / w, cphi, out=n[:, 0])
        np.multiply(-zr / w, sphi, out=n[:, 1])
        np.divide(1.0, w, out=n[:, 2])
        foot = np.empty((len(rho), 3))
        np.multiply(rho, cphi, out=foot[:, 0])
        np.multiply(rho, sphi, out=foot[:, 1])
        foot[:, 2] = z
        return foot, n, (zp - z) * w

    def gradient(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        g = self.slope_over_r(np.hypot(x, y))
        return g * x, g * y

