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
from pydantic_core import PydanticCustomError, ValidationError

from ..yamlio import bool_as_number, number_as_text, yaml_word
from .base import NominalSurface
from .even_asphere import EvenAsphere
from .forbes import QBfsAsphere, QConAsphere
from .mesh import MeshSurface
from .xy_polynomial import XYPolynomial

_TERM = re.compile(r"x([0-9]+)y([0-9]+)")  # fullmatch: "x2y0\n" and "x２y0" are not terms
_INT = TypeAdapter(int)


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN, ±inf: never
    aperture: float | None = Field(None, gt=0, description="clear-aperture diameter (mm)")

    @model_validator(mode="before")
    @classmethod
    def _true_is_not_a_number(cls, data):
        """`c: true`, `aperture: true`, `A: {4: true}`, `a: [1e-4, false]` are refused: pydantic's lax
        mode would take true as 1 and false as 0 (core.yamlio.bool_as_number); and, as a step's
        parameters do (core.step.Params), `repair: yes`, a word in YAML 1.2 that pydantic would take
        as true, and `aperture: 1_300` or `c: "3.33e-4"`, text it would take as the number
        (number_as_text; a review: both ran). A model validator: a field's before-validator may not
        touch the union's discriminator `type`."""
        if isinstance(data, dict):
            for name, v in data.items():
                f = cls.model_fields.get(name) if isinstance(name, str) else None
                if f is not None and f.annotation in (bool, bool | None) and isinstance(v, str):
                    why = (f"Input should be true or false (yes, no, on and off are words in YAML "
                           f"1.2) (got {v!r})")
                    raise PydanticCustomError("bool_word", "key {name}: {detail}",
                                              {"name": repr(name), "keys": [name], "detail": why})
                if (f is not None and f.annotation in (bool, bool | None) and isinstance(v, (int, float))
                        and not isinstance(v, bool)):  # lax mode takes 1 and 0.0 as yes and no
                    raise PydanticCustomError("bool_number", "key {name}: {detail}",
                                              {"name": repr(name), "keys": [name],
                                               "detail": f"Input should be true or false (got {v})"})
                if f is not None and isinstance(v, (bool, list, tuple, dict)):
                    error = bool_as_number(f.annotation, v, name)
                    if error is not None:
                        raise error
                if f is not None:  # `aperture: 1_300`, `c: "3.33e-4"`: text, refused as a step's is
                    error = number_as_text(f.annotation, v, name)
                    if error is not None:
                        raise error
        return data


def _one_key_each(keys, normal, what: str, lines: dict | None = None, shown=str) -> None:
    """Refuse two keys of a coefficient mapping that mean the same coefficient once normalised (YAML
    sees "4" and 4, or x2y0 and x02y0, as different keys; the model would keep the last silently).
    ``normal``: a key → its normal form, None when it has none (the model's own check says why);
    ``lines``: the keys' lines (a LineDict's key_lines); ``shown``: the normal form as written."""
    seen: dict = {}
    for key in keys:
        n = normal(key)
        if n is None:
            continue
        if n in seen:
            first = seen[n]
            where = ""
            if lines and lines.get(first) and lines.get(key) and lines[first] != lines[key]:
                where = f" on lines {lines[first]} and {lines[key]}"
            raise PydanticCustomError(
                "duplicate_coefficient", "duplicate {what} {n} (written as {a} and {b}{where})",
                {"what": what, "n": shown(n), "a": yaml_word(first), "b": yaml_word(key), "where": where})
        seen[n] = key


def _power(key) -> int | None:
    """The power n of an A_n key as the model reads it (4, "4", 4.0 → 4); None: not a power."""
    if isinstance(key, bool):
        return None
    try:
        return _INT.validate_python(key)
    except ValidationError:
        return None


def _term(key) -> tuple[int, int] | None:
    m = _TERM.fullmatch(key) if isinstance(key, str) else None
    return (int(m[1]), int(m[2])) if m else None


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

    @field_validator("A", mode="before")
    @classmethod
    def _one_key_per_power(cls, v):
        """{"4": 7e-13, 4: 1e-19}: YAML's duplicate-key check sees two keys, the model one power."""
        if isinstance(v, dict):
            _one_key_each(v, _power, "coefficient", getattr(v, "key_lines", None))
        return v

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

    @field_validator("terms", mode="before")
    @classmethod
    def _one_key_per_term(cls, v):
        """{x2y0: 1e-3, x02y0: 2e-3}: two keys to YAML, one term C_20 to the polynomial."""
        if isinstance(v, dict):
            _one_key_each(v, _term, "term", getattr(v, "key_lines", None), lambda t: f"x{t[0]}y{t[1]}")
        return v

    @field_validator("terms")
    @classmethod
    def _names(cls, v):
        for name in v:
            if _term(name) is None:
                raise ValueError(f"term {name!r} is not of the form x<i>y<j>, e.g. x2y0")
        return v

    def build(self, base_dir: Path | None = None) -> XYPolynomial:
        terms = {_term(k): v for k, v in self.terms.items()}
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
