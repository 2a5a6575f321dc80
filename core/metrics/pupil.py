"""The pupil of a pupil-based quantity (Zernike fit, PVr): its centre and normalisation radius.

Where the centre comes from (docs/conventions.md, "Pupil"):

1. given by the recipe (``centre: [x, y]`` on the step) — always wins;
2. a nominal surface with an axis (any surface but a flat): its axis, x = y = 0 of the part frame,
   where `misalignment`/`probe_radius` put the data; the radius is half the surface's aperture when it
   has one;
3. otherwise (a map with no nominal, or a flat, which has no axis): the centre of the **bounding box**
   of the measured points, and the smallest radius about it that holds every point.

Why the bounding box and not the centroid: an interferometer's map is a disk or a rectangle sampled
on a grid with dropouts; the centroid moves with the dropouts and with uneven sampling (a star or a
spiral scan is denser at the centre, a partial map leans to its full side), while the bounding box's
centre is the centre of a circular or rectangular aperture whatever the sampling. A file's own
origin (usually a corner: MetroPro, Digital Surf, X3P) is never used — on a corner-origin map the data
fill one quadrant of the unit disk, where tilt and power are nearly the same function and a 36-term
fit is singular (issue 15: 155.6 µm of "residual" from 0.013 µm of heights).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Pupil:
    center: tuple[float, float]  # mm, in the cloud's frame
    radius: float  # mm
    how: str  # where the centre came from, in words (for the report)

    def report(self) -> dict:
        return {"centre_mm": [float(self.center[0]), float(self.center[1])],
                "norm_radius_mm": float(self.radius), "centre_from": self.how}


#: the steps whose ``centre`` is the pupil's (docs/conventions.md, Pupil)
PUPIL_STEPS = ("zernike", "bspline_map")


def recipe_centre(steps) -> tuple[float, float] | None:
    """The centre the recipe gives the pupil: that of the last enabled zernike or bspline_map step
    with ``centre`` (``steps``: core.recipe.RecipeStep), else None. The summary's PVr, the Monte
    Carlo's samples of it and the tolerance's quantities take it, so they are about the same pupil
    as the step's Zernike fit (an off-axis aperture's PVr was fitted about the part's axis)."""
    for rs in reversed(list(steps)):
        if getattr(rs, "enabled", True) and rs.id in PUPIL_STEPS:
            c = getattr(rs.params, "given_centre", None)
            if c is not None:
                return float(c[0]), float(c[1])
    return None


def is_flat(surface) -> bool:
    """A nominal with no axis: zero sag and zero slope everywhere (a plane)."""
    if surface is None:
        return True
    probe = getattr(surface, "is_flat", None)
    if probe is not None:
        return bool(probe() if callable(probe) else probe)
    return False


def heights_are_sag(surface, x, y, z) -> bool:
    """True when the heights z of a cloud with no residual are the part's surface — their spread at
    least half the nominal's sag spread over the same x, y (the probe points of a curved part) —
    rather than a form-error map an instrument wrote (µm against the sag's mm). A flat nominal, none,
    or points beyond the nominal's domain: False."""
    if is_flat(surface) or len(z) < 3:
        return False
    from ..errors import DomainError

    try:
        sag = np.asarray(surface.sag(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)))
    except (DomainError, ValueError):
        return False
    span = float(np.nanmax(sag) - np.nanmin(sag)) if np.isfinite(sag).any() else 0.0
    return span > 0 and float(np.ptp(z)) >= 0.5 * span


def pupil_of(x, y, surface=None, center=None, radius: float | None = None) -> Pupil:
    """The pupil of points (x, y) (mm) by the rules in the module doc."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if center is not None:
        c = (float(center[0]), float(center[1]))
        how = "given in the recipe"
    elif not is_flat(surface):
        c = (0.0, 0.0)
        how = "the nominal surface's axis (part frame)"
    elif x.size:
        c = (0.5 * (float(x.min()) + float(x.max())), 0.5 * (float(y.min()) + float(y.max())))
        how = ("bounding-box centre of the measured region (no nominal surface)" if surface is None
               else "bounding-box centre of the measured region (a flat has no axis)")
    else:
        c = (0.0, 0.0)
        how = "no points"
    if radius is None and center is None and not is_flat(surface):
        ap = getattr(surface, "aperture", None)
        if ap:
            radius = ap / 2
    if radius is None:
        radius = float(np.sqrt(_max_r2(x, y, c))) if x.size else 0.0
    return Pupil(c, float(radius), how)


def _max_r2(x, y, c) -> float:
    """max((x − cx)² + (y − cy)²) in chunks of 2¹⁸ points: no full-length temporaries (12.6 M points
    0.65 → ~0.1 s). inf for a centre ~1e154 mm or more away (no overflow warning): the steps refuse
    that pupil by name."""
    best = 0.0
    step = 1 << 18
    with np.errstate(over="ignore"):
        for a in range(0, x.size, step):
            dx = x[a:a + step] - c[0]
            dy = y[a:a + step] - c[1]
            dx *= dx
            dy *= dy
            dx += dy
            best = max(best, float(dx.max()))
    return best


#: steps that carry the points into another frame (the part frame, a calibrated one, any pose):
#: an `aperture` step before one of them cut about a centre in the frame before
FRAME_CHANGING_STEPS = ("misalignment", "register", "transform", "volumetric")


def applied_aperture_step(cloud) -> dict | None:
    """The last circular or annular `aperture` step in the cloud's provenance that gave a diameter:
    {"diameter", "inner_diameter", "centre", "moved"} (mm) — the clear aperture the recipe kept,
    which the correction must cover (the surface's own aperture may be larger than the measured
    zone); None when the last aperture step was a polygon or took the surface's diameter, or there is
    none. ``moved``: a step that changes the frame ran after it (FRAME_CHANGING_STEPS) — its centre
    was in the frame before (a review: an aperture about x = 30 mm in the measuring frame, then
    misalignment, cut the map 30 mm off the part); the pose fit brings the part onto the nominal's
    axis, so the diameter and the hole stand about the axis, and ``centre`` is (0, 0)."""
    moved = False
    for entry in reversed(cloud.provenance):
        if entry.get("id") in FRAME_CHANGING_STEPS:
            moved = True
        if entry.get("id") == "aperture":
            p = entry.get("params") or {}
            if p.get("shape", "circle") in ("circle", "annulus") and p.get("diameter"):
                inner = float(p.get("inner_diameter") or 0.0) if p.get("shape") == "annulus" else 0.0
                centre = (0.0, 0.0) if moved else (float(p.get("center_x") or 0.0),
                                                   float(p.get("center_y") or 0.0))
                return {"diameter": float(p["diameter"]), "inner_diameter": inner, "centre": centre,
                        "moved": moved}
            return None
    return None
