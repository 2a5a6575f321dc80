"""A form-error map on a regular grid and the files it is written to.

Grid nodes lie at integer multiples of the spacing (x = i·spacing, y = j·spacing in the cloud's
frame), so maps of the same part from different runs share nodes and subtract node by node. A node
carries a value only inside the clear aperture and inside the measured region: in a cell of half a
knot spacing that holds points (gaps of one cell closed) *and* inside the convex hull of the points
around it (within ``HULL_REACH`` × the sampling scale: ``inside_the_points``) — so no node lies beyond
the outermost point, the edge of a bore, a dropout strip or a missing sector. Elsewhere it is NaN — a
map never shows numbers the measurement did not support unless extrapolation is asked for. The cells
alone let nodes reach up to half a knot beyond the data, where the spline is extrapolated noise: with
30 nm point noise on a 100 mm disk those nodes erred by up to 434 nm and put the map's PV 11–44 %
above the truth (a review; tests/test_map_psd_review.py).

Files: ``map.csv`` (x, y, z in mm, the header ``x [mm],y [mm],z [mm]``, one row per valid node,
y-major rows), ``map.x3p`` (ISO 25178-72
through x3pio; heights in metres as the standard stores them, NaN = not measured), ``map.asc`` (plain
ASCII matrix for polishing machines: a commented header with origin, spacing and units, one text row
per grid row from the lowest y up, NaN outside).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .bspline import TensorBSpline

#: map.csv's header: names and units (docs/formats.md, Files PointsPro writes)
CSV_HEADER = "x [mm],y [mm],z [mm]\n"


@dataclass(frozen=True)
class MapGrid:
    xs: np.ndarray          # (nx,) node x (mm), ascending
    ys: np.ndarray          # (ny,) node y (mm), ascending
    z: np.ndarray           # (ny, nx) values (mm), NaN where not mapped
    spacing: float          # mm

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.z)

    def nodes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, z) of the valid nodes, y-major (row by row from the lowest y)."""
        X, Y = np.meshgrid(self.xs, self.ys)
        v = self.valid
        return X[v], Y[v], self.z[v]

    def write_csv(self, path: Path) -> None:
        """x, y, z (mm) of the valid nodes, shortest round-trip decimals; the header states the unit
        (``x [mm],y [mm],z [mm]``), so read_cloud reads the file back bit for bit."""
        from pointspro.core.io.formats import write_number_columns

        x, y, z = self.nodes()
        with open(path, "wb") as f:
            f.write(CSV_HEADER.encode("utf-8"))
            write_number_columns(f, (x, y, z))

    def write_ascii_matrix(self, path: Path, unit: str = "mm") -> None:
        scale = {"mm": 1.0, "um": 1e3, "nm": 1e6}[unit]
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(f"# PointsPro form-error map, ASCII matrix\n# columns {len(self.xs)} rows {len(self.ys)}\n"
                    f"# x0 {float(self.xs[0])!r} mm, y0 {float(self.ys[0])!r} mm, "
                    f"spacing {float(self.spacing)!r} mm\n"
                    f"# row i is y = y0 + i*spacing (lowest y first), column j is x = x0 + j*spacing\n"
                    f"# heights in {unit}; NaN = not measured\n")
            f.flush()
            # the numbers by Arrow's shortest round-trip formatting (core.io.formats.write_number_columns:
            # ~10× faster than repr per value, issue 17), one column of the table per map column;
            # a node without a value reads "NaN" as the header says (Arrow writes "nan")
            import io

            from pointspro.core.io.formats import write_number_columns

            z = self.z * scale
            z[~np.isfinite(z)] = np.nan
            buf = io.BytesIO()
            write_number_columns(buf, [np.ascontiguousarray(z[:, j]) for j in range(z.shape[1])], delimiter=" ")
            f.buffer.write(buf.getvalue().replace(b"nan", b"NaN"))

    def write_x3p(self, path: Path, revision: str = "2000", comment: str | None = None) -> None:
        """ISO 25178-72 areal file: row r of the matrix is y index r, column c is x index c; the
        placement offset carries the first node's (x, y) so the file keeps the map's position.

        ``revision`` "2000" writes the 'ISO5436 - 2000' record that every reader takes (MountainsMap,
        Gwyddion, OpenGPS, SurfaceTopography — which refuses the newer one); "2017" writes
        'ISO25178-72:2017/DAM1' (x3pio reads both). ``comment``: Record2's Comment — what the
        heights mean where it is not a form-error map (a correction's dz to add, a removal depth)."""
        import x3pio

        rev = {"2000": x3pio.Revision.ISO5436_2000,
               "2017": x3pio.Revision.ISO25178_72_2017_DAM1}[revision]
        placement = x3pio.Placement.translation(self.xs[0] * 1e-3, self.ys[0] * 1e-3, 0.0)
        x3pio.write(str(path), self.z * 1e-3, x_scale=self.spacing * 1e-3, y_scale=self.spacing * 1e-3,
                    placement=placement, coordinate_system=x3pio.CoordinateSystem.VIEW, revision=rev,
                    metadata=x3p_record(comment))


