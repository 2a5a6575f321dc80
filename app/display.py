"""What the views show, in numpy only (no Qt, no VTK): the channel's values and colour scale, the
3D level of detail, and selection in screen space. Tested headless.

Channels that are lengths (mm in the cloud) are shown in the unit their spread asks for (mm, µm or
nm): deviations signed on a diverging map centred on zero, non-negative ones (ω, uncertainties) on a
sequential map; x, y, z about their mean.
"""
from __future__ import annotations

import threading

import numpy as np

from pointspro.core.units import (
    SHOWN_LENGTH_MM,
    display_unit,  # noqa: F401  (the views' unit rule; tests import it here)
    format_length,
)

# Signed deviations (mm): shown in the unit their spread asks for on a diverging map centred on zero
# (the steps' error channels too: core.units.LENGTH_CHANNELS lists what the steps make in mm).
DEVIATION_CHANNELS = ("residual", "probe_residual", "distance", "gap", "correction", "form_error",
                      "kinematic_error", "dynamic_error")
# Non-negative deviations and uncertainties (mm): shown on a sequential map.
MAGNITUDE_CHANNELS = ("omega", "u", "uncertainty", "u_x", "u_y", "u_z", "sigma")
# Positions (mm): shown about their mean (a height's 1 mm offset would read every label as "1").
POSITION_CHANNELS = ("x", "y", "z", "z_raw", "xd", "xc")

#: points drawn in the 3D view at most (level of detail). Software OpenGL (llvmpipe, the CI's and
#: many remote desktops') draws ~3 M points/s, so 150,000 keep a frame near 0.05 s — an edit redraws
#: the 3D view twice (the highlight, then the deletion), within the 0.5 s a lasso + delete may take
#: at 12.6 M points (issue 26); the 2D map, the selection and every computation use all points.
DEFAULT_3D_BUDGET = 150_000


def channel_order(cloud) -> list[str]:
    """The colour-by choices: residual first when present (a form-error map is what an optician opens
    a processed cloud for), then z, the other channels, then x and y."""
    rest = [n for n in cloud.column_names if n not in ("x", "y", "z", "index")]
    return (["residual"] if "residual" in rest else []) + ["z"] + [n for n in rest if n != "residual"] \
        + ["x", "y"]


#: units a length channel can be shown in (mm in the cloud): the one its spread asks for
#: (``display_unit``, core.units: the report's figures choose by the same rule)
_DISPLAY_UNITS = SHOWN_LENGTH_MM


def channel_display(cloud, name: str, unit: str | None = None, rows=None):
    """(values in display units float64, colour-bar title with the unit, unit, diverging?).

    Length channels — deviations, magnitudes, and x, y, z about their mean — are shown in the unit
    their spread asks for (``display_unit``), or in ``unit`` when given: a view that keeps its colour
    limits through edits keeps its unit too. ``rows``: the values of those points only (the 3D
    view's level of detail), with the unit and the mean of all points."""
    full = np.asarray(cloud[name], dtype=np.float64)
    v = full if rows is None else full[rows]
    if name in DEVIATION_CHANNELS or name in MAGNITUDE_CHANNELS or name in POSITION_CHANNELS:
        if name in POSITION_CHANNELS:
            v = v - full.mean()
            label = f"{name} − mean"
        else:
            label = name
        if unit not in _DISPLAY_UNITS:
            src = v if rows is None else full - full.mean() if name in POSITION_CHANNELS else full
            unit = display_unit(src)  # of all points, whatever is drawn
        return v / _DISPLAY_UNITS[unit], f"{label} ({unit})", unit, name in DEVIATION_CHANNELS
    return v, name, None, False


def shown_length(v: float, unit: str) -> str:
    """A readout of ``v`` in a view's unit: a length in the unit its own size asks for ("1.001 mm",
    not "1001 µm": core.units.format_length); anything else with 4 significant digits and its unit."""
    if unit in _DISPLAY_UNITS:
        return format_length(float(v) * _DISPLAY_UNITS[unit], 4)
    return f"{float(v):.4g} {unit}".rstrip()


def channel_values(cloud, name: str, unit: str | None = None) -> tuple[np.ndarray, str, bool]:
    """(values in display units float64, colour-bar title with the unit, diverging?)."""
    v, title, _, diverging = channel_display(cloud, name, unit)
    return v, title, diverging


def colour_limits(v: np.ndarray, diverging: bool, keep=None) -> tuple[float, float]:
    """The reports' robust limits (0.5–99.5 percentiles: a few spikes saturate instead of washing
    the map out), symmetric about zero for signed deviations — of the values ``v`` of every point
    (less those ``keep`` hides), sampled as the report's form_error.png samples them
    (core.figures.limits_sample): the map, the 3D view and the report show one residual alike."""
    from pointspro.core.figures import limits_sample, robust_limits

    lo, hi = robust_limits(limits_sample(v, keep), symmetric=diverging)
    return float(lo), float(hi)


