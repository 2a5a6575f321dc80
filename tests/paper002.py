"""The simulated set-ups of paper 002 (Li et al., Chinese Optics 13(2) 2020), rebuilt for the tests.

Each function returns true contact points in the part frame and the pose; the tests build probe
centres and misaligned measurements from them exactly as the paper's Fig. 8 describes.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.geometry import Pose
from pointspro.core.surfaces import EvenAsphere

# Table 1 (probe-radius compensation)
TABLE1_SURFACE = EvenAsphere(1 / 3000, -0.98, {4: 7e-13, 6: 1e-19}, 1300)
TABLE1_POSE = Pose(0.17, -0.01, 0.8, 4.0, 0.0)
# Table 4 (five-DOF misalignment)
DATA1_SURFACE = EvenAsphere(-1 / 1646.4, -0.9861, {4: 4e-16}, 600)
DATA1_POSE = Pose(0.0063, 0.0035, 0.1291, 0.1532, -61.37)
DATA2_SURFACE = EvenAsphere(1 / 2085, -0.97, {4: 3e-19, 6: -2e-23}, 1000)
DATA2_POSE = Pose(-2.341, -0.5315, 4.296, 3.372, -50.37)
# Table 3: the Leitz comparison part
LEITZ_SURFACE = EvenAsphere(1 / 2086.73, -0.97, {4: 4e-19}, 1050)


def star(diameter: float, lines: int = 18, pitch: float = 5.0):
    """'米字' pattern: `lines` diameters evenly in 180°, a point every `pitch` mm, none twice."""
    half = diameter / 2
    s = np.arange(-half + pitch / 2, half, pitch)
    ang = np.radians(np.arange(lines) * 180.0 / lines)
    x = np.concatenate([s * np.cos(a) for a in ang])
    y = np.concatenate([s * np.sin(a) for a in ang])
    return x, y


def radial(diameter: float, rays: int, n_points: int):
    """`rays` radial lines from the centre, n_points in all."""
    per = n_points // rays
    r = np.linspace(diameter / 2 / per, diameter / 2, per)
    ang = np.radians(np.arange(rays) * 360.0 / rays)
    return np.concatenate([r * np.cos(a) for a in ang]), np.concatenate([r * np.sin(a) for a in ang])


def raster(diameter: float, pitch: float):
    g = np.arange(-diameter / 2, diameter / 2 + 1e-9, pitch)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    keep = np.hypot(x, y) <= diameter / 2
    return x[keep], y[keep]


def astigmatism(x, y, diameter, pv_um=2.678):
    """Low-order astigmatism (data 1 residual), scaled to the given PV (µm) → mm."""
    r = np.hypot(x, y) / (diameter / 2)
    w = r ** 2 * np.cos(2 * np.arctan2(y, x) - 0.3)
    return (w - w.mean()) / np.ptp(w) * pv_um * 1e-3


def machining_marks(x, y, diameter, pv_um=3.057):
    """Mid/high-frequency turning/grinding marks (data 2 residual): rings and ripples, PV scaled."""
    r = np.hypot(x, y)
    t = np.arctan2(y, x)
    # turning rings every 37 and 11.3 mm, a 9-lobed chatter pattern and sharp tool marks every 61 mm
    w = (0.5 * np.sin(2 * np.pi * r / 37.0) + 0.3 * np.sin(2 * np.pi * r / 11.3 + 1.0)
         + 0.25 * np.cos(9 * t) * np.sin(np.pi * r / (diameter / 2)) ** 2
         + 2.0 * np.exp(-(((r + 20.0) % 61.0) - 30.5) ** 2 / (2 * 1.2 ** 2)))
    return (w - w.mean()) / np.ptp(w) * pv_um * 1e-3


def measured(surface: EvenAsphere, pose: Pose, x, y, form_error=None):
    """Points of the posed part in the measuring frame (form error added along z in the part frame)."""
    z = surface.sag(x, y) + (0.0 if form_error is None else form_error)
    return pose.to_measuring(np.column_stack([x, y, z]))
