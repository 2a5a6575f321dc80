"""Geometry: the part pose and least-squares features (sphere, plane, circle) with uncertainties."""
from .fits import FitResult, fit_circle, fit_plane, fit_sphere
from .pose import Pose, apply_affine, rot_x, rot_y

__all__ = ["Pose", "apply_affine", "rot_x", "rot_y", "FitResult", "fit_sphere", "fit_plane",
           "fit_circle"]
