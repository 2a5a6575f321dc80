"""PointsPro headless core: point clouds, nominal surfaces, geometry, pipeline, I/O and the CLI.

From Python (README "From Python", docs/api.md)::

    import pointspro.core as pp
    cloud = pp.read("resources/example/asphere_cmm.csv")
    result = pp.run("resources/example/recipe.yaml", cloud)

Nothing here imports Qt (checked by import-linter in the test suite); heavy libraries (open3d,
pymeshlab, pyvista) are imported lazily where they are used, and so is the Python API (``read``,
``run``, ``step``, ``steps``, ``Result``…: PEP 562 module attributes), so ``pointspro --version``
stays quick.
"""
import logging as _logging
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("pointspro")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

# A library never prints through logging's last-resort handler: scripts and notebooks see our log
# records only when they configure logging (the CLI's --verbose does).
_logging.getLogger("pointspro").addHandler(_logging.NullHandler())

from .cloud import PointCloud  # noqa: E402
from .errors import Cancelled, DomainError, InputError, PointsProError, RecipeError, StepError  # noqa: E402
from .progress import CancelToken  # noqa: E402

#: the Python API, imported from core.api on first use
_API = ("read", "write", "run", "step", "steps", "load", "Result", "StepRunner", "StepInfo",
        "StepCatalog")


def __getattr__(name):
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'pointspro.core' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_API])


__all__ = ["read", "write", "run", "step", "steps", "load", "Result", "StepRunner", "StepInfo",
           "StepCatalog", "PointCloud", "CancelToken", "PointsProError", "InputError", "RecipeError",
           "DomainError", "StepError", "Cancelled", "__version__"]
