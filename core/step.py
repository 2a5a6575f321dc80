"""The step contract (this module documents it; README "Steps" lists the built-in ones).

A step is a class with a stable ``id`` (what recipes name; never renamed), a ``title``, a ``Params``
pydantic model (extra keys forbidden, frozen, typed, with units, bounds and help) and
``run(cloud, params, ctx) -> StepResult``. It never prints, exits, opens a dialog or imports Qt; it
reports through ``ctx.log``, ``ctx.progress`` and the returned report.
"""
from __future__ import annotations

import logging
import os
import sys
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterable, Mapping

from pydantic import BaseModel, ConfigDict, Field, field_validator

from .cloud import PointCloud
from .progress import Progress
from .surfaces import NominalSurface


class Params(BaseModel):
    """Base of every step's parameters: extra keys forbidden, frozen, versioned.

    Declare fields with `param(...)` so each carries its unit and help. Bump ``schema_version`` when
    a field changes meaning and teach ``migrate`` to rewrite the old form.
    """

    # allow_inf_nan=False: NaN and ±inf are never a parameter (a pose dx of .inf wrote a cloud of
    # inf and NaN with exit 0; a NaN conic reached LAPACK as "SVD did not converge")
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False)
    schema_version: ClassVar[int] = 1

    @field_validator("*", mode="before")
    @classmethod
    def _booleans_are_true_or_false(cls, v, info):
        """A yes/no field takes true or false only: after YAML 1.2 (core/yamlio.py) `repair: yes` is
        the word "yes", which pydantic's lax mode would still take as True. And true or false is
        never a number: pydantic's lax mode takes `radius: true` as 1.0, `side: true` as 1 and
        `remove: [520, true]` as [520, 1] (core.yamlio.bool_as_number refuses them, naming the
        item)."""
        f = cls.model_fields.get(info.field_name)
        if f is None:
            return v
        if f.annotation in (bool, bool | None) and isinstance(v, str):
            from pydantic_core import PydanticCustomError

            raise PydanticCustomError("bool_word", "Input should be true or false (yes, no, on and off "
                                      "are words in YAML 1.2)")
        if f.annotation in (bool, bool | None) and isinstance(v, (int, float)) and not isinstance(v, bool):
            from pydantic_core import PydanticCustomError  # lax mode takes 1 and 0.0 as yes and no

            raise PydanticCustomError("bool_number", "Input should be true or false (got {got})", {"got": v})
        if f.annotation in (float, int, float | None, int | None) and isinstance(v, str):
            from .yamlio import NUMBER_TEXT, numeric_text

            if numeric_text(v):  # lax mode would read "1_290" or a quoted "1290" as the number
                from pydantic_core import PydanticCustomError

                raise PydanticCustomError("number_text", NUMBER_TEXT)
        if isinstance(v, (bool, list, tuple, dict)):
            from .yamlio import bool_as_number, number_as_text

            # and text inside a list or mapping where numbers are wanted: `remove: ['520']`,
            # `matrix: [[1_0, 0, 0, 0], …]` (1_0 is a word in YAML 1.2), which lax mode would read as
            # the numbers (a review: a ×10 scale ran with exit 0), refused as a single value is
            error = bool_as_number(f.annotation, v) or number_as_text(f.annotation, v)
            if error is not None:
                raise error
        return v

    @classmethod
    def migrate(cls, data: dict, from_version: int) -> dict:
        """Rewrite parameters written by ``from_version`` of this step into the current form."""
        if from_version > cls.schema_version:
            raise ValueError(f"written by a newer version ({from_version}) of this step "
                             f"than the installed one ({cls.schema_version})")
        return data


def param(default: Any = ..., *, unit: str | None = None, help: str, file: bool = False,
          **bounds) -> Any:
    """A step parameter with its unit and help text (shown in the GUI, `pointspro steps`, the CLI).
    ``file=True``: the value names a file (read through ``ctx.resolve``), so the batch checks, before
    any input runs, that it lies where the recipe may reach (see ``check_parameter_path``)."""
    extra = ({"unit": unit} if unit else {}) | ({"file": True} if file else {})
    return Field(default, description=help, json_schema_extra=extra or None, **bounds)


def file_parameters(params: BaseModel) -> dict[str, str]:
    """The set values of a step's ``file=True`` parameters, by name."""
    out = {}
    for name, f in type(params).model_fields.items():
        extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
        value = getattr(params, name, None)
        if extra.get("file") and isinstance(value, (str, Path)) and str(value):
            out[name] = str(value)
    return out


# --- where parameter files may lie ----------------------------------------------------------------
# A recipe is data shared between people and machines, not a permission: a file it names must lie in
# the recipe's folder, an input's folder or a folder allowed on the command line (--allow-path). The
# batch passes that list to each run (Context.allowed_dirs, sent with every job to the process pool
# and to Dask's workers); None (the window, scripts): any file the user gave is read.


def outside_allowed(path: Path, allowed: Iterable[Path]) -> str | None:
    """None when ``path`` (links followed, ``..`` removed) lies in one of ``allowed``; else the
    one-line reason naming the path and the --allow-path that would permit it."""
    real = Path(os.path.realpath(path))
    for d in allowed:
        if real.is_relative_to(os.path.realpath(d)):
            return None
    shown = str(path) if real == Path(path) else f"{path} (→ {real})"
    return (f"{shown} is outside the recipe's folder and the inputs' folders; a recipe may not "
            f"reach other files — to allow it, run with --allow-path {real.parent}")


