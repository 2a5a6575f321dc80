"""Nominal (design) surfaces: even asphere, XY-polynomial freeform, triangle mesh."""
from .base import NominalSurface
from .even_asphere import EvenAsphere
from .mesh import MeshSurface
from .spec import SURFACE_TYPES, parse_surface_spec, surface_from_spec
from .xy_polynomial import XYPolynomial

__all__ = ["NominalSurface", "EvenAsphere", "XYPolynomial", "MeshSurface", "SURFACE_TYPES",
           "parse_surface_spec", "surface_from_spec"]