@dataclass(frozen=True)
class X3pWriter:
    """An artifact writer (core.step.Artifact) of ``grid`` as map.x3p with Record2's ``comment``."""
    grid: MapGrid
    comment: str | None = None

    def __call__(self, path: Path) -> None:
        self.grid.write_x3p(path, comment=self.comment)


def x3p_record(comment: str | None = None):
    """Record2 of a file PointsPro computed: PointsPro (and its version) as the software that made it
    — x3pio named itself — with a software probing system and no calibration date: ISO 25178-72's
    CalibrationDate is the instrument's last calibration, which computed data has none of (a review:
    every file claimed a calibration at the moment it was written). The 2000 revision's schema
    requires the element, so x3pio writes the creation date there; the 2017 revision leaves it out."""
    from dataclasses import replace

    import x3pio

    from pointspro.core import __version__

    # Creator named too (optional in the schema; a review read the file's creator as empty), and the
    # serial number said not to exist rather than left blank
    meta = x3pio.Metadata.for_software("PointsPro", __version__)
    meta = replace(meta, creator=f"PointsPro {__version__}",
                   instrument=replace(meta.instrument, serial="not available"))
    if comment:
        meta = replace(meta, comment=comment)
    return meta


def read_x3p_map(path: Path) -> MapGrid:
    """The inverse of MapGrid.write_x3p (tests, and maps handed back by other software)."""
    import x3pio

    f = x3pio.read(str(path))
    z = np.asarray(f.layers[0].z, dtype=np.float64) * 1e3
    hx = f.header.x.increment * 1e3
    hy = f.header.y.increment * 1e3
    off = getattr(f, "placement", None)
    ox, oy = (0.0, 0.0) if off is None else (off.offset[0] * 1e3, off.offset[1] * 1e3)
    ny, nx = z.shape
    return MapGrid(ox + hx * np.arange(nx), oy + hy * np.arange(ny), z, hx)


def coverage_mask(px, py, xs, ys, cell: float) -> np.ndarray:
    """(len(ys), len(xs)) True where a node lies in the measured region: in a cell of size ``cell``
    that holds points, after closing gaps of one cell (scipy.ndimage.binary_closing)."""
    from scipy import ndimage

    x0, y0 = xs[0] - cell, ys[0] - cell
    ncx = int(np.ceil((xs[-1] - x0) / cell)) + 2
    ncy = int(np.ceil((ys[-1] - y0) / cell)) + 2
    occ = np.zeros(ncy * ncx, dtype=bool)
    px, py = np.asarray(px), np.asarray(py)
    step = 1 << 18  # chunks: no full-length index columns (issue 26)
    for s in range(0, len(px), step):
        ix = np.floor((px[s:s + step] - x0) / cell).astype(np.intp)
        iy = np.floor((py[s:s + step] - y0) / cell).astype(np.intp)
        ok = (ix >= 0) & (ix < ncx) & (iy >= 0) & (iy < ncy)
        occ[iy[ok] * ncx + ix[ok]] = True
    occ = occ.reshape(ncy, ncx)
    occ |= ndimage.binary_closing(occ, structure=np.ones((3, 3), bool))
    jx = np.floor((xs - x0) / cell).astype(np.intp)
    jy = np.floor((ys - y0) / cell).astype(np.intp)
    return occ[np.ix_(jy, jx)]


