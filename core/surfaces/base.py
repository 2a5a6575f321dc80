"""What every nominal surface offers: sag, gradient, unit normal and the signed distance of points.

A nominal is a height function z = f(x, y) over its domain (all optics here are measured along z).
The unit normal is the one with positive z (docs/conventions.md "Frames and signs"):
    n̂ = (−∂f/∂x, −∂f/∂y, 1) / sqrt(1 + (∂f/∂x)² + (∂f/∂y)²).
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class NominalSurface(ABC):
    """A design surface z = f(x, y) in its own (part) frame; lengths in mm."""

    kind: str = "surface"
    #: clear-aperture diameter (mm) or None when the design does not say
    aperture: float | None = None

    def is_flat(self) -> bool:
        """True for a plane z = 0: no axis, no curvature (its pose has only tilt and height)."""
        return False

    @abstractmethod
    def sag(self, x, y) -> np.ndarray:
        """Height f(x, y) in mm. Raises DomainError for points outside the surface's domain."""

    @abstractmethod
    def gradient(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(∂f/∂x, ∂f/∂y), dimensionless."""

    def normal(self, x, y) -> np.ndarray:
        """(N, 3) unit normals with positive z."""
        fx, fy = self.gradient(x, y)
        inv = 1.0 / np.sqrt(1.0 + fx * fx + fy * fy)
        return np.column_stack([-fx * inv, -fy * inv, inv])

    def vertical_residual(self, xyz) -> np.ndarray:
        """z − f(x, y): the residual PointsPro reports after misalignment (mm)."""
        xyz = np.asarray(xyz, dtype=np.float64)
        return xyz[:, 2] - self.sag(xyz[:, 0], xyz[:, 1])

    def foot_point(self, xyz) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(foot points (N,3), unit normals there (N,3), signed orthogonal distances (N,)).

        The foot is the surface point nearest to p, so p = foot + d·n̂(foot); d > 0 on the +z side.
        Generic version: a fixed point on the foot, foot = p − d n̂(foot), d = (p − foot)·n̂(foot),
        started from the vertical projection; it converges when |d| is well below the radius of
        curvature (as for probe balls and form errors). Surfaces of revolution override this with an
        exact 1-D Newton solve.
        """
        p = np.asarray(xyz, dtype=np.float64)
        n = self.normal(p[:, 0], p[:, 1])
        dist = self.vertical_residual(p) * n[:, 2]
        for _ in range(50):
            fxy = p[:, :2] - dist[:, None] * n[:, :2]
            foot = np.column_stack([fxy, self.sag(fxy[:, 0], fxy[:, 1])])
            n = self.normal(fxy[:, 0], fxy[:, 1])
            new = np.einsum("ij,ij->i", p - foot, n)
            done = np.max(np.abs(new - dist), initial=0.0) <= 1e-13 * (1.0 + np.max(np.abs(new)))
            dist = new
            if done:
                break
        return foot, n, dist

    def signed_distance(self, xyz) -> np.ndarray:
        """Signed orthogonal distance (mm), positive on the +z side of the surface."""
        return self.foot_point(xyz)[2]

    def describe(self) -> dict:
        """JSON-able description for reports."""
        return {"type": self.kind}
