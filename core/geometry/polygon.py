"""Point-in-region tests in the plane: a polygon (the aperture step, the window's lasso) and an
axis-aligned rectangle (the window's rubber band)."""
from __future__ import annotations

import numpy as np


def points_in_polygon(x, y, poly: np.ndarray, closed: bool = False) -> np.ndarray:
    """Even-odd rule, vectorised over the points (loop over the polygon's edges only). ``closed``:
    the edges included — a point on an edge (within 1e-9 of the polygon's size) is inside, as a
    point on a circular aperture's rim is (the aperture step); the even-odd rule alone keeps the
    points on a square's left and bottom edges and drops those on its right and top ones, which a
    hand-drawn lasso (the window) does not mind and is not slowed for."""
    poly = np.asarray(poly, dtype=np.float64)
    inside = np.zeros(x.shape, dtype=bool)
    edge = np.zeros(x.shape, dtype=bool)
    tol = 1e-9 * max(float(np.ptp(poly[:, 0])), float(np.ptp(poly[:, 1])), 1e-300)
    xj, yj = poly[-1]
    for xi, yi in poly:
        crosses = (yi > y) != (yj > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xint = (xj - xi) * (y - yi) / (yj - yi) + xi
        inside ^= crosses & (x < xint)
        if closed:
            edge |= _on_segment(x, y, xi, yi, xj, yj, tol)
        xj, yj = xi, yi
    return inside | edge


def _on_segment(x, y, x0, y0, x1, y1, tol) -> np.ndarray:
    """Points within ``tol`` of the segment (x0, y0)–(x1, y1)."""
    dx, dy = x1 - x0, y1 - y0
    L2 = dx * dx + dy * dy
    if L2 == 0.0:
        return np.hypot(x - x0, y - y0) <= tol
    t = np.clip(((x - x0) * dx + (y - y0) * dy) / L2, 0.0, 1.0)
    return np.hypot(x - (x0 + t * dx), y - (y0 + t * dy)) <= tol


def in_rectangle(x, y, x0, x1, y0, y1) -> np.ndarray:
    """Mask of the points inside the axis-aligned rectangle (corners in any order, edges included):
    the map's rectangle in mm and the 3D view's in screen pixels."""
    lo_x, hi_x = sorted((x0, x1))
    lo_y, hi_y = sorted((y0, y1))
    return (x >= lo_x) & (x <= hi_x) & (y >= lo_y) & (y <= hi_y)


def self_intersection(poly) -> tuple[int, int] | None:
    """(i, j) of two edges of the closed polygon ``poly`` (n × 2, edge i from vertex i to i + 1) that
    cross properly — each passing through the other's interior — or None. A bow-tie "aperture" has
    no inside its user can mean. Edges that only touch or run along each other are allowed: a ring
    whose last vertex repeats the first, a repeated vertex, and a keyhole (a hole joined to the
    outline by a cut walked both ways) are what even-odd filling reads as meant (a review).
    O(n²): apertures have tens of vertices."""
    p = np.asarray(poly, dtype=np.float64)
    n = len(p)
    a, b = p, np.roll(p, -1, axis=0)

    def orient(o, q, r):
        return np.sign((q[..., 0] - o[..., 0]) * (r[..., 1] - o[..., 1])
                       - (q[..., 1] - o[..., 1]) * (r[..., 0] - o[..., 0]))

    for i in range(n - 1):
        j = np.arange(i + 1, n)
        d1, d2 = orient(a[i], b[i], a[j]), orient(a[i], b[i], b[j])
        d3, d4 = orient(a[j], b[j], a[i]), orient(a[j], b[j], b[i])
        cross = (d1 * d2 < 0) & (d3 * d4 < 0)
        if cross.any():
            return i, int(j[np.argmax(cross)])
    return None