#: a node is kept where it lies in the convex hull of the points within this many times the sampling
#: scale (the larger of the automatic knot spacing's point and gap terms: twice the mean point
#: spacing, twice the widest gaps of the scan pattern; core.maps.bspline.knot_spacing_terms) — far
#: enough to reach across a star's spokes and a spiral's turns at the rim, near enough to follow a
#: bore, a dropout strip or a missing sector
HULL_REACH = 2.0
#: the nearest points that first try to enclose a node (cheap); the rest see all within the reach
_FIRST_NEIGHBOURS = 16


def inside_the_points(px, py, xs, ys, keep, reach: float) -> np.ndarray:
    """``keep`` (len(ys), len(xs)) less the nodes that do not lie in the convex hull of the points
    within ``reach`` of them — nodes beyond the outermost point or the edge of a hole, where the
    spline is extrapolated. Inside the hull: no open half-plane through the node is empty of those
    points (their largest angular gap seen from the node is at most π); a node on a point is inside.

    ``xs``, ``ys``: ascending axes of one uniform spacing (grid_map's). In three passes, each looking
    only at what the one before left undecided: (1) a point in each of the four closed quadrants
    about the node, within the reach (occupied cells, ``_quadrants_hold_points``) — any half-plane
    through the node holds a whole quadrant, so the node is inside: all the interior but a band of
    a cell or two at the edge; (2) the same among its 16 nearest points, or one on it; (3) the
    angular gaps of all the points within the reach, thinned to the extremes in x and in y of cells
    of reach/16 (the hull to a small fraction of that), so a dense cloud or a finely sampled star
    costs little. Passes 1 and 2 only ever say "inside"; pass 3 decides the rest."""
    from scipy.spatial import cKDTree

    keep = np.asarray(keep, dtype=bool)
    if not keep.any() or not reach > 0:
        return keep
    xs = np.asarray(xs, dtype=np.float64)
    ys = np.asarray(ys, dtype=np.float64)
    iy, ix = np.nonzero(keep & ~_quadrants_hold_points(px, py, xs, ys, keep, reach))
    if ix.size == 0:
        return keep
    qx, qy = xs[ix], ys[iy]
    inside = np.zeros(ix.size, dtype=bool)
    bx, by = _points_near(px, py, qx, qy, reach)
    if bx.size:
        tree = cKDTree(np.column_stack([bx, by]))
        k = min(_FIRST_NEIGHBOURS, bx.size)
        dist, idx = tree.query(np.column_stack([qx, qy]), k=k, distance_upper_bound=reach)
        dist, idx = dist.reshape(ix.size, k), idx.reshape(ix.size, k)
        found = np.isfinite(dist)
        idx = np.where(found, idx, 0)
        dx = np.where(found, bx[idx] - qx[:, None], np.nan)
        dy = np.where(found, by[idx] - qy[:, None], np.nan)
        with np.errstate(invalid="ignore"):
            inside = (((dx >= 0) & (dy >= 0)).any(axis=1) & ((dx <= 0) & (dy >= 0)).any(axis=1)
                      & ((dx <= 0) & (dy <= 0)).any(axis=1) & ((dx >= 0) & (dy <= 0)).any(axis=1))
        inside |= dist[:, 0] <= 1e-9 * reach  # on a point
        del tree, bx, by
    todo = np.nonzero(~inside)[0]
    if todo.size:
        q = np.column_stack([qx[todo], qy[todo]])
        bx, by = _thinned(*_points_near(px, py, qx[todo], qy[todo], reach), reach / 16.0)
        if bx.size:
            pairs = cKDTree(q).sparse_distance_matrix(cKDTree(np.column_stack([bx, by])), reach,
                                                      output_type="ndarray")
            inside[todo] = _enclosed(q, pairs["i"], pairs["j"], pairs["v"], bx, by, reach)
    out = keep.copy()
    out[iy[~inside], ix[~inside]] = False
    return out


