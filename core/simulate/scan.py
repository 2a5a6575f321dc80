"""Scan paths with their timing: raster (serpentine rows), star (spokes), spiral (spindle + slide).

Every path gives x, y (mm, part frame), t (s) and c (deg, the spindle angle: on a spiral the polar
angle of the probed point; on raster and star paths the polar angle too, for effects written in c).
A fiducial pattern probes a square patch around each centre (channel `fiducial`, 1, 2, …).
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field


class ScanSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN, ±inf: never
    type: Literal["raster", "star", "spiral", "fiducials"] = Field(description="path shape")
    radius: float = Field(gt=0, description="radius of the scanned disk (mm)")
    spacing: float = Field(1.0, gt=0, description="raster/star: point spacing along a line (mm)")
    lines: int = Field(20, ge=1, le=100000, description="raster: rows; star: spokes")
    speed: float = Field(10.0, gt=0, description="raster/star: scan speed (mm/s)")
    rpm: float = Field(30.0, gt=0, description="spiral: spindle speed (rev/min)")
    pitch: float = Field(0.1, gt=0, description="spiral: radial feed per revolution (mm/rev)")
    fs: float = Field(1000.0, gt=0, description="spiral: sampling rate (Hz)")
    direction: Literal["inward", "outward"] = Field("inward", description="spiral: from the rim inward "
                                                    "or from the centre outward")
    centers: list[tuple[float, float]] = Field(default_factory=list, description="fiducials: (x, y) of "
                                               "each ball or mark (mm)")
    patch: float = Field(6.0, gt=0, description="fiducials: side of the square patch probed on each (mm)")
    points: int = Field(20, ge=1, le=100000, description="fiducials: points per patch")


#: the fewest samples a raster, star or spiral may have: fewer make no scan. A spiral with `fs: 0.001` (a
#: sampling interval in s written for the rate in Hz) had 0 samples: `pointspro simulate` wrote a
#: header-only file, exit 0. A small scan is no error (a CMM's 4-spoke star of 84 points, an 11-line
#: raster of 85 were refused for a while): below explain's MIN_POINTS, scan_warnings says so.
MIN_SAMPLES = 3


def scan_points(spec: ScanSpec) -> dict[str, np.ndarray]:
    """x, y, t, c of the scan (and ``fiducial`` on a fiducial pattern). ValueError for a spiral of more
    than 5,000,000 samples, and for a raster, star or spiral of fewer than MIN_SAMPLES (none, or too
    few to be a scan), naming the keys (and the unit slip most likely behind it)."""
    R = spec.radius
    if spec.type == "spiral":
        revs = R / spec.pitch
        T = revs * 60.0 / spec.rpm
        n = int(T * spec.fs)
        if n > 5_000_000:
            raise ValueError(f"the spiral has {n} samples; lower fs or raise pitch")
        if n < MIN_SAMPLES:
            raise ValueError(
                f"scan: the spiral has {n} sample(s), fewer than the {MIN_SAMPLES} that make a scan: radius {R:g} mm / pitch {spec.pitch:g} mm/rev = {revs:.3g} rev at rpm {spec.rpm:g} "
                f"take {T:.3g} s, sampled at fs {spec.fs:g} Hz — check the units of scan.fs (a rate in Hz: "
                "1 kHz is `fs: 1000`, not 1, nor a sampling interval such as 0.001), scan.radius and "
                "scan.pitch (mm) and scan.rpm (rev/min)")
        t = np.arange(n) / spec.fs
        c = (360.0 * spec.rpm / 60.0 * t) % 360.0
        frac = t / T
        r = R * (1 - frac) if spec.direction == "inward" else R * frac
        a = np.deg2rad(c)
        return {"x": r * np.cos(a), "y": r * np.sin(a), "t": t, "c": c}
    xs, ys = [], []
    if spec.type == "fiducials":
        if not spec.centers:
            raise ValueError("a fiducial scan needs `centers`")
        k = int(np.ceil(np.sqrt(spec.points)))
        u = (np.arange(k) / max(k - 1, 1) - 0.5) * spec.patch
        U, V = np.meshgrid(u, u)
        U, V = U.ravel()[: spec.points], V.ravel()[: spec.points]
        ids = []
        for i, (cx, cy) in enumerate(spec.centers):
            xs.append(cx + U)
            ys.append(cy + V)
            ids.append(np.full(U.size, i + 1))
        x, y = np.concatenate(xs), np.concatenate(ys)
        t = np.arange(x.size) * spec.spacing / spec.speed
        return {"x": x, "y": y, "t": t, "c": np.degrees(np.arctan2(y, x)) % 360.0,
                "fiducial": np.concatenate(ids)}
    if spec.type == "raster":
        for k, y in enumerate(np.linspace(-R, R, spec.lines)):
            half = np.sqrt(max(R * R - y * y, 0.0))
            x = np.arange(-half, half + 1e-9, spec.spacing)
            xs.append(x if k % 2 == 0 else x[::-1])
            ys.append(np.full(x.size, y))
    else:  # star
        for k in range(spec.lines):
            a = np.pi * k / spec.lines
            s = np.arange(-R, R + 1e-9, spec.spacing)
            s = s if k % 2 == 0 else s[::-1]
            xs.append(s * np.cos(a))
            ys.append(s * np.sin(a))
    x, y = np.concatenate(xs), np.concatenate(ys)
    if x.size < MIN_SAMPLES:
        raise ValueError(
            f"scan: the {spec.type} has {x.size} point(s), fewer than the {MIN_SAMPLES} that make a scan: "
            f"radius {R:g} mm, spacing {spec.spacing:g} mm, lines {spec.lines} — check "
            "the units of scan.radius and scan.spacing (mm) and raise scan.lines")
    step = np.r_[0.0, np.hypot(np.diff(x), np.diff(y))]
    t = np.cumsum(step) / spec.speed
    c = np.degrees(np.arctan2(y, x)) % 360.0
    return {"x": x, "y": y, "t": t, "c": c}


def scan_warnings(spec: ScanSpec) -> list[str]:
    """Warnings about the scan itself (`pointspro simulate` prints them): a raster, star or spiral of
    fewer points than `pointspro explain` needs in a measurement (core.explain.workflow.MIN_POINTS) —
    fine for a coarse CMM scan, and as a model's own scan for explain (it evaluates the model at the
    measured points), but this simulated file cannot be explain's measurement."""
    from ..explain.workflow import MIN_POINTS

    if spec.type == "fiducials":
        return []
    n = scan_points(spec)["x"].size
    if n >= MIN_POINTS:
        return []
    return [f"scan: the {spec.type} has {n} point(s), fewer than the {MIN_POINTS} that `pointspro explain` "
            "needs in a measurement to tell an effect from the noise: the simulated file can be explain's "
            "--simulated or a model's scan, not its measurement (raise the scan's density for that: "
            "scan.lines, a smaller scan.spacing, or scan.fs)"]
