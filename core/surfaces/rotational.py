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

_CHUNK = 1 << 14  # points per Newton chunk: its dozen temporaries stay in the L2 cache


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
        Started from ρ_p + (z_p − z(ρ_p)) z'(ρ_p) / (1 + z'²) (p lies at d along the normal, whose
        radial component is −z'/√(1 + z'²): the foot is *outward* of p where z' > 0); quadratic
        convergence to float64 in a few iterations. Then d = (z_p − z(ρ)) sqrt(1 + z'²) and
        n̂ = (−z' cos φ, −z' sin φ, 1)/sqrt(1 + z'²).
        """
        return self.foot_point_warm(xyz)[:3]

    def foot_point_warm(self, xyz, shift=None):
        """`foot_point` and the foot shifts ρ_p − ρ, optionally started from ``shift`` — the shifts of a
        previous solve of the same points at a nearby pose (an LM step moves a point by µm; its shift,
        d·z'/√(1 + z'²), changes by d·κ times that): Newton then needs two steps instead of four.

        Returns (foot, n̂, d, shift). Each point stops when its own Newton step is below
        1e-15·(1 + max ρ_p) (≈ 6·10⁻¹³ mm at ρ 650 mm: rounding), its profile values carried to the
        stepped radius to first order (the second-order term is below 10⁻²⁰ mm); the points are solved
        in cache-sized chunks. The same foot points as a cold start to rounding (≤ 10⁻¹⁵ relative).
        """
        p = np.asarray(xyz, dtype=np.float64)
        m = len(p)
        rho_p = np.sqrt(p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1])
        tol = 1e-15 * (1.0 + np.max(rho_p, initial=0.0))
        foot, n, dist, out_shift = np.empty((m, 3)), np.empty((m, 3)), np.empty(m), np.empty(m)
        for s in range(0, m, _CHUNK):
            c = slice(s, min(s + _CHUNK, m))
            rp, px, py, zp = rho_p[c], p[c, 0], p[c, 1], p[c, 2]
            rho, z, zr = self._newton(rp, zp, None if shift is None else shift[c], tol)
            w = np.sqrt(1.0 + zr * zr)
            with np.errstate(invalid="ignore", divide="ignore"):
                cphi = np.where(rp > 0, px / rp, 1.0)
                sphi = np.where(rp > 0, py / rp, 0.0)
            np.divide(1.0, w, out=n[c, 2])
            iw = -zr / w
            np.multiply(iw, cphi, out=n[c, 0])
            np.multiply(iw, sphi, out=n[c, 1])
            np.multiply(rho, cphi, out=foot[c, 0])
            np.multiply(rho, sphi, out=foot[c, 1])
            foot[c, 2] = z
            np.multiply(zp - z, w, out=dist[c])
            np.subtract(rp, rho, out=out_shift[c])
        return foot, n, dist, out_shift

    def _newton(self, rho_p, zp, shift, tol):
        """ρ, z(ρ), z'(ρ) of one chunk's foot points.

        A conic exists only out to r_max (its slope turns vertical there). A point beyond it — the
        ball centre over a steep convex dome: R −10 mm, 1 mm ball, 70° slopes put centres at r 10.36
        mm — starts from 0.98 r_max, and no Newton step leaves the domain (clipped just inside it):
        the foot lies on the surface, inside. Elsewhere the iterates are those of before. A point
        beyond 2 r_max, or a foot held at the edge, is the conic's DomainError as before (data in µm
        read as mm, a wrong c)."""
        r_max = float(getattr(self, "r_max", np.inf))
        inside = r_max * (1.0 - 1e-12) if np.isfinite(r_max) else None
        rho_p0 = rho_p
        if inside is not None and (rho_p > 2.0 * r_max).any():  # no ball centre lies that far out
            self.sag_r(rho_p[rho_p > 2.0 * r_max])  # the conic's DomainError (µm read as mm, wrong c)
        if shift is None:
            r0 = rho_p if inside is None or not (rho_p >= 0.98 * r_max).any() \
                else np.minimum(rho_p, 0.98 * r_max)
            dz = zp - self.sag_r(r0)
            zr = self.slope_r(r0)
            rho = r0 + dz * zr / (1.0 + zr * zr)
        else:
            rho = rho_p - shift
        if inside is not None and (rho > inside).any():
            rho = np.minimum(rho, inside)
        k = len(rho)
        rho_out, z_out, zr_out = np.empty(k), np.empty(k), np.empty(k)
        act = None  # indices still iterating (None: all of the chunk)
        for _ in range(30):
            z, zr, zrr = self.profile_r(rho)
            e = zp - z
            h = (rho_p - rho) + e * zr
            dh = -1.0 - zr * zr + e * zrr
            step = h / dh
            rho = rho - step
            if inside is not None and (rho > inside).any():  # never past the domain's edge
                over = rho > inside
                step = np.where(over, rho - inside + step, step)  # the step actually taken
                rho = np.minimum(rho, inside)
            z -= zr * step  # z and z' at the stepped radius, to first order in the step
            zr -= zrr * step
            done = np.abs(step) <= tol
            if act is None and done.all():
                return self._inside_domain(rho, rho_p0, inside), z, zr
            fin = np.flatnonzero(done) if act is None else act[done]
            rho_out[fin], z_out[fin], zr_out[fin] = rho[done], z[done], zr[done]
            if fin.size == (k if act is None else act.size):
                return self._inside_domain(rho_out, rho_p0, inside), z_out, zr_out
            keep = ~done
            act = np.flatnonzero(keep) if act is None else act[keep]
            rho, rho_p, zp = rho[keep], rho_p[keep], zp[keep]
        # not converged in 30 steps (as before: the last iterate stands)
        z, zr, _ = self.profile_r(rho)
        sel = slice(None) if act is None else act
        rho_out[sel], z_out[sel], zr_out[sel] = rho, z, zr
        return self._inside_domain(rho_out, rho_p0, inside), z_out, zr_out

    def _inside_domain(self, rho, rho_p, inside):
        """``rho`` when no foot ended on the domain's edge: a foot held there by the clip is no foot
        point (data far outside the conic: µm read as mm, a wrong c) — the conic's own DomainError,
        naming those points' radii, as before the clip."""
        if inside is not None and (rho >= inside).any():
            self.sag_r(np.array([max(float(rho_p[rho >= inside].max()), 2.0 * inside)]))
        return rho

    def gradient(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        g = self.slope_over_r(np.hypot(x, y))
        return g * x, g * y