def channel_limits(cloud, name: str, unit: str | None, diverging: bool, keep=None) -> tuple[float, float]:
    """``colour_limits`` of channel ``name`` of all of ``cloud``'s points (less those ``keep``
    hides) in ``unit``, whatever part of them a view draws (the 3D view's level of detail)."""
    from pointspro.core.units import UNIT_SAMPLE

    if keep is None:  # limits_sample's rows, taken before the values are formed
        n = cloud.n
        rows = np.arange(0, n, n // UNIT_SAMPLE) if n > 2 * UNIT_SAMPLE else None
    else:
        rows = np.flatnonzero(keep)
        if rows.size > 2 * UNIT_SAMPLE:
            rows = rows[:: rows.size // UNIT_SAMPLE]
    v, _, _, _ = channel_display(cloud, name, unit, rows=rows)
    return colour_limits(v, diverging)


def display_subset(index: np.ndarray, n_input: int, budget: int) -> np.ndarray:
    """Positions of the points the 3D view draws, never more than ``budget``: all when they fit it,
    else a fixed pseudo-random share chosen by input row (golden-ratio hash: frac(row / φ) < share,
    in 64-bit integers — 0.16 s at 12.6 M rows where the float form took 1.4 s), so a deletion only
    removes points from the view and never reshuffles the rest. The hash takes the share on average
    (150,001 of 200,000 rows for a budget of 150,000): the few beyond the budget, those of the
    largest hashes, are left out."""
    index = np.asarray(index)
    if index.size <= budget:
        return np.arange(index.size)
    share = budget / max(int(n_input), index.size)
    h = index.astype(np.int64, copy=False).view(np.uint64) * np.uint64(0x9E3779B97F4A7C15)  # wraps
    pos = np.flatnonzero(h < np.uint64(int(share * 2.0**64)))
    if pos.size > budget:
        pos = np.sort(pos[np.argpartition(h[pos], budget - 1)[:budget]])
    return pos


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


PROFILE_DOT_BUDGET = 20_000


def envelope_rows(s: np.ndarray, v: np.ndarray, budget: int = PROFILE_DOT_BUDGET) -> np.ndarray | None:
    """Which of a profile's points to draw as dots when there are more than ``budget``: in each of
    ``budget // 2`` equal intervals along the cut the lowest and the highest value (min-max
    decimation, as an oscilloscope draws), so that the drawn cloud has the envelope of all points
    — a spike or a dig stays visible — at a fraction of the markers. ``s`` sorted ascending. None:
    draw them all. The profile's numbers (PV, the mean per bin) always come from every point."""
    n = s.size
    if n <= budget:
        return None
    nb = max(budget // 2, 1)
    span = s[-1] - s[0]
    j = np.zeros(n, dtype=np.int64) if span <= 0 else np.minimum(
        ((s - s[0]) * (nb / span)).astype(np.int64), nb - 1)
    order = np.lexsort((v, j))  # by interval, then by value
    jo = j[order]
    first = np.flatnonzero(np.r_[True, jo[1:] != jo[:-1]])
    last = np.r_[first[1:] - 1, n - 1]
    return np.unique(order[np.r_[first, last]])


# -- selection over millions of points: cells first, points only where the outline passes -------------
class CellIndex:
    """The points grouped by the cell of a ``g`` × ``g`` grid in x, y (a counting sort by a 16-bit
    key: numpy's radix sort, linear in N), with each cell's box (its x, y edges and the z range of
    its points). A selection then decides whole cells from their boxes — projected through the
    camera, wholly inside or wholly outside the outline — and tests point by point only the cells
    the outline passes through: the result is the same mask as testing every point, at a cost
    that grows with the outline's length, not with N."""

    def __init__(self, xyz: np.ndarray, g: int = 256):
        xyz = np.asarray(xyz, dtype=np.float64)
        self.n, self.g = xyz.shape[0], int(g)
        x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        lo = np.array([x.min(), y.min()]) if self.n else np.zeros(2)
        hi = np.array([x.max(), y.max()]) if self.n else np.ones(2)
        self.lo, self.size = lo, np.maximum(hi - lo, 1e-12) / g
        ix = np.clip(((x - lo[0]) / self.size[0]).astype(np.int32), 0, g - 1)
        iy = np.clip(((y - lo[1]) / self.size[1]).astype(np.int32), 0, g - 1)
        iy *= g
        iy += ix
        del ix
        self.key = iy.astype(np.uint16 if g * g <= 65536 else np.int32)
        del iy
        order = np.argsort(self.key, kind="stable")
        self.order = order.astype(np.int32) if self.n < 2**31 else order
        del order
        counts = np.bincount(self.key, minlength=g * g)
        self.ends = np.cumsum(counts)
        self.starts = self.ends - counts
        self.cells = np.flatnonzero(counts)  # non-empty cells
        zs = z[self.order]
        self.zmin = np.minimum.reduceat(zs, self.starts[self.cells]) if self.cells.size else np.empty(0)
        self.zmax = np.maximum.reduceat(zs, self.starts[self.cells]) if self.cells.size else np.empty(0)

    def corners(self, origin=np.zeros(3)) -> np.ndarray:
        """(cells, 8, 3) corners of each non-empty cell's box, less ``origin``; a margin of 10⁻⁹ of
        the cell covers the rounding of the key."""
        g = self.g
        iy, ix = np.divmod(self.cells, g)
        m = 1e-9 * self.size
        x0 = self.lo[0] + ix * self.size[0] - m[0] - origin[0]
        y0 = self.lo[1] + iy * self.size[1] - m[1] - origin[1]
        x1, y1 = x0 + self.size[0] + 2 * m[0], y0 + self.size[1] + 2 * m[1]
        z0, z1 = self.zmin - origin[2], self.zmax - origin[2]
        out = np.empty((self.cells.size, 8, 3))
        for j, (a, b, c) in enumerate(np.ndindex(2, 2, 2)):
            out[:, j, 0] = (x0, x1)[a]
            out[:, j, 1] = (y0, y1)[b]
            out[:, j, 2] = (z0, z1)[c]
        return out

    def xy_boxes(self):
        """(x0, x1, y0, y1) of each non-empty cell, with the margin of ``corners``."""
        c = self.corners()
        return c[:, 0, 0], c[:, 7, 0], c[:, 0, 1], c[:, 7, 1]

    def positions(self, cells: np.ndarray) -> np.ndarray:
        """Positions (rows of the cloud) of the points of the given non-empty cells (indices into
        ``self.cells``)."""
        c = self.cells[cells]
        s, e = self.starts[c], self.ends[c]
        n = e - s
        if n.sum() == 0:
            return np.empty(0, dtype=np.int64)
        # ranges s[i]:e[i] concatenated without a Python loop
        step = np.ones(int(n.sum()), dtype=np.int64)
        first = np.cumsum(n) - n
        step[first[n > 0]] = s[n > 0] - np.concatenate([[0], e[n > 0][:-1] - 1])
        return self.order[np.cumsum(step)]

    def select(self, box_class, points_test, keep=None) -> np.ndarray:
        """Boolean mask over the cloud: ``box_class(corners)`` → per cell 1 inside, 0 outside, -1 to
        test; ``points_test(positions)`` → the exact test of those points; ``keep`` limits the
        result to the points shown."""
        cls = box_class(self)
        mask = np.zeros(self.n, dtype=bool)
        inside = cls == 1
        if inside.any():
            table = np.zeros(self.g * self.g, dtype=bool)
            table[self.cells[inside]] = True
            mask = table[self.key]
        pos = self.positions(np.flatnonzero(cls == -1))
        if pos.size:
            mask[pos] = points_test(pos)
        if keep is not None:
            mask &= keep
        return mask


def screen_boxes(corners: np.ndarray, matrix: np.ndarray, width: int, height: int):
    """Screen bounding boxes (sx0, sx1, sy0, sy1) of boxes' 8 corners through the camera, and
    whether every corner lies in front of it (else the projection of the box is not the hull of its
    corners' projections, and its points must be tested one by one)."""
    c = corners.reshape(-1, 3)
    sx, sy = to_screen(c, matrix, width, height)
    w = c @ matrix[3, :3] + matrix[3, 3]
    sx, sy, w = (a.reshape(corners.shape[:2]) for a in (sx, sy, w))
    return sx.min(1), sx.max(1), sy.min(1), sy.max(1), (w > 0).all(1)


def rectangle_class(bx0, bx1, by0, by1, x0, x1, y0, y1) -> np.ndarray:
    """Per box: 1 wholly inside the closed rectangle, 0 wholly outside, -1 to test point by point."""
    lo_x, hi_x = sorted((x0, x1))
    lo_y, hi_y = sorted((y0, y1))
    out = np.full(bx0.shape, -1, dtype=np.int8)
    out[(bx0 >= lo_x) & (bx1 <= hi_x) & (by0 >= lo_y) & (by1 <= hi_y)] = 1
    out[(bx1 < lo_x) | (bx0 > hi_x) | (by1 < lo_y) | (by0 > hi_y)] = 0
    return out


def polygon_class(bx0, bx1, by0, by1, poly: np.ndarray, res: int = 256) -> np.ndarray:
    """Per box: 1 wholly inside the polygon (even-odd), 0 wholly outside, -1 to test point by point.

    The polygon is rasterised over its bounding box (``res`` pixels along the longer side): pixels
    its edges touch are marked (edges sampled every ¼ pixel, each sample's pixel and its eight
    neighbours), every other pixel lies wholly on one side and takes its centre's side. A box is
    decided when every pixel it covers is unmarked and on the same side."""
    from pointspro.core.geometry.polygon import points_in_polygon

    poly = np.asarray(poly, dtype=np.float64)
    out = np.zeros(bx0.shape, dtype=np.int8)
    px0, py0 = poly.min(0)
    px1, py1 = poly.max(0)
    h = max(px1 - px0, py1 - py0, 1e-300) / res
    nx, ny = int((px1 - px0) / h) + 3, int((py1 - py0) / h) + 3
    ox, oy = px0 - h, py0 - h  # one pixel of margin all round
    cx = ox + h * (np.arange(nx) + 0.5)
    cy = oy + h * (np.arange(ny) + 0.5)
    gx, gy = np.meshgrid(cx, cy)
    inside = points_in_polygon(gx.ravel(), gy.ravel(), poly).reshape(ny, nx)
    edge = np.zeros((ny, nx), dtype=bool)
    a, b = poly, np.roll(poly, -1, axis=0)
    for (xa, ya), (xb, yb) in zip(a, b):
        k = int(np.ceil(4 * max(abs(xb - xa), abs(yb - ya)) / h)) + 1
        t = np.linspace(0.0, 1.0, k + 1)
        i = np.floor((xa + t * (xb - xa) - ox) / h).astype(np.int64)
        j = np.floor((ya + t * (yb - ya) - oy) / h).astype(np.int64)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                edge[np.clip(j + dj, 0, ny - 1), np.clip(i + di, 0, nx - 1)] = True
    sure_in = inside & ~edge
    sure_out = ~inside & ~edge

    def table(a):  # summed-area table with a zero row and column in front
        s = np.zeros((ny + 1, nx + 1), dtype=np.int64)
        s[1:, 1:] = a.cumsum(0).cumsum(1)
        return s
    s_in, s_out = table(sure_in), table(sure_out)
    # pixel ranges the boxes cover, clipped to the raster (beyond it: outside the polygon)
    i0 = np.floor((bx0 - ox) / h)
    i1 = np.floor((bx1 - ox) / h)
    j0 = np.floor((by0 - oy) / h)
    j1 = np.floor((by1 - oy) / h)
    within = (i0 >= 0) & (j0 >= 0) & (i1 <= nx - 1) & (j1 <= ny - 1)
    disjoint = (i1 < 0) | (j1 < 0) | (i0 > nx - 1) | (j0 > ny - 1) | ~np.isfinite(i0 + i1 + j0 + j1)
    a0 = np.clip(i0, 0, nx - 1).astype(np.int64)
    a1 = np.clip(i1, 0, nx - 1).astype(np.int64)
    b0 = np.clip(j0, 0, ny - 1).astype(np.int64)
    b1 = np.clip(j1, 0, ny - 1).astype(np.int64)
    area = (a1 - a0 + 1) * (b1 - b0 + 1)

    def count(s):
        return s[b1 + 1, a1 + 1] - s[b0, a1 + 1] - s[b1 + 1, a0] + s[b0, a0]
    out[:] = -1
    out[within & (count(s_in) == area)] = 1
    out[(count(s_out) == area) & ~(within & (count(s_in) == area))] = 0
    out[disjoint] = 0
    return out


#: clouds from this size on are selected through a CellIndex (below it every point is tested)
CELL_INDEX_FROM = 500_000
_index_lock = threading.Lock()
_index: dict = {}  # one entry: the cloud shown, its CellIndex (or the thread building it)


def prepare_cell_index(cloud) -> None:
    """Start building the cloud's CellIndex in a thread (numpy's sort releases the GIL), so the
    first selection after opening finds it ready. Only the last cloud's index is kept."""
    if cloud is None or cloud.n < CELL_INDEX_FROM:
        return
    with _index_lock:
        if _index.get("cloud") is cloud:
            return
        box: dict = {}
        t = threading.Thread(target=lambda: box.setdefault("index", CellIndex(cloud.xyz)), daemon=True)
        _index.clear()
        _index.update(cloud=cloud, thread=t, box=box)
        t.start()


def cell_index(cloud) -> CellIndex | None:
    """The cloud's CellIndex (waiting for the thread building it), None for a small cloud."""
    if cloud is None or cloud.n < CELL_INDEX_FROM:
        return None
    prepare_cell_index(cloud)
    with _index_lock:
        t, box = _index["thread"], _index["box"]
    t.join()
    if "index" not in box:  # the thread failed (memory): build it here, the error shows
        box["index"] = CellIndex(cloud.xyz)
    return box["index"]