# An artifact is written by the runner into the output folder: text, bytes, or a writer callable.
Artifact = str | bytes | Callable[[Path], None]


@dataclass
class StepResult:
    cloud: PointCloud
    report: dict = field(default_factory=dict)
    artifacts: dict[str, Artifact] = field(default_factory=dict)
    #: fits later stages of the same run may take instead of fitting again (core.pipeline.summarize:
    #: "pvr" from `zernike`, "slope_spline" from `bspline_map`), each with the arrays it was computed
    #: from, so a consumer can check by identity that the data are still those; never written
    reuse: dict = field(default_factory=dict)


@dataclass
class Context:
    """What a step may use besides its cloud and parameters."""

    progress: Progress = field(default_factory=Progress)
    log: logging.Logger = field(default_factory=lambda: logging.getLogger("pointspro.step"))
    surface: NominalSurface | None = None
    #: named auxiliary inputs (e.g. "fiducials": Path to a calibrated-fiducials file)
    inputs: Mapping[str, Path] = field(default_factory=dict)
    #: folder the recipe came from (relative paths in parameters are relative to it)
    base_dir: Path | None = None
    #: folders a parameter file may lie in besides ``base_dir`` (the batch: the inputs' folders and
    #: --allow-path); None: any file (the window, where the user chose or typed the path)
    allowed_dirs: tuple[Path, ...] | None = None

    def resolve(self, path: str | Path, param: str | None = None) -> Path:
        """A parameter's file path: relative paths are relative to the recipe's folder. With
        ``allowed_dirs`` set, a file outside them and the recipe's folder is a StepError naming the
        parameter (``param``), the path and the --allow-path that permits it."""
        p = Path(path)
        p = p if p.is_absolute() or self.base_dir is None else Path(self.base_dir) / p
        if self.allowed_dirs is not None:
            allowed = [*([self.base_dir] if self.base_dir is not None else []), *self.allowed_dirs]
            why = outside_allowed(p, allowed)
            if why:
                from .errors import StepError

                raise StepError(f"parameter '{param}': {why}" if param else why)
        return p

    def require_surface(self, step_id: str) -> NominalSurface:
        from .errors import StepError

        if self.surface is None:
            raise StepError(f"step '{step_id}' needs the recipe's nominal `surface:`")
        return self.surface


class Step:
    """Base class of steps. Subclasses set ``id``, ``title``, ``Params`` and implement ``run``."""

    id: ClassVar[str]
    title: ClassVar[str]
    Params: ClassVar[type[Params]] = Params
    #: one line for lists; the class docstring is the long help
    summary: ClassVar[str] = ""
    #: the step makes the cloud's ``residual`` channel, the form error (misalignment: z − sag in the
    #: part frame; register: the distance to the mesh). README, "Step order".
    makes_residual: ClassVar[bool] = False
    #: the step works on the form error: the ``residual`` channel when the cloud has one, else the
    #: heights z (its ``channel`` parameter, where it has one, left at "auto"). Such a step belongs
    #: after the step that makes the residual; core.recipe.check_step_order refuses it before.
    reads_residual: ClassVar[bool] = False
    #: the step moves the points and hands a residual it finds on untouched (probe_radius, dynamic,
    #: volumetric): after the step that makes the residual, that residual is the points' before the
    #: move. core.recipe.check_step_order refuses such a step unless the residual is made again after
    #: it before anything uses or writes it (core.pipeline's stale-residual check, at run time, too).
    moves_points: ClassVar[bool] = False
    #: the step drops a residual it finds (transform: it referred to the old frame); a step that reads
    #: the residual after it reads the heights z unless the residual is made again (check_step_order)
    drops_residual: ClassVar[bool] = False

    def run(self, cloud: PointCloud, params: Params, ctx: Context) -> StepResult:  # pragma: no cover
        raise NotImplementedError

    @classmethod
    def example_params(cls) -> dict:
        """Valid parameters for the contract test on the generic test cloud (defaults suffice)."""
        return {}

    @classmethod
    def example_cloud(cls, cloud: PointCloud) -> PointCloud:
        """The contract test's cloud for this step: the generic one, plus what the step needs (e.g.
        the time channels of on-machine data)."""
        return cloud


def with_example_residual(cloud: PointCloud) -> PointCloud:
    """The contract test's generic raster (the 002 asphere) as misalignment leaves it: a smooth form
    error of ~0.1 µm (power and astigmatism) as its residual — for the steps that work on the form
    error and refuse a curved part's sag (zernike, bspline_map, correction)."""
    import numpy as np

    r = np.hypot(cloud.x, cloud.y) / 650.0
    return cloud.replace(channels={**cloud.channels, "residual": 1e-4 * (2 * r**2 - 1)
                                   + 5e-5 * r**2 * np.cos(2 * np.arctan2(cloud.y, cloud.x))})


class _StepModule(types.ModuleType):
    """This module is also the Python API's ``pp.step(step_id, **params)`` (core/api.py): the name
    ``pointspro.core.step`` is both the step contract (``from pointspro.core.step import Step``, what
    plugins import) and, called, one step ready to run on a cloud. A package's submodule attribute
    always wins over a function of the same name, so the module itself answers the call."""

    def __call__(self, step_id: str, /, **params):
        from .api import step

        return step(step_id, **params)


sys.modules[__name__].__class__ = _StepModule
