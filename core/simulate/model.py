"""A measurement model (YAML): nominal surface, scan, probe, effects — and the simulator that runs it.

    pointspro_model: 1
    surface: {type: even_asphere, R: 200, k: -1, aperture: 50}
    scan: {type: spiral, radius: 20, rpm: 30, pitch: 0.1, fs: 500}
    probe: {noise: 2.0e-6}            # mm RMS of the probe's reading
    seed: 1
    effects:
      - pose: {alpha_deg: 0.002, dz: 0.001}
      - vibration: {frequency_hz: 37, amplitude: 5.0e-6}

`pointspro simulate MODEL.yaml --out FILE` writes x, y, z, t, c (and xd, the encoder of an axis that
follows the nominal) — z = f(x, y) + Σ effects + noise.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..errors import RecipeError
from .effects import LIBRARY, ScanContext
from .scan import ScanSpec, scan_points, scan_warnings


class ProbeSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN, ±inf: never
    noise: float = Field(0.0, ge=0, description="RMS noise of the reading (mm)")
    radius: float = Field(0.0, ge=0, description="tip radius (mm); not simulated here — an uncompensated "
                          "radius is the probe_radius effect")

    @field_validator("radius")
    @classmethod
    def _radius_is_an_effect(cls, v):
        # a radius here was accepted and changed nothing (byte-identical simulations with and without)
        if v:
            raise ValueError(f"probe.radius {v:g} mm is not simulated: an uncompensated tip radius is the "
                             f"effect `- probe_radius: {{radius: {v:g}}}` under effects")
        return v


class ModelSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN, ±inf: never
    pointspro_model: int = Field(1, description="model format version")
    surface: dict = Field(description="nominal surface, as in recipes")
    scan: ScanSpec
    probe: ProbeSpec = ProbeSpec()
    # ge=0: numpy's generator refused seed: -1 in its own words ("expected non-negative integer")
    seed: int = Field(0, ge=0, description="seed of the noise (0 or more)")
    effects: list[dict[str, dict]] = Field(default_factory=list, description="[{effect: {param: value}}]")

    @model_validator(mode="before")
    @classmethod
    def _numbers_are_numbers(cls, data):
        """`seed: true`, `scan: {radius: true}` (taken as 1 by pydantic's lax mode) and `seed: "3"`,
        `fs: 4_00` (text, a word in YAML 1.2, taken as the number) are refused, as in a recipe's
        steps and surface (core.yamlio.bool_as_number, core.yamlio.number_as_text). The
        surface is checked as a recipe's (load_model), the effects by _known."""
        from ..yamlio import bool_as_number, number_as_text

        if isinstance(data, dict):
            for name, v in data.items():
                f = cls.model_fields.get(name) if isinstance(name, str) and name != "surface" else None
                if f is None:
                    continue
                error = bool_as_number(f.annotation, v, name) or number_as_text(f.annotation, v, name)
                if error is not None:
                    raise error
        return data

    @field_validator("effects")
    @classmethod
    def _known(cls, v):
        for i, e in enumerate(v):
            if len(e) != 1:
                raise ValueError(f"effect {i + 1}: one effect name per list item")
            (name, params), = e.items()
            if name not in LIBRARY:
                raise ValueError(f"effect {i + 1}: unknown effect '{name}'; the library has "
                                 f"{', '.join(LIBRARY)}")
            bad = set(params or {}) - set(LIBRARY[name].params)
            if bad:
                raise ValueError(f"effect {i + 1} '{name}': unknown parameter(s) {sorted(bad)}; it has "
                                 f"{LIBRARY[name].params_text()}")
            for key, value in (params or {}).items():  # a NaN amplitude simulated 20,000 NaN heights
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ValueError(f"effect {i + 1} '{name}': {key} = {value!r} is not a finite number")
        return v

    def build_surface(self, base_dir=None):
        from ..surfaces import surface_from_spec

        return surface_from_spec(self.surface, base_dir)

    def to_yaml(self) -> str:
        from ..yamlio import dump_yaml

        return dump_yaml(self.model_dump(mode="json"), sort_keys=False, default_flow_style=None)


def load_model(path) -> ModelSpec:
    """A measurement model file (YAML 1.2: core.yamlio); RecipeError naming the file, the line and the
    key at fault."""
    from ..yamlio import read_yaml_mapping

    path = Path(path)
    data = read_yaml_mapping(path, "measurement model", "pointspro_model", 1, RecipeError)
    try:
        model = ModelSpec.model_validate(data)
    except ValidationError as e:
        err = e.errors()[0]
        names = [str(k) for k in err["loc"]]
        msg = err["msg"].removeprefix("Value error, ")  # a validator's own words, without pydantic's tag
        ctx = err.get("ctx") or {}
        if "keys" in ctx and "detail" in ctx:  # bool_as_number, number_as_text: the keys down to the value
            names, msg = names + [str(k) for k in ctx["keys"]], ctx["detail"]
        key = ".".join(names)
        line = data.key_lines.get(names[0]) if names else None
        at = f", line {line}" if line else ""
        raise RecipeError(f"{path}{at}: key '{key}': {msg}") from None
    # the surface is checked now, as a recipe's is (a review: `R: 0` was an internal error of explain
    # and a pydantic dump from simulate)
    from ..recipe import format_validation_error, surface_model
    from ..surfaces.spec import parse_surface_spec

    try:
        parse_surface_spec(model.surface)
    except ValidationError as e:
        line = data.key_lines.get("surface")
        kind = model.surface.get("type") if isinstance(model.surface, dict) else None
        raise RecipeError(format_validation_error(e, f"{path}{f', line {line}' if line else ''}: surface: ",
                                                  surface_model(kind), tag=kind)) from None
    return model


def check_scan(model: ModelSpec, path) -> None:
    """Refuse, as `pointspro simulate` does and in its words, a model whose own scan cannot be
    simulated: a spiral of more than 5,000,000 samples, fiducials without centres (the scan's
    ValueError, named with the model file as core/cli.py cmd_simulate names it), a scan reaching
    where the nominal surface is not defined (the surface's own error). For `pointspro explain`,
    which evaluates the model at the measured points only: it took such models, and its
    model.updated.yaml would then not simulate (a review's finding)."""
    path = Path(path)
    try:
        pts = scan_points(model.scan)
    except ValueError as e:
        raise RecipeError(f"{path}: {e}") from None
    ScanContext.from_surface(model.build_surface(path.parent), pts["x"], pts["y"], pts["t"], pts["c"])


def effects_dz(ctx: ScanContext, effects: list[dict]) -> np.ndarray:
    """The effects' height changes (mm) at the scan's points. An effect whose parameters make them
    overflow (`volumetric: {cxx: 1.0e+308}` wrote a file of inf heights with exit 0 — a review) is
    refused naming it."""
    dz = np.zeros_like(ctx.x)
    for i, e in enumerate(effects, 1):
        (name, params), = e.items()
        with np.errstate(over="ignore", invalid="ignore"):
            d = LIBRARY[name].apply(ctx, params or {})
        if not np.all(np.isfinite(d)):
            from ..errors import InputError

            raise InputError(f"effect {i} '{name}': its parameters give heights beyond any number "
                             f"({', '.join(f'{k} {v!r}' for k, v in (params or {}).items())}): check their "
                             "size and unit (lengths in mm)")
        dz = dz + d
    return dz


def implausible_effects(model: ModelSpec, base_dir=None) -> list[str]:
    """Warnings for effects (the pose aside: a part may sit far off) that change the heights by more
    than a tenth of the part's own sag variation over the scan, and by over 1 µm RMS — a length
    written in the wrong unit (`amplitude: 8` for 8 nm is 8 mm; a review: simulated with exit 0 and no
    word), or `z_scale: {scale: -1}`, which flattens the part. First the scan's own warnings
    (scan_warnings: fewer points than explain needs in a measurement): `pointspro simulate` prints
    these."""
    from ..units import format_length

    pts = scan_points(model.scan)
    ctx = ScanContext.from_surface(model.build_surface(base_dir), pts["x"], pts["y"], pts["t"], pts["c"])
    sag = float(np.ptp(ctx.f)) if ctx.f.size else 0.0
    out = scan_warnings(model.scan)
    for i, e in enumerate(model.effects, 1):
        (name, params), = e.items()
        if name == "pose":
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            d = LIBRARY[name].apply(ctx, params or {})
        big = float(np.max(np.abs(d))) if d.size else 0.0  # scaled: d² of 1e300 would overflow
        rms = big * float(np.sqrt(np.mean((d / big) ** 2))) if big > 0 and np.isfinite(big) else big
        if np.isfinite(rms) and rms > max(0.1 * sag, 1e-3):
            out.append(f"effect {i} '{name}' changes the heights by {format_length(rms)} RMS, more than a tenth "
                       f"of the part's sag over the scan ({format_length(sag)} PV): check its size and unit "
                       "(lengths in mm, times in s)")
    return out


def simulate(model: ModelSpec, base_dir=None, at: dict | None = None, noise: bool = True) -> dict:
    """Columns x, y, z, t, c, xd of the simulated measurement; ``at`` (x, y, t, c) to evaluate the
    model at given scan coordinates instead of its own scan (explain does, to match a measurement)."""
    pts = scan_points(model.scan) if at is None else at
    surf = model.build_surface(base_dir)
    ctx = ScanContext.from_surface(surf, pts["x"], pts["y"], pts["t"], pts["c"])
    if at is not None:  # the effects mean at these points what they mean on the model's own scan
        own = scan_points(model.scan)
        ctx.with_norms_of(own["x"], own["y"], own["t"])
    z = ctx.f + effects_dz(ctx, model.effects)
    if noise and model.probe.noise > 0:
        z = z + np.random.default_rng(model.seed).normal(0, model.probe.noise, z.size)
    out = {"x": ctx.x, "y": ctx.y, "z": z, "t": ctx.t, "c": ctx.c, "xd": ctx.f.copy()}
    if "fiducial" in pts:
        out["fiducial"] = np.asarray(pts["fiducial"])
    return out
