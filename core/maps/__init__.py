"""Form-error maps: a smoothing B-spline surface of scattered points, sampled on a grid."""
from .bspline import TensorBSpline, fit_bspline
from .grid import MapGrid, grid_map

__all__ = ["TensorBSpline", "fit_bspline", "MapGrid", "grid_map"]