def _quadrants_hold_points(px, py, xs, ys, keep, reach) -> np.ndarray:
    """(len(ys), len(xs)): ``keep`` and each of the node's four closed quadrants holds a point within
    ``reach``.

    Cells of the node spacing / k (k ≥ 1) with the nodes at cell corners, so a quadrant is whole
    cells: a rectangle of a × b cells at the node's corner lies within the reach when its far corner
    does, a² + b² ≤ (reach/cell)²; a staircase of such rectangles covers most of the quarter disk.
    Occupied cells are counted by prefix sums: the squarest rectangle shifted over the whole grid at
    once, the others only at the nodes it left. k is the smallest with reach ≥ 6 cells, at most 4
    (the cells: at most 16 × the nodes); where the reach is shorter than a cell's diagonal nothing
    is decided here."""
    none = np.zeros((len(ys), len(xs)), dtype=bool)
    d = float(xs[1] - xs[0]) if len(xs) > 1 else float(ys[1] - ys[0]) if len(ys) > 1 else 0.0
    if not d > 0 or not (np.allclose(np.diff(xs), d, rtol=1e-9, atol=0)
                         and np.allclose(np.diff(ys), d, rtol=1e-9, atol=0)):
        return none  # not one uniform spacing: the later passes decide every node
    k = int(min(max(np.ceil(6.0 * d / reach), 1), 4))
    cell = d / k
    n = reach / cell  # the reach in cells
    rects = [(int(np.floor(np.sqrt(max(n * n - b * b, 0.0)) * (1 - 1e-12))), b) for b in range(1, int(n) + 1)]
    rects = [(a, b) for a, b in rects if a >= 1]
    if not rects:
        return none
    best = max(rects, key=lambda r: r[0] * r[1])
    if len(rects) > 8:  # a staircase of 8 steps at most
        rects = [rects[i] for i in np.unique(np.linspace(0, len(rects) - 1, 8).round().astype(int))]
    rects = [best] + [r for r in rects if r != best]
    pad = max(max(a for a, _ in rects), max(b for _, b in rects)) + 1
    ny, nx = len(ys), len(xs)
    ncy, ncx = (ny - 1) * k + 2 * pad, (nx - 1) * k + 2 * pad
    x0, y0 = float(xs[0]) - pad * cell, float(ys[0]) - pad * cell
    occ = np.zeros(ncy * ncx, dtype=bool)
    px, py = np.asarray(px), np.asarray(py)
    step = 1 << 18  # chunks: no full-length index columns (issue 26)
    for s in range(0, len(px), step):
        cx = np.floor((px[s:s + step] - x0) / cell)
        cy = np.floor((py[s:s + step] - y0) / cell)
        ok = (cx >= 0) & (cx < ncx) & (cy >= 0) & (cy < ncy)
        occ[cy[ok].astype(np.intp) * ncx + cx[ok].astype(np.intp)] = True
    # S[r, q]: occupied cells in rows < r and columns < q
    S = np.zeros((ncy + 1, ncx + 1), dtype=np.int64 if ncy * ncx >= 2**31 else np.int32)
    np.cumsum(occ.reshape(ncy, ncx), axis=0, dtype=S.dtype, out=S[1:, 1:])
    del occ
    np.cumsum(S[1:, 1:], axis=1, out=S[1:, 1:])
    flat = S.ravel()
    w = ncx + 1

    def at(dr, dq):  # S at every node's corner shifted by (dr, dq) cells: (ny, nx)
        r, q = pad + dr, pad + dq
        return S[r:r + (ny - 1) * k + 1:k, q:q + (nx - 1) * k + 1:k]

    out = np.asarray(keep, dtype=bool).copy()
    for sy, sx in ((1, 1), (1, -1), (-1, 1), (-1, -1)):  # the quadrants
        # rows [r0, r1) and columns [q0, q1) of cells from the node's corner, per rectangle
        spans = [(0, a, 0, b) if sy > 0 else (-a, 0, 0, b) for a, b in rects]
        spans = [(r0, r1, q0, q1) if sx > 0 else (r0, r1, -q1, -q0) for r0, r1, q0, q1 in spans]
        r0, r1, q0, q1 = spans[0]
        rest = np.flatnonzero(out & ((at(r1, q1) - at(r0, q1) - at(r1, q0) + at(r0, q0)) == 0))
        base = (pad + k * (rest // nx)) * w + pad + k * (rest % nx)  # each node's corner in S
        for r0, r1, q0, q1 in spans[1:]:
            if rest.size == 0:
                break
            hit = (flat[base + r1 * w + q1] - flat[base + r0 * w + q1] - flat[base + r1 * w + q0]
                   + flat[base + r0 * w + q0]) > 0
            rest, base = rest[~hit], base[~hit]
        out.ravel()[rest] = False
    return out


def _enclosed(q, i, j, d, bx, by, reach) -> np.ndarray:
    """Per node q[n]: its pairs (i == n) with points j at distances d surround it — the largest gap
    between the directions to them is at most π (10⁻⁶ rad of rounding allowed) — or one is on it."""
    n = len(q)
    on = np.zeros(n, dtype=bool)
    at = d <= 1e-9 * reach
    on[i[at]] = True
    i, j = i[~at], j[~at]
    if i.size == 0:
        return on
    ang = np.arctan2(by[j] - q[i, 1], bx[j] - q[i, 0])
    order = np.lexsort((ang, i))
    i, ang = i[order], ang[order]
    count = np.bincount(i, minlength=n)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    has = count > 0
    widest = np.full(n, 2 * np.pi)  # no point around: nothing encloses it
    # the wrap-around gap: from the last direction back to the first
    widest[has] = ang[first[has]] + 2 * np.pi - ang[first[has] + count[has] - 1]
    if i.size > 1:
        same = i[1:] == i[:-1]
        g = np.diff(ang)[same]
        np.maximum.at(widest, i[1:][same], g)
    return on | (widest <= np.pi + 1e-6)


def _points_near(px, py, qx, qy, reach):
    """The points within about ``reach`` of the nodes (qx, qy) — those in cells of size reach next
    to a node's cell — in chunks (no full-length index columns; issue 26)."""
    px, py = np.asarray(px), np.asarray(py)
    x0, y0 = float(qx.min()) - 2 * reach, float(qy.min()) - 2 * reach
    ncx = int(np.floor((float(qx.max()) + 2 * reach - x0) / reach)) + 1
    ncy = int(np.floor((float(qy.max()) + 2 * reach - y0) / reach)) + 1
    near = np.zeros((ncy, ncx), dtype=bool)
    near[np.floor((qy - y0) / reach).astype(np.intp), np.floor((qx - x0) / reach).astype(np.intp)] = True
    from scipy import ndimage

    near = ndimage.binary_dilation(near, structure=np.ones((3, 3), bool))
    flat = near.ravel()
    sx, sy = [], []
    step = 1 << 18
    for s in range(0, len(px), step):
        cx = np.floor((px[s:s + step] - x0) / reach)
        cy = np.floor((py[s:s + step] - y0) / reach)
        ok = (cx >= 0) & (cx < ncx) & (cy >= 0) & (cy < ncy)
        ok[ok] = flat[cy[ok].astype(np.intp) * ncx + cx[ok].astype(np.intp)]
        sx.append(np.asarray(px[s:s + step][ok], dtype=np.float64))
        sy.append(np.asarray(py[s:s + step][ok], dtype=np.float64))
    bx = np.concatenate(sx) if sx else np.zeros(0)
    by = np.concatenate(sy) if sy else np.zeros(0)
    return bx, by


def _thinned(bx, by, fine):
    """The points (bx, by) that are the lowest or the highest in x or in y of their cell of size
    ``fine``: the hull of each cell's points within a fraction of ``fine``, at most 4 a cell."""
    if bx.size < 2:
        return bx, by
    x0, y0 = float(bx.min()), float(by.min())
    ncx = int((float(bx.max()) - x0) / fine) + 2
    cid = np.floor((by - y0) / fine).astype(np.int64) * ncx + np.floor((bx - x0) / fine).astype(np.int64)
    pick = np.zeros(bx.size, dtype=bool)
    for key in (bx, by):  # the lowest and the highest of each fine cell in x, then in y
        o = np.lexsort((key, cid))
        c = cid[o]
        edge = np.flatnonzero(c[1:] != c[:-1])
        pick[o[np.concatenate([[0], edge + 1])]] = True
        pick[o[np.concatenate([edge, [c.size - 1]])]] = True
    return bx[pick], by[pick]


def nice_spacing(v: float) -> float:
    """The largest of 1, 2, 5 × 10^k not above v (mm): grid spacings people can read (the automatic
    spacing of `bspline_map`'s and `correction`'s grids, half the knot spacing)."""
    e = np.floor(np.log10(v))
    for m in (5.0, 2.0, 1.0):
        if m * 10**e <= v:
            return float(m * 10**e)
    return float(10**e)


def node_axis(lo: float, hi: float, spacing: float) -> np.ndarray:
    i0 = int(np.ceil(lo / spacing - 1e-9))
    i1 = int(np.floor(hi / spacing + 1e-9))
    return spacing * np.arange(i0, i1 + 1, dtype=np.float64)


def grid_map(spline: TensorBSpline, spacing: float, px, py, *, diameter: float | None = None,
             center=(0.0, 0.0), extrapolate: bool = False, inner_diameter: float = 0.0) -> MapGrid:
    """Sample the spline at nodes (multiples of ``spacing``) inside the aperture circle (when given;
    outside its hole of ``inner_diameter``, an annular clear aperture) and, unless ``extrapolate``,
    inside the measured region of points (px, py): coverage_mask's cells of half a knot, and inside
    the points' hull around each node (inside_the_points; module doc)."""
    px = np.asarray(px, dtype=np.float64)
    py = np.asarray(py, dtype=np.float64)
    if diameter is not None:
        r = diameter / 2.0
        lo_x, hi_x, lo_y, hi_y = center[0] - r, center[0] + r, center[1] - r, center[1] + r
    else:
        lo_x, hi_x, lo_y, hi_y = px.min(), px.max(), py.min(), py.max()
    if not extrapolate:  # nodes beyond the spline's box are masked below: the grid need not hold
        bx0, bx1, by0, by1 = spline.bounds  # them (a 100 mm patch of a 1300 mm part: 1 % of the nodes)
        lo_x, hi_x, lo_y, hi_y = max(lo_x, bx0), min(hi_x, bx1), max(lo_y, by0), min(hi_y, by1)
    # the node counts before the nodes: spacing 1e-9 mm asked numpy for 9.5 TiB (MemoryError)
    nx = np.floor(hi_x / spacing + 1e-9) - np.ceil(lo_x / spacing - 1e-9) + 1
    ny = np.floor(hi_y / spacing + 1e-9) - np.ceil(lo_y / spacing - 1e-9) + 1
    if nx > 25_000_000 or ny > 25_000_000 or nx * ny > 25_000_000:  # (1e-300 mm: nx·ny overflows)
        raise ValueError(f"a {nx:.4g} × {ny:.4g} map at spacing {spacing:g} mm is too large (at most "
                         "25 million nodes); use a larger spacing")
    if nx < 2 or ny < 2:  # a spacing beyond the region's size: one node, RMS and PV 0, exit 0
        span = max(hi_x - lo_x, hi_y - lo_y)
        raise ValueError(f"spacing {spacing:g} mm leaves {max(nx, 0):.0f} × {max(ny, 0):.0f} map nodes over "
                         f"the {span:.4g} mm region; use a smaller spacing (≤ {span / 4:.4g} mm puts ≥ 3 across)")
    xs = node_axis(lo_x, hi_x, spacing)
    ys = node_axis(lo_y, hi_y, spacing)
    z = spline.grid(xs, ys)
    keep = np.ones(z.shape, dtype=bool)
    if diameter is not None:
        rr = (xs[None, :] - center[0]) ** 2 + (ys[:, None] - center[1]) ** 2
        keep &= rr <= (diameter / 2) ** 2
        if inner_diameter > 0:  # the annulus's hole: no map there (a review: 393 nodes of a 400 mm hole)
            keep &= rr >= (inner_diameter / 2) ** 2
    if not extrapolate:
        keep &= coverage_mask(px, py, xs, ys, spline.h / 2.0)
        bx0, bx1, by0, by1 = spline.bounds
        keep &= ((xs[None, :] >= bx0) & (xs[None, :] <= bx1)) & ((ys[:, None] >= by0) & (ys[:, None] <= by1))
        keep = inside_the_points(px, py, xs, ys, keep, hull_reach(spline, px, py))
    z = np.where(keep, z, np.nan)
    return MapGrid(xs, ys, z, float(spacing))


def hull_reach(spline: TensorBSpline, px, py) -> float:
    """How far around a node ``inside_the_points`` looks (mm): HULL_REACH × the sampling scale —
    the map's rule, shared by the correction's error map (core/correction/compute.py)."""
    return HULL_REACH * _sampling_scale(spline, px, py)


def _sampling_scale(spline: TensorBSpline, px, py) -> float:
    """The larger of knot_spacing_terms' ``points`` and ``gaps`` (mm): the automatic knots' own, else
    measured here (knots given by hand); 0 where the points span no area (nothing is trimmed)."""
    t = spline.knot_terms
    if not t:
        from .bspline import knot_spacing_terms

        try:
            t = knot_spacing_terms(px, py)
        except ValueError:
            return 0.0
    return float(max(t["points"], t["gaps"]))
