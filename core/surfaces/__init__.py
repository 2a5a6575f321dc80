"""Nominal (design) surfaces: even asphere, Forbes Q-con/Q-bfs, XY-polynomial freeform, triangle mesh."""
from .base import NominalSurface
from .even_asphere import EvenAsphere
from .forbes import QBfsAsphere, QConAsphere
from .mesh import MeshSurface
from .rotational import SurfaceOfRevolution
from .spec import SURFACE_TYPES, parse_surface_spec, surface_from_spec
from .xy_polynomial import XYPolynomial

__all__ = ["NominalSurface", "SurfaceOfRevolution", "EvenAsphere", "QConAsphere", "QBfsAsphere", "XYPolynomial", "MeshSurface", "SURFACE_TYPES",
           "parse_surface_spec", "surface_from_spec"]
