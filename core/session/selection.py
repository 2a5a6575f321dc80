"""What the optician selects on the displayed cloud: masks of its points (rectangle, lasso,
threshold on a channel). Pure functions of the cloud; the window turns a mask into a deletion."""
from __future__ import annotations

import numpy as np

from ..cloud import PointCloud
from ..geometry.polygon import in_rectangle, points_in_polygon

__all__ = ["in_rectangle", "points_in_polygon", "rectangle", "lasso", "threshold"]


def rectangle(cloud: PointCloud, x0, x1, y0, y1) -> np.ndarray:
    """The points whose (x, y) lie in the rectangle (corners in any order, edges included)."""
    return in_rectangle(cloud.x, cloud.y, x0, x1, y0, y1)


def lasso(cloud: PointCloud, polygon) -> np.ndarray:
    """The points whose (x, y) lie inside the polygon [[x, y], …] (even-odd rule)."""
    return points_in_polygon(cloud.x, cloud.y, np.asarray(polygon, dtype=np.float64))


def threshold(cloud: PointCloud, channel: str, value: float, above: bool = True) -> np.ndarray:
    """The points whose ``channel`` (``z`` or any channel) is above (or below) ``value``."""
    v = cloud.z if channel == "z" else cloud[channel]
    return v > value if above else v < value
