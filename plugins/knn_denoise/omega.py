"""The noise measure ω of paper 002 §5 (eq 18, as reconstructed in docs/references.md, paper 002).

    1. interpolate the residual D(x, y) onto a regular grid of spacing h (the paper: cubic, 1 mm);
    2. for a measured point P the neighbours are all grid nodes in the 2a × 2a square centred on P;
    3. ω(P) = | D(P) − mean of D over those nodes |   (z-distances, not Euclidean ones: D is µm, x, y
       are mm; the absolute value lets low points — the probe slipping off the edge — count too).

Vectorised: the window mean of every node is one box filter over the grid (values and a validity
mask filtered separately, so nodes outside the measured region do not count), and each point reads
the mean field at its own position (bilinear). No loop over points.

Interpolation. A raster (points on a lattice, the usual CMM grid) is interpolated by a cubic B-spline
on its lattice (`ndimage.map_coordinates`, order 3), nodes beyond the measured cells left empty.
Scattered points (star patterns, spirals): Clough–Tocher (scipy's `CloughTocher2DInterpolator`, C¹
piecewise cubic on a Delaunay triangulation — a lattice's co-circular points make qhull crawl, hence
the lattice path) is the paper's "cubic" and is used up to `CUBIC_MAX_POINTS`. Beyond that its Delaunay
step alone costs 12 s for 10⁶ points here, while such clouds are as dense as the 1 mm grid anyway: the
nodes then take the mean of the points in their cell, and the few empty nodes inside the footprint are
filled by normalised convolution (a 3 × 3 mask-weighted mean). The window mean (a box of
(2a/h + 1)² nodes) is insensitive to the difference.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# scipy is imported where it is used: a batch's own process validates the recipe without it (issue 17)

CUBIC_MAX_POINTS = 150_000


@dataclass
class OmegaField:
    omega: np.ndarray  # |D − window mean| at the points (same unit as D)
    signed: np.ndarray  # D − window mean
    interpolation: str


def _grid_axes(x, y, h):
    x0, y0 = x.min(), y.min()
    nx = int(np.floor((x.max() - x0) / h)) + 1
    ny = int(np.floor((y.max() - y0) / h)) + 1
    return x0, y0, nx, ny


def _clough_tocher(px, py, pd, nodes) -> np.ndarray:
    """Clough–Tocher on the Delaunay triangulation of (px, py), limited to each triangle's range.

    Its vertex gradients are estimated from the neighbours; two nearly coincident points with
    different noise give a wild gradient and the cubic patch overshoots by micrometres (seen here:
    12 µm from 20 nm of noise). Clipping each node to [min, max] of the corners of its triangle keeps
    the cubic where it is right and removes the overshoot; a spike's own triangles keep its height.
    NaN outside the convex hull.
    """
    from scipy.interpolate import CloughTocher2DInterpolator
    from scipy.spatial import Delaunay

    tri = Delaunay(np.column_stack([px, py]))
    vals = CloughTocher2DInterpolator(tri, pd)(nodes)
    simplex = tri.find_simplex(nodes)
    inside = simplex >= 0
    corners = pd[tri.simplices[simplex[inside]]]
    vals[inside] = np.clip(vals[inside], corners.min(axis=1), corners.max(axis=1))
    return vals


def _cubic_grid(x, y, d, x0, y0, nx, ny, h):
    X, Y = np.meshgrid(x0 + h * np.arange(nx), y0 + h * np.arange(ny))
    return _clough_tocher(x, y, d, np.column_stack([X.ravel(), Y.ravel()])).reshape(ny, nx)


def _lattice(x, y, max_fill: float = 4.0):
    """(x0, y0, pitch_x, pitch_y, i, j) when the points sit on a regular lattice, else None."""
    ux, uy = np.unique(x), np.unique(y)
    if len(ux) < 4 or len(uy) < 4 or len(ux) * len(uy) > max_fill * len(x):
        return None
    dx, dy = np.diff(ux), np.diff(uy)
    px, py = np.median(dx), np.median(dy)
    i = np.rint((x - ux[0]) / px)
    j = np.rint((y - uy[0]) / py)
    tol = 1e-6
    if (np.max(np.abs(ux[0] + i * px - x)) > tol * px or np.max(np.abs(uy[0] + j * py - y)) > tol * py):
        return None
    return ux[0], uy[0], px, py, i.astype(np.int64), j.astype(np.int64)


def _lattice_grid(x, y, d, lat, x0, y0, nx, ny, h):
    from scipy import ndimage

    lx0, ly0, px, py, i, j = lat
    L = np.full((j.max() + 1, i.max() + 1), np.nan)
    L[j, i] = d
    have = np.isfinite(L)
    # the spline needs values everywhere: extend the measured cells by their nearest neighbour
    near = ndimage.distance_transform_edt(~have, return_distances=False, return_indices=True)
    filled = L[tuple(near)]
    gx = x0 + h * np.arange(nx)
    gy = y0 + h * np.arange(ny)
    X, Y = np.meshgrid((gx - lx0) / px, (gy - ly0) / py)
    grid = ndimage.map_coordinates(filled, [Y.ravel(), X.ravel()], order=3, mode="nearest").reshape(ny, nx)
    # a node counts only where its lattice cell was measured (nothing invented beyond the aperture)
    ci = np.clip(np.rint(X).astype(np.int64), 0, L.shape[1] - 1)
    cj = np.clip(np.rint(Y).astype(np.int64), 0, L.shape[0] - 1)
    grid[~have[cj, ci]] = np.nan
    return grid


def _binned_grid(x, y, d, x0, y0, nx, ny, h):
    from scipy import ndimage

    ix = np.clip(np.rint((x - x0) / h).astype(np.int64), 0, nx - 1)
    iy = np.clip(np.rint((y - y0) / h).astype(np.int64), 0, ny - 1)
    cell = iy * nx + ix
    s = np.bincount(cell, weights=d, minlength=nx * ny).reshape(ny, nx)
    c = np.bincount(cell, minlength=nx * ny).reshape(ny, nx).astype(np.float64)
    grid = np.full((ny, nx), np.nan)
    have = c > 0
    grid[have] = s[have] / c[have]
    # fill holes inside the footprint: mask-weighted 3 × 3 mean of the filled neighbours
    w = ndimage.uniform_filter(have.astype(np.float64), 3, mode="constant")
    v = ndimage.uniform_filter(np.where(have, grid, 0.0), 3, mode="constant")
    hole = ~have & (w >= 4.5 / 9.0)  # at least half the neighbours measured: inside, not beyond
    grid[hole] = v[hole] / w[hole]
    return grid


class OmegaGrid:
    """ω of the kept points of a cloud, recomputed as points are set aside round by round.

    The grid frame (origin, size) is that of the whole cloud. After a removal the lattice and binned
    grids are rebuilt (cheap); the scattered cubic grid is patched locally: only the triangles around
    a removed point and the gradient estimates of their corners change, so the nodes within 2.5 local
    point spacings of it are interpolated again from the kept points within 5 spacings.
    """

    def __init__(self, x, y, d, window: float, spacing: float, interpolation: str = "auto"):
        self.x = np.asarray(x, dtype=np.float64)
        self.y = np.asarray(y, dtype=np.float64)
        self.d = np.asarray(d, dtype=np.float64)
        self.h = float(spacing)
        self.size = 2 * int(round(window / self.h)) + 1  # the 2a × 2a square, in nodes
        self.x0, self.y0, self.nx, self.ny = _grid_axes(self.x, self.y, self.h)
        self.keep = np.ones(len(self.x), dtype=bool)
        if interpolation == "auto":
            interpolation = "cubic" if len(self.x) <= CUBIC_MAX_POINTS else "binned"
        self.lattice = _lattice(self.x, self.y) if interpolation == "cubic" else None
        if self.lattice is not None:
            interpolation = "cubic (lattice spline)"
        self.interpolation = interpolation
        self.grid = self._build()

    def _build(self) -> np.ndarray:
        k = self.keep
        args = (self.x[k], self.y[k], self.d[k], self.x0, self.y0, self.nx, self.ny, self.h)
        if self.lattice is not None:
            lx0, ly0, px, py, i, j = self.lattice
            return _lattice_grid(*args[:3], (lx0, ly0, px, py, i[k], j[k]), *args[3:])
        if self.interpolation == "cubic":
            return _cubic_grid(*args)
        return _binned_grid(*args)

    def remove(self, positions) -> None:
        positions = np.asarray(positions, dtype=np.int64)
        self.keep[positions] = False
        if self.interpolation != "cubic" or len(positions) == 0:
            self.grid = self._build()
            return
        from scipy.spatial import cKDTree

        kept = np.flatnonzero(self.keep)
        tree = cKDTree(np.column_stack([self.x[kept], self.y[kept]]))
        rx, ry = self.x[positions], self.y[positions]
        spacing = tree.query(np.column_stack([rx, ry]), k=min(6, len(kept)))[0][:, -1]
        near = np.unique(np.concatenate(tree.query_ball_point(np.column_stack([rx, ry]), r=5.0 * spacing)))
        patch = np.zeros((self.ny, self.nx), dtype=bool)
        for cx, cy, s in zip(rx, ry, 2.5 * spacing):  # a box per removed point: few points
            i0, i1 = int(np.floor((cx - s - self.x0) / self.h)), int(np.ceil((cx + s - self.x0) / self.h))
            j0, j1 = int(np.floor((cy - s - self.y0) / self.h)), int(np.ceil((cy + s - self.y0) / self.h))
            patch[max(j0, 0):max(j1 + 1, 0), max(i0, 0):max(i1 + 1, 0)] = True
        jj, ii = np.nonzero(patch)
        nodes = np.column_stack([self.x0 + self.h * ii, self.y0 + self.h * jj])
        sel = kept[near]
        if len(sel) >= 3:
            self.grid[jj, ii] = _clough_tocher(self.x[sel], self.y[sel], self.d[sel], nodes)
        else:
            self.grid[jj, ii] = np.nan

    def field(self) -> OmegaField:
        """ω of the kept points (in the order of np.flatnonzero(keep))."""
        from scipy import ndimage

        grid = self.grid
        valid = np.isfinite(grid)
        num = ndimage.uniform_filter(np.where(valid, grid, 0.0), self.size, mode="constant")
        den = ndimage.uniform_filter(valid.astype(np.float64), self.size, mode="constant")
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = num / den
        # read the window-mean field at each point (bilinear; nodes are at x0 + i·h, y0 + j·h)
        mean = np.where(np.isfinite(mean), mean, 0.0)
        k = self.keep
        coords = np.vstack([(self.y[k] - self.y0) / self.h, (self.x[k] - self.x0) / self.h])
        m = ndimage.map_coordinates(mean, coords, order=1, mode="nearest")
        signed = self.d[k] - m
        return OmegaField(np.abs(signed), signed, self.interpolation)


def omega(x, y, d, window: float, spacing: float, interpolation: str = "auto") -> OmegaField:
    """ω at every point. x, y, window, spacing in mm; d in any unit (ω comes in the same)."""
    return OmegaGrid(x, y, d, window, spacing, interpolation).field()
