"""What the views show, in numpy only (no Qt, no VTK): the channel's values and colour scale, the
3D level of detail, and selection in screen space. Tested headless.

Channels that are lengths (mm in the cloud) are shown in the unit their spread asks for (mm, µm or
nm): deviations signed on a diverging map centred on zero, non-negative ones (ω, uncertainties) on a
sequential map; x, y, z about their mean.
"""
from __future__ import annotations

import numpy as np

# Signed deviations (mm): shown in µm on a diverging map centred on zero.
DEVIATION_CHANNELS = ("residual", "probe_residual", "distance", "gap", "correction", "form_error")
# Non-negative deviations and uncertainties (mm): shown in µm on a sequential map.
MAGNITUDE_CHANNELS = ("omega", "u", "uncertainty", "u_z", "sigma")

#: points drawn in the 3D view at most (level of detail). Software OpenGL (llvmpipe, the CI's and
#: many remote desktops') draws ~2 M points/s, so 200,000 keep a frame near 0.1 s; the 2D map, the
#: selection and every computation always use all points.
DEFAULT_3D_BUDGET = 200_000


def channel_order(cloud) -> list[str]:
    """The colour-by choices: residual first when present (a form-error map is what an optician opens
    a processed cloud for), then z, the other channels, then x and y."""
    rest = [n for n in cloud.column_names if n not in ("x", "y", "z", "index")]
    return (["residual"] if "residual" in rest else []) + ["z"] + [n for n in rest if n != "residual"] \
        + ["x", "y"]


#: units a length channel can be shown in (mm in the cloud): the one its spread asks for
_DISPLAY_UNITS = {"mm": 1.0, "µm": 1e-3, "nm": 1e-6}


def display_unit(v_mm) -> str:
    """The unit a length channel's values (mm) read best in: that of its robust spread (0.5–99.5 %),
    so a 44 nm PV reads "43.9 nm", not "4.39e-05 mm" (core.units; mm above 1 mm)."""
    from pointspro.core.units import length_unit

    v = np.asarray(v_mm, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "mm"
    lo, hi = np.percentile(v, [0.5, 99.5]) if v.size > 200 else (v.min(), v.max())
    span = float(hi - lo) or float(np.max(np.abs(v)))
    unit = length_unit(span)[1]
    return unit if unit in _DISPLAY_UNITS else ("mm" if unit == "m" else "nm")


def channel_display(cloud, name: str, unit: str | None = None):
    """(values in display units float64, colour-bar title with the unit, unit, diverging?).

    Length channels — deviations, magnitudes, and x, y, z about their mean — are shown in the unit
    their spread asks for (``display_unit``), or in ``unit`` when given: a view that keeps its colour
    limits through edits keeps its unit too."""
    if name in DEVIATION_CHANNELS or name in MAGNITUDE_CHANNELS or name in ("x", "y", "z"):
        if name in ("x", "y", "z"):
            v = np.asarray(getattr(cloud, name), dtype=np.float64)
            v = v - v.mean()
            label = f"{name} − mean"
        else:
            v = np.asarray(cloud[name], dtype=np.float64)
            label = name
        unit = unit if unit in _DISPLAY_UNITS else display_unit(v)
        return v / _DISPLAY_UNITS[unit], f"{label} ({unit})", unit, name in DEVIATION_CHANNELS
    return np.asarray(cloud[name], dtype=np.float64), name, None, False


def channel_values(cloud, name: str, unit: str | None = None) -> tuple[np.ndarray, str, bool]:
    """(values in display units float64, colour-bar title with the unit, diverging?)."""
    v, title, _, diverging = channel_display(cloud, name, unit)
    return v, title, diverging


def colour_limits(v: np.ndarray, diverging: bool) -> tuple[float, float]:
    """The reports' robust limits (0.5–99.5 percentiles: a few spikes saturate instead of washing
    the map out), symmetric about zero for signed deviations."""
    from pointspro.core.figures import robust_limits

    lo, hi = robust_limits(v, symmetric=diverging)
    return float(lo), float(hi)


def display_subset(index: np.ndarray, n_input: int, budget: int) -> np.ndarray:
    """Positions of the points the 3D view draws: all when they fit the budget, else a fixed
    pseudo-random share chosen by input row (golden-ratio hash), so a deletion only removes points
    from the view and never reshuffles the rest."""
    index = np.asarray(index)
    if index.size <= budget:
        return np.arange(index.size)
    share = budget / max(int(n_input), index.size)
    h = (index.astype(np.float64) * 0.6180339887498949) % 1.0
    return np.flatnonzero(h < share)


def to_screen(xyz: np.ndarray, matrix: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Display coordinates (pixels, origin top-left as Qt's) of world points through the camera's
    4×4 world→normalised-device matrix (VTK's composite projection transform)."""
    h = xyz @ matrix[:3, :3].T + matrix[:3, 3]
    w = xyz @ matrix[3, :3] + matrix[3, 3]
    ndc_x, ndc_y = h[:, 0] / w, h[:, 1] / w
    return (ndc_x + 1.0) * 0.5 * width, (1.0 - (ndc_y + 1.0) * 0.5) * height


def profile_along(x, y, v, p0, p1, half_width: float) -> tuple[np.ndarray, np.ndarray]:
    """A profile cut: the points within ``half_width`` (mm) of the segment p0→p1, as (distance
    along the cut from p0 in mm, value), sorted along the cut."""
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    d = p1 - p0
    length = float(np.hypot(*d))
    if length == 0:
        return np.empty(0), np.empty(0)
    u = d / length
    rx, ry = np.asarray(x) - p0[0], np.asarray(y) - p0[1]
    s = rx * u[0] + ry * u[1]
    off = -rx * u[1] + ry * u[0]
    keep = (s >= 0) & (s <= length) & (np.abs(off) <= half_width)
    order = np.argsort(s[keep], kind="stable")
    return s[keep][order], np.asarray(v)[keep][order]
