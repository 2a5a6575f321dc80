"""Nominal surfaces as written in recipes and models (the `surface:` key), validated with pydantic.

    surface: {type: even_asphere, c: 3.3333333e-4, k: -0.98, A: {4: 7.0e-13, 6: 1.0e-19}, aperture: 1300}
    surface: {type: even_asphere, R: -1646.4, k: -0.9861, A: {4: 4e-16}}
    surface: {type: xy_polynomial, c: 0, k: 0, norm_radius: 50, terms: {x2y0: 1e-3, x0y2: -1e-3}}
    surface: {type: mesh, path: nominal.stl}        # path relative to the recipe file (STL/OBJ/OFF/PLY/3MF)
    surface: {type: mesh, path: part.obj, repair: true}   # repair a broken mesh instead of refusing it
    surface: {type: qcon, R: 500, k: -1, norm_radius: 50, a: [1e-4, -2e-5]}   # Forbes Q-con
    surface: {type: qbfs, R: 500, norm_radius: 50, a: [2e-3, 1e-4]}           # Forbes Q-bfs
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, field_validator, model_validator

from .base import NominalSurface
from .even_asphere import EvenAsphere
from .forbes import QBfsAsphere, QConAsphere
from .mesh import MeshSurface
from .xy_polynomial import XYPolynomial

_TERM = re.compile(r"^x(\d+)y(\d+)$")


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    aperture: float | None = Field(None, gt=0, description="clear-aperture diameter (mm)")


class _CurvatureSpec(_Spec):
    """A base sphere/conic given by its curvature c or its radius R, exactly one of them."""

    c: float | None = Field(None, description="vertex curvature 1/R (1/mm); give c or R")
    R: float | None = Field(None, description="vertex radius (mm); give c or R")

    @model_validator(mode="after")
    def _one_curvature(self):
        if (self.c is None) == (self.R is None):
            raise ValueError("give exactly one of c (1/mm) and R (mm)")
        if self.R == 0:
            raise ValueError("R must not be 0 (use c: 0 for a flat)")
        return self

    @property
    def curvature(self) -> float:
        return self.c if self.c is not None else 1.0 / self.R


class EvenAsphereSpec(_CurvatureSpec):
    type: Literal["even_asphere"]
    k: float = Field(0.0, description="conic constant")
    A: dict[int, float] = Field(default_factory=dict, description="aspheric coefficients A_n by power n")

    @field_validator("A")
    @classmethod
    def _powers(cls, v):
        for n in v:
            if n < 2 or n > 40:
                raise ValueError(f"power {n} out of range 2..40")
        return v

    def build(self, base_dir: Path | None = None) -> EvenAsphere:
        return EvenAsphere(self.curvature, self.k, self.A, self.aperture)


class XYPolynomialSpec(_Spec):
    type: Literal["xy_polynomial"]
    c: float = Field(0.0, description="base vertex curvature (1/mm)")
    k: float = Field(0.0, description="base conic constant")
    norm_radius: float = Field(1.0, gt=0, description="normalisation radius ρ (mm)")
    terms: dict[str, float] = Field(description="coefficients C_ij keyed 'x<i>y<j>' (mm)")

    @field_validator("terms")
    @classmethod
    def _names(cls, v):
        for name in v:
            if not _TERM.match(name):
                raise ValueError(f"term {name!r} is not of the form x<i>y<j>, e.g. x2y0")
        return v

    def build(self, base_dir: Path | None = None) -> XYPolynomial:
        terms = {tuple(int(g) for g in _TERM.match(k).groups()): v for k, v in self.terms.items()}
        return XYPolynomial(terms, self.c, self.k, self.norm_radius, self.aperture)


class MeshSpec(_Spec):
    type: Literal["mesh"]
    path: str = Field(description="STL, OBJ, OFF, PLY or 3MF triangle mesh, relative to the recipe")
    repair: bool = Field(False, description="repair a mesh with problems (non-manifold edges or "
                         "vertices, holes, duplicated vertices, zero-area faces, inconsistent "
                         "orientation) instead of refusing it")

    def build(self, base_dir: Path | None = None) -> MeshSurface:
        p = Path(self.path)
        if not p.is_absolute() and base_dir is not None:
            p = Path(base_dir) / p
        return MeshSurface.from_file(p, self.aperture, repair=self.repair)


class _ForbesSpec(_CurvatureSpec):
    """c/R: the vertex curvature (Q-con) or the best-fit sphere's (Q-bfs)."""

    norm_radius: float = Field(gt=0, description="normalisation radius r_n (mm), u = r / r_n")
    a: list[float] = Field(default_factory=list, description="coefficients a_0, a_1, … (mm)")


class QConSpec(_ForbesSpec):
    type: Literal["qcon"]
    k: float = Field(0.0, description="conic constant of the base")

    def build(self, base_dir: Path | None = None) -> QConAsphere:
        return QConAsphere(self.curvature, self.k, self.a, self.norm_radius, self.aperture)


class QBfsSpec(_ForbesSpec):
    type: Literal["qbfs"]

    def build(self, base_dir: Path | None = None) -> QBfsAsphere:
        return QBfsAsphere(self.curvature, self.a, self.norm_radius, self.aperture)


SurfaceSpec = Annotated[Union[EvenAsphereSpec, XYPolynomialSpec, MeshSpec, QConSpec, QBfsSpec],
                        Field(discriminator="type")]
_ADAPTER = TypeAdapter(SurfaceSpec)
SURFACE_TYPES = ("even_asphere", "xy_polynomial", "mesh", "qcon", "qbfs")


def parse_surface_spec(data: dict):
    """Validate a `surface:` mapping; raises pydantic.ValidationError."""
    return _ADAPTER.validate_python(data)


def surface_from_spec(data: dict, base_dir: Path | None = None) -> NominalSurface:
    return parse_surface_spec(data).build(base_dir)
