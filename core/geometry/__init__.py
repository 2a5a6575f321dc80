"""Geometry: the part pose, least-squares features (sphere, plane, circle) with uncertainties, and
point-in-region tests in the plane."""
from .fits import FitResult, fit_circle, fit_plane, fit_sphere
from .polygon import in_rectangle, points_in_polygon
from .pose import Pose, apply_affine, rot_x, rot_y

__all__ = ["Pose", "apply_affine", "rot_x", "rot_y", "FitResult", "fit_sphere", "fit_plane",
           "fit_circle", "points_in_polygon", "in_rectangle"]
