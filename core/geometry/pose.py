"""The rigid pose of the part in the measuring frame (docs/conventions.md "Frames and signs"; paper 002 §4).

    p_measuring = Rx(alpha) · Ry(beta) · p_part + (dx, dy, dz)

    Rx(a) = [[1, 0, 0], [0, cos a, −sin a], [0, sin a, cos a]]
    Ry(b) = [[cos b, 0, sin b], [0, 1, 0], [−sin b, 0, cos b]]

Angles in degrees, shifts in mm. Rotation about the optical axis is not part of the pose: it is not
observable on a surface of revolution (002 §4).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


def rot_x(a_rad: float) -> np.ndarray:
    c, s = np.cos(a_rad), np.sin(a_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(b_rad: float) -> np.ndarray:
    c, s = np.cos(b_rad), np.sin(b_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class Pose:
    alpha_deg: float = 0.0
    beta_deg: float = 0.0
    dx: float = 0.0
    dy: float = 0.0
    dz: float = 0.0

    @property
    def rotation(self) -> np.ndarray:
        """R = Rx(alpha) · Ry(beta)."""
        return rot_x(np.radians(self.alpha_deg)) @ rot_y(np.radians(self.beta_deg))

    @property
    def translation(self) -> np.ndarray:
        return np.array([self.dx, self.dy, self.dz], dtype=np.float64)

    def matrix(self) -> np.ndarray:
        """4 × 4 homogeneous matrix part → measuring."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.translation
        return m

    def to_measuring(self, p_part) -> np.ndarray:
        p = np.asarray(p_part, dtype=np.float64)
        return p @ self.rotation.T + self.translation

    def to_part(self, p_measuring) -> np.ndarray:
        p = np.asarray(p_measuring, dtype=np.float64)
        return (p - self.translation) @ self.rotation

    def inverse_matrix(self) -> np.ndarray:
        """4 × 4 homogeneous matrix measuring → part."""
        r = self.rotation
        m = np.eye(4)
        m[:3, :3] = r.T
        m[:3, 3] = -r.T @ self.translation
        return m

    def as_dict(self) -> dict:
        return asdict(self)


def apply_affine(matrix, p) -> np.ndarray:
    """Apply a 4 × 4 (or 3 × 4) affine matrix to (N, 3) points."""
    m = np.asarray(matrix, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    return p @ m[:3, :3].T + m[:3, 3]
