"""What every nominal surface offers: sag, gradient, unit normal and the signed distance of points.

A nominal is a height function z = f(x, y) over its domain (all optics here are measured along z).
The unit normal is the one with positive z (DESIGN "Conventions"):
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

    def signed_distance(self, xyz) -> np.ndarray:
        """Signed orthogonal distance (mm), positive on the +z side of the surface.

        Generic version: Newton iterations for the foot point (x₀, y₀) that minimises
        |p − (x₀, y₀, f(x₀, y₀))|, started from the vertical projection; a handful of iterations reach
        float64 for the slopes of optics (the vertical residual times cos θ is the first iterate).
        """
        p = np.asarray(xyz, dtype=np.float64)
        d = self.vertical_residual(p)
        n = self.normal(p[:, 0], p[:, 1])
        # first iterate: orthogonal distance ≈ vertical residual · n_z; then a fixed point on the
        # foot (foot = p − d n̂(foot), d = (p − foot)·n̂), which converges for |d| ≪ radius of curvature
        dist = d * n[:, 2]
        for _ in range(8):
            foot = p - dist[:, None] * n
            n = self.normal(foot[:, 0], foot[:, 1])
            zf = self.sag(foot[:, 0], foot[:, 1])
            new = np.einsum("ij,ij->i", p - np.column_stack([foot[:, 0], foot[:, 1], zf]), n)
            if np.max(np.abs(new - dist), initial=0.0) < 1e-13:
                dist = new
                break
            dist = new
        return dist

    def describe(self) -> dict:
        """JSON-able description for reports."""
        return {"type": self.kind}
