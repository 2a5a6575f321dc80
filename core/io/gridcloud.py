"""A gridded input stays a grid (issue 26): find the pixel grid of a cloud, write it as X3P.

An interferometer's map is a grid of pixels with dropouts. Written as cloud.csv it becomes ~90 bytes
of text a pixel (1.15 GB at 12.6M pixels, 18 s of formatting); as ``cloud.x3p`` (ISO 25178-72, heights
in metres, NaN = not measured) it is the map again, read by MountainsMap, Gwyddion, SurfaceTopography
and PointsPro itself.

``detect_grid``: whether points (x, y) are pixels x = x0 + i·Δx, y = y0 + j·Δy (i, j integers, no
pixel twice) — for readers whose format has no grid of its own (PLY's x, y, z); the instrument readers
record theirs (docs/formats.md, Pixel convention): ``meta["pixel_mm"]``, ``meta["grid"]``.

``grid_of``: at write time, the grid the processed cloud still lies on — the input's pixel pitch
(``meta["pixel_mm"]``) and the points still on it (a step that moved the points to the part frame,
``misalignment``, leaves no grid: the cloud is then written as CSV and the report says why).
The work is in chunks of a few columns; the grid itself is one float64 per pixel when written.
"""
from __future__ import annotations

import numpy as np

#: points per chunk of the checks
CHUNK = 1 << 18
#: a pixel coordinate may miss its node by this fraction of the pitch (the file's decimal rounding)
TOLERANCE = 1e-6
#: a grid is worth writing when it has no more than this many pixels per point (a disk in its square
#: has 4/π; a sparse scatter snapped to a fine pitch would make a huge, empty image)
MAX_PIXELS_PER_POINT = 4.0


def _indices(v: np.ndarray, v0: float, step: float) -> tuple[np.ndarray | None, int]:
    """(integer index of each value on v0 + k·step, count), or (None, 0) when a value is off it."""
    idx = np.empty(len(v), dtype=np.int32 if len(v) < 2**31 else np.int64)
    kmax = 0
    for s in range(0, len(v), CHUNK):
        q = np.asarray(v[s:s + CHUNK], dtype=np.float64) - v0
        q /= step
        k = np.rint(q)
        if np.abs(q - k).max(initial=0.0) > TOLERANCE:
            return None, 0
        idx[s:s + len(k)] = k
        kmax = max(kmax, int(k.max(initial=0)))
    return idx, kmax + 1


def _pitch(v: np.ndarray) -> float | None:
    """The smallest positive step between consecutive values of a sample (a row of pixels)."""
    d = np.abs(np.diff(np.asarray(v[:200_000], dtype=np.float64)))
    span = float(np.ptp(v[:200_000])) if len(v) else 0.0
    d = d[d > TOLERANCE * max(span, 1e-300)]
    return float(d.min()) if d.size else None


def detect_grid(x, y) -> dict | None:
    """{"pixel_mm": [Δx, Δy], "grid": [nx, ny], "grid_origin_mm": [x0, y0]} when the points are
    distinct pixels of a regular grid (module doc), else None."""
    n = len(x)
    if n < 16:
        return None
    x0, y0 = float(np.min(x)), float(np.min(y))
    dx, dy = _pitch(x), _pitch(y)
    if dx is None or dy is None:
        # every point of the sample on one row or one column: take the pitch from the other axis
        dx = dx or dy
        dy = dy or dx
        if dx is None:
            return None
    return _on_grid(x, y, x0, y0, dx, dy, refine=True)


def _on_grid(x, y, x0, y0, dx, dy, refine: bool = False) -> dict | None:
    i, nx = _indices(x, x0, dx)
    if i is None:
        return None
    j, ny = _indices(y, y0, dy)
    if j is None or nx * ny > MAX_PIXELS_PER_POINT * len(x) + 1024:
        return None
    seen = np.zeros(nx * ny, dtype=bool)
    for s in range(0, len(x), CHUNK):
        seen[j[s:s + CHUNK].astype(np.int64) * nx + i[s:s + CHUNK]] = True
    if int(np.count_nonzero(seen)) != len(x):
        return None  # a pixel twice: not a map
    if refine:  # the pitch from the whole span (a sample's smallest step carries its rounding)
        if nx > 1:
            dx = (float(np.max(x)) - x0) / (nx - 1)
        if ny > 1:
            dy = (float(np.max(y)) - y0) / (ny - 1)
    return {"pixel_mm": [dx, dy], "grid": [int(nx), int(ny)], "grid_origin_mm": [x0, y0]}


def grid_of(cloud) -> tuple[dict | None, str]:
    """(the grid the cloud lies on, or None; why, in words) — see module doc."""
    pix = cloud.meta.get("pixel_mm")
    if not pix or cloud.n < 16:
        return None, "the input is not a regular grid of pixels"
    dx, dy = (float(p) for p in pix)
    if not (dx > 0 and dy > 0):
        return None, "the input's pixel size is not positive"
    x0, y0 = float(cloud.x.min()), float(cloud.y.min())
    g = _on_grid(cloud.x, cloud.y, x0, y0, dx, dy)
    if g is None:
        return None, ("the points no longer lie on the input's pixel grid (a step moved them, or "
                      "the grid has too few points to be worth an image)")
    return g, f"the input is a regular grid ({g['grid'][0]} × {g['grid'][1]} pixels of {dx:g} × {dy:g} mm)"


def grid_channel(cloud) -> str:
    """What the grid file holds: the residual when a step made one (the form error), else z."""
    return "residual" if "residual" in cloud.channels else "z"


def write_x3p_cloud(path, cloud, grid: dict | None = None, revision: str = "2000") -> None:
    """``cloud.x3p``: the channel ``grid_channel`` on the cloud's pixel grid, metres, NaN where no
    point; the placement puts pixel (0, 0) at the grid's origin (mm → m)."""
    import x3pio

    from ..maps.grid import x3p_record

    if grid is None:
        grid, why = grid_of(cloud)
        if grid is None:
            raise ValueError(f"cannot write the cloud as a grid: {why}")
    nx, ny = grid["grid"]
    dx, dy = grid["pixel_mm"]
    x0, y0 = grid["grid_origin_mm"]
    v = cloud[grid_channel(cloud)] if grid_channel(cloud) != "z" else cloud.z
    img = np.full(nx * ny, np.nan)
    i, _ = _indices(cloud.x, x0, dx)
    j, _ = _indices(cloud.y, y0, dy)
    for s in range(0, cloud.n, CHUNK):
        img[j[s:s + CHUNK].astype(np.int64) * nx + i[s:s + CHUNK]] = v[s:s + CHUNK] * 1e-3
    del i, j
    rev = {"2000": x3pio.Revision.ISO5436_2000, "2017": x3pio.Revision.ISO25178_72_2017_DAM1}[revision]
    x3pio.write(str(path), img.reshape(ny, nx), x_scale=dx * 1e-3, y_scale=dy * 1e-3,
                placement=x3pio.Placement.translation(x0 * 1e-3, y0 * 1e-3, 0.0),
                coordinate_system=x3pio.CoordinateSystem.VIEW, revision=rev, metadata=x3p_record())
