"""PointsPro headless core: point clouds, nominal surfaces, geometry, pipeline, I/O and the CLI.

Nothing here imports Qt (checked by import-linter in the test suite); heavy libraries (open3d,
pymeshlab, pyvista) are imported lazily where they are used.
"""
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("pointspro")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

from .cloud import PointCloud  # noqa: E402
from .errors import Cancelled, DomainError, InputError, PointsProError, RecipeError  # noqa: E402

__all__ = ["PointCloud", "PointsProError", "InputError", "RecipeError", "DomainError", "Cancelled",
           "__version__"]
