"""Point-in-region tests in the plane: a polygon (the aperture step, the window's lasso) and an
axis-aligned rectangle (the window's rubber band)."""
from __future__ import annotations

import numpy as np


def points_in_polygon(x, y, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorised over the points (loop over the polygon's edges only)."""
    inside = np.zeros(x.shape, dtype=bool)
    xj, yj = poly[-1]
    for xi, yi in poly:
        crosses = (yi > y) != (yj > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xint = (xj - xi) * (y - yi) / (yj - yi) + xi
        inside ^= crosses & (x < xint)
        xj, yj = xi, yi
    return inside


def in_rectangle(x, y, x0, x1, y0, y1) -> np.ndarray:
    """Mask of the points inside the axis-aligned rectangle (corners in any order, edges included):
    the map's rectangle in mm and the 3D view's in screen pixels."""
    lo_x, hi_x = sorted((x0, x1))
    lo_y, hi_y = sorted((y0, y1))
    return (x >= lo_x) & (x <= hi_x) & (y >= lo_y) & (y <= hi_y)
