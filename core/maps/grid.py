"""A form-error map on a regular grid and the files it is written to.

Grid nodes lie at integer multiples of the spacing (x = i·spacing, y = j·spacing in the cloud's
frame), so maps of the same part from different runs share nodes and subtract node by node. A node
carries a value only inside the clear aperture and inside the measured region (cells of half a knot
spacing that hold points, gaps of one cell closed); elsewhere it is NaN — a map never shows numbers
the measurement did not support unless extrapolation is asked for.

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

    def write_x3p(self, path: Path, revision: str = "2000") -> None:
        """ISO 25178-72 areal file: row r of the matrix is y index r, column c is x index c; the
        placement offset carries the first node's (x, y) so the file keeps the map's position.

        ``revision`` "2000" writes the 'ISO5436 - 2000' record that every reader takes (MountainsMap,
        Gwyddion, OpenGPS, SurfaceTopography — which refuses the newer one); "2017" writes
        'ISO25178-72:2017/DAM1' (x3pio reads both)."""
        import x3pio

        rev = {"2000": x3pio.Revision.ISO5436_2000,
               "2017": x3pio.Revision.ISO25178_72_2017_DAM1}[revision]
        placement = x3pio.Placement.translation(self.xs[0] * 1e-3, self.ys[0] * 1e-3, 0.0)
        x3pio.write(str(path), self.z * 1e-3, x_scale=self.spacing * 1e-3, y_scale=self.spacing * 1e-3,
                    placement=placement, coordinate_system=x3pio.CoordinateSystem.VIEW, revision=rev)


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
             center=(0.0, 0.0), extrapolate: bool = False) -> MapGrid:
    """Sample the spline at nodes (multiples of ``spacing``) inside the aperture circle (when given)
    and, unless ``extrapolate``, inside the measured region of points (px, py)."""
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
        keep &= ((xs[None, :] - center[0]) ** 2 + (ys[:, None] - center[1]) ** 2) <= (diameter / 2) ** 2
    if not extrapolate:
        keep &= coverage_mask(px, py, xs, ys, spline.h / 2.0)
        bx0, bx1, by0, by1 = spline.bounds
        keep &= ((xs[None, :] >= bx0) & (xs[None, :] <= bx1)) & ((ys[:, None] >= by0) & (ys[:, None] <= by1))
    z = np.where(keep, z, np.nan)
    return MapGrid(xs, ys, z, float(spacing))
