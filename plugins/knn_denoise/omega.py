"""The noise measure ω of paper 002 §5 (eq 18, as reconstructed in shared/papers/README.md).

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
from scipy import ndimage

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


def _cubic_grid(x, y, d, x0, y0, nx, ny, h):
    """Clough–Tocher on the Delaunay triangulation, limited to the range of each triangle's corners.

    Its vertex gradients are estimated from the neighbours; two nearly coincident points with
    different noise give a wild gradient and the cubic patch overshoots by micrometres (seen here:
    12 µm from 20 nm of noise). Clipping each node to [min, max] of the corners of its triangle keeps
    the cubic where it is right and removes the overshoot; a spike's own triangles keep its height.
    """
    from scipy.interpolate import CloughTocher2DInterpolator
    from scipy.spatial import Delaunay

    gx = x0 + h * np.arange(nx)
    gy = y0 + h * np.arange(ny)
    tri = Delaunay(np.column_stack([x, y]))
    X, Y = np.meshgrid(gx, gy)
    nodes = np.column_stack([X.ravel(), Y.ravel()])
    grid = CloughTocher2DInterpolator(tri, d)(nodes)  # NaN outside the convex hull
    simplex = tri.find_simplex(nodes)
    inside = simplex >= 0
    corners = d[tri.simplices[simplex[inside]]]
    grid[inside] = np.clip(grid[inside], corners.min(axis=1), corners.max(axis=1))
    return grid.reshape(ny, nx)


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


def omega(x, y, d, window: float, spacing: float, interpolation: str = "auto") -> OmegaField:
    """ω at every point. x, y, window, spacing in mm; d in any unit (ω comes in the same)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    h = float(spacing)
    x0, y0, nx, ny = _grid_axes(x, y, h)
    if interpolation == "auto":
        interpolation = "cubic" if len(x) <= CUBIC_MAX_POINTS else "binned"
    lat = _lattice(x, y) if interpolation == "cubic" else None
    if lat is not None:
        interpolation = "cubic (lattice spline)"
        grid = _lattice_grid(x, y, d, lat, x0, y0, nx, ny, h)
    elif interpolation == "cubic":
        grid = _cubic_grid(x, y, d, x0, y0, nx, ny, h)
    else:
        grid = _binned_grid(x, y, d, x0, y0, nx, ny, h)
    valid = np.isfinite(grid)
    size = 2 * int(round(window / h)) + 1  # the 2a × 2a square, in nodes
    num = ndimage.uniform_filter(np.where(valid, grid, 0.0), size, mode="constant")
    den = ndimage.uniform_filter(valid.astype(np.float64), size, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = num / den
    # read the window-mean field at each point (bilinear; nodes are at x0 + i·h, y0 + j·h)
    mean = np.where(np.isfinite(mean), mean, 0.0)
    coords = np.vstack([(y - y0) / h, (x - x0) / h])
    m = ndimage.map_coordinates(mean, coords, order=1, mode="nearest")
    signed = d - m
    return OmegaField(np.abs(signed), signed, interpolation)
