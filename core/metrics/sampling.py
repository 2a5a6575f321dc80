"""How points sample their area: whether each stands for the same share of it.

Area-weighted least squares (the best-fit plane and sphere of ISO 14999-4) are plain least squares
over the points when the sampling is even — a pixel map, a raster — whatever the area's shape; a star
or a spiral of even angular steps crowds its centre, and there a joint Zernike fit over the disk stands
for the area weights (core.tolerance.quantities, plugins/zernike).
"""
from __future__ import annotations

import numpy as np

#: cells per side of the grid uniform_sampling counts points in, and the largest relative spread of
#: the counts of interior cells that is still uniform (a pixel grid: aliasing of the columns between
#: cells, ≤ 3 %; Poisson scatter of random points with ≥ 100 a cell: ~10 %)
_UNIFORM_CELLS = 16
_UNIFORM_SPREAD = 0.12


def on_lattice(x, y) -> bool:
    """Whether the points are pixels of a regular grid: along x and along y their distinct coordinates
    are whole multiples of one step (to 10⁻⁶ of it; the coordinates first rounded to 10⁻¹² of their
    span), however many pixels are missing. A pixel map of any size, a raster in the frame it was
    scanned in; not a raster turned by a pose fit, a star, a spiral."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.size < 9:
        return False
    # the first 20,000 points first: scattered points fail there in a millisecond, where sorting all
    # of a 10⁶-point cloud's coordinates takes 0.16 s
    return _steps_whole(x[:20_000], y[:20_000], x, y) and _steps_whole(x, y, x, y)


def _steps_whole(xs, ys, x, y) -> bool:
    for a, full in ((xs, x), (ys, y)):
        span = float(np.ptp(full))
        if not span > 0:
            return False
        u = np.unique(np.round((a - full.min()) / (span * 1e-12)))
        if u.size < 2:
            continue  # a sample along one row: its y says nothing yet
        d = np.diff(u)
        k = d / d.min()
        # a grid's nodes, not a rounding quantum: the step spans the values in at most 4× as many
        # steps as there are distinct values (a star's coordinates differ by anything, down to the
        # 10⁻¹² quantum, of which every difference is a whole multiple)
        if (u[-1] - u[0]) / d.min() > 4 * u.size or np.max(np.abs(k - np.round(k))) > 1e-6:
            return False
    return True


def uniform_sampling(x, y) -> bool:
    """Whether the points sample their area evenly: on a regular grid (on_lattice: a pixel map, a
    raster as scanned), or — scattered points — the counts in the cells of a 16 × 16 grid over their
    box, taken where a cell and its four neighbours all hold points (the area's inside, not its edge),
    spreading by less than 12 % (needs ≥ 2,500 points: fewer stay with the joint fit). A star or a
    spiral of even angular steps crowds its centre (counts 3–50× the rim's): False, and the joint fit
    stands for the area weights. The grid test comes first so that a map's method does not depend on
    its pixel count (a review: a 49 × 49 map took the joint fit and a 50 × 50 one the plain fits, A
    0.177 against 0.121 µm for one surface)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if on_lattice(x, y):
        return True
    g = int(min(_UNIFORM_CELLS, np.sqrt(x.size / 100.0)))
    if g < 4 or not (np.ptp(x) > 0 and np.ptp(y) > 0):
        return False
    ix = np.minimum(((x - x.min()) / np.ptp(x) * g).astype(np.int64), g - 1)
    iy = np.minimum(((y - y.min()) / np.ptp(y) * g).astype(np.int64), g - 1)
    counts = np.bincount(iy * g + ix, minlength=g * g).reshape(g, g)
    full = counts > 0
    inner = full[1:-1, 1:-1] & full[:-2, 1:-1] & full[2:, 1:-1] & full[1:-1, :-2] & full[1:-1, 2:]
    c = counts[1:-1, 1:-1][inner].astype(np.float64)
    return c.size >= 9 and float(np.std(c) / np.mean(c)) < _UNIFORM_SPREAD


#: the share of the test disk the points must cover for the joint Zernike fit to stand for the
#: area-weighted fits (a disk of pixels: ~1; an annulus with a hole of 0.3 R: 0.91; a square map in
#: its circumscribed disk: 2/π = 0.64)
DISK_COVERAGE = 0.9
_COVER_CELLS = 64


def disk_coverage(x, y, center, radius) -> float:
    """The share of the disk (``center``, ``radius``) the points cover: of the cells of a grid over its
    bounding square whose centres lie inside the disk, those holding a point. The cells are no finer
    than about twice the points' spacing (0.5·√N a side, 4 to 64), so an evenly sampled disk covers it
    whole rather than leaving cells between its points empty."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    R = float(radius)
    if not R > 0 or x.size == 0:
        return 0.0
    g = int(np.clip(0.5 * np.sqrt(x.size), 4, _COVER_CELLS))
    if x.size > 1 << 17:  # every k-th point still puts dozens in each of the 64 × 64 cells
        k = x.size // (1 << 17)
        x, y = x[::k], y[::k]
    ix = np.floor((x - center[0] + R) / (2 * R) * g).astype(np.int64)
    iy = np.floor((y - center[1] + R) / (2 * R) * g).astype(np.int64)
    ok = (ix >= 0) & (ix < g) & (iy >= 0) & (iy < g)
    held = np.zeros((g, g), dtype=bool)
    held[iy[ok], ix[ok]] = True
    c = (np.arange(g) + 0.5) / g * 2 - 1
    inside = np.hypot(*np.meshgrid(c, c)) <= 1.0
    return float(held[inside].mean())


def plain_best_fits(x, y, center, radius) -> bool:
    """Whether piston, tilt and power are to be taken as the plain least-squares fits over the points
    (the area-weighted best-fit plane and sphere of ISO 14999-4) rather than from a joint Zernike fit
    over the disk: when the points sample their area evenly (uniform_sampling) and that area is not
    the disk (covering less than DISK_COVERAGE of it: a rectangular map, whose circumscribed disk has
    corners without points, where the higher terms trade with tilt and power). Over a covered disk
    the joint fit keeps the terms apart that a coarse pixel rim mixes in a plain fit (a 1,000-point
    raster of pure spherical aberration: A 0 against 0.007 µm)."""
    return disk_coverage(x, y, center, radius) < DISK_COVERAGE and uniform_sampling(x, y)
