"""Generate the example CMM measurement (deterministic; seed 2020).

The set-up of paper 002 Table 1 (Li et al., Chinese Optics 13(2) 2020): an even asphere of
D = 1300 mm, C = 1/3000 mm⁻¹, k = −0.98, a4 = 7e−13, a6 = 1e−19, measured on a CMM with a 4 mm
probe ball touching from +z, misaligned by (α, β, Δx, Δy) = (0.17°, −0.01°, 0.8 mm, 4 mm) plus a
height offset Δz = 12.5 mm, on a star ("米字") pattern: 18 diameters every 10°, a point every 5 mm
(4680 points). The part carries a few µm of polishing form error (astigmatism, trefoil, a zone); the
probe centres get 0.3 µm of noise and some outliers (spikes, and low points where the probe slipped off
the edge). The file holds probe-centre coordinates in the measuring frame, as a CMM exports them.

    python resources/example/make_example.py      # rewrites asphere_cmm.csv and truth.json
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pointspro.core.geometry import Pose
from pointspro.core.surfaces import EvenAsphere

HERE = Path(__file__).parent
SURFACE = EvenAsphere(c=1 / 3000, k=-0.98, A={4: 7e-13, 6: 1e-19}, aperture=1300)
PROBE_RADIUS = 4.0  # mm
SIDE = +1
POSE = Pose(alpha_deg=0.17, beta_deg=-0.01, dx=0.8, dy=4.0, dz=12.5)
NOISE = 0.3e-3  # mm (0.3 µm, 1σ)


def form_error(x, y):
    """Polishing residual (mm): astigmatism, trefoil and a zone; a few µm PV."""
    r = np.hypot(x, y) / 650.0
    t = np.arctan2(y, x)
    return 1e-3 * (1.2 * r ** 2 * np.cos(2 * (t - 0.4)) + 0.6 * r ** 3 * np.cos(3 * t + 1.0)
                   + 0.7 * np.exp(-((r - 0.62) / 0.08) ** 2) - 0.3 * r ** 4)


def star_pattern():
    s = np.arange(-647.5, 648.0, 5.0)  # 260 points per diameter, none at the centre twice
    ang = np.radians(np.arange(0, 180, 10))
    x = np.concatenate([s * np.cos(a) for a in ang])
    y = np.concatenate([s * np.sin(a) for a in ang])
    line = np.repeat(np.arange(len(ang)), len(s))
    return x, y, line


def make(seed: int = 2020):
    rng = np.random.default_rng(seed)
    x, y, line = star_pattern()
    e = form_error(x, y)
    contact = np.column_stack([x, y, SURFACE.sag(x, y) + e])
    # the ball touches the real part: its normal includes the form error's slope (central differences)
    h = 1e-3
    fx, fy = SURFACE.gradient(x, y)
    ex = (form_error(x + h, y) - form_error(x - h, y)) / (2 * h)
    ey = (form_error(x, y + h) - form_error(x, y - h)) / (2 * h)
    m = np.column_stack([-(fx + ex), -(fy + ey), np.ones_like(x)])
    normal = m / np.linalg.norm(m, axis=1)[:, None]
    centre = contact + SIDE * PROBE_RADIUS * normal  # docs/conventions.md: contact = centre − s·R·n̂
    centre[:, 2] += rng.normal(0.0, NOISE, len(x))
    outliers = {}
    for i, h in zip(rng.choice(len(x), 3, replace=False), (12e-3, 15e-3, 16e-3)):  # spikes, mm
        centre[i, 2] += h
        outliers[int(i)] = h
    edge = np.flatnonzero(np.hypot(x, y) > 640)
    for i in rng.choice(edge, 4, replace=False):  # probe slipping off the edge: low points
        centre[i, 2] -= 25e-3
        outliers[int(i)] = -25e-3
    measured = POSE.to_measuring(centre)
    return measured, line, e, outliers, POSE.to_measuring(contact)


def area_rms(f, radius: float) -> float:
    """RMS of f(x, y) about its mean over the disk of ``radius`` (the area's, ISO 10110-5: polar
    midpoint quadrature, 2000 radii × 1440 angles, each node weighted by r) — the star's points crowd
    its centre, so their plain RMS (`form_error_rms_points_um`) is not the surface's."""
    r = (np.arange(2000) + 0.5) / 2000 * radius
    t = (np.arange(1440) + 0.5) / 1440 * 2 * np.pi
    rr, tt = np.meshgrid(r, t)
    v = f(rr * np.cos(tt), rr * np.sin(tt)).ravel()
    w = rr.ravel() / rr.sum()
    mean = np.dot(w, v)
    return float(np.sqrt(np.dot(w, (v - mean) ** 2)))


def main():
    xyz, line, e, outliers, _ = make()
    lines = ["# CMM export — probe-centre coordinates (mm), measuring frame",
             "# part: even asphere D1300 C=1/3000 k=-0.98; probe ball radius 4.000 mm, touching from +z",
             "# pattern: star, 18 lines every 10 deg, 5 mm pitch",
             "x,y,z,line"]
    lines += [f"{a:.6f},{b:.6f},{c:.6f},{int(d)}" for (a, b, c), d in zip(xyz, line)]
    (HERE / "asphere_cmm.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    truth = {"surface": SURFACE.describe(), "probe_radius": PROBE_RADIUS, "side": SIDE,
             "pose": POSE.as_dict(), "noise_um": NOISE * 1e3,
             "form_error_rms_um": area_rms(form_error, 647.5) * 1e3,
             "form_error_rms_points_um": float(np.std(e) * 1e3), "form_error_pv_um": float(np.ptp(e) * 1e3),
             "outliers": {str(k): v * 1e3 for k, v in sorted(outliers.items())},
             "note": "outliers: input row (index) -> height added to the probe centre, µm"}
    (HERE / "truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
