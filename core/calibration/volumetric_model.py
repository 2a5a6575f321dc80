"""volumetric_model.json: the fiducial calibration written once, applied to many measurements.

Plain JSON, validated field by field on loading (pydantic) and sealed with a SHA-256 of its content,
so a file from another version or edited by hand is refused with a clear message — nothing in it is
ever executed (no pickle). Contents: the 12-parameter transform and its covariance, the workspace
bounds (mm), and per error component (ex, ey, ez) the GP: kernel kind and hyperparameters, training
positions and values; prediction rebuilds the regressor with those hyperparameters fixed.
"""
from __future__ import annotations

import hashlib
import json
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from ..errors import InputError

FORMAT = 1


class GPSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal["spectral_mixture", "rbf", "matern52"]
    params: dict[str, list[float] | float]
    noise: float
    X: list[list[float]]
    y: list[float]


class VolumetricModelSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    pointspro_volumetric_model: int
    transform: dict
    workspace: list[list[float]]          # [[xmin, xmax], [ymin, ymax], [zmin, zmax]]
    gp: dict[str, GPSpec]                 # "ex", "ey", "ez"
    loo_rms_um: dict
    sha256: str


def _digest(d: dict) -> str:
    body = {k: v for k, v in d.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def encode_gp(gp, kind: str, X, y) -> dict:
    k = gp.kernel_
    main, white = k.k1, k.k2
    if kind == "spectral_mixture":
        params = {"weights": main.weights.tolist(), "means": main.means.tolist(),
                  "variances": main.variances.tolist()}
    else:
        params = {"constant": float(main.k1.constant_value),
                  "length_scale": np.atleast_1d(main.k2.length_scale).tolist()}
    return {"kind": kind, "params": params, "noise": float(white.noise_level),
            "X": np.asarray(X).tolist(), "y": np.asarray(y).tolist()}


def decode_gp(spec: GPSpec):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

    from .gp import SpectralMixture

    p = spec.params
    if spec.kind == "spectral_mixture":
        main = SpectralMixture(p["weights"], p["means"], p["variances"])
    else:
        ls = np.asarray(p["length_scale"])
        base = RBF(ls) if spec.kind == "rbf" else Matern(ls, nu=2.5)
        main = ConstantKernel(float(p["constant"])) * base
    kernel = main + WhiteKernel(spec.noise)
    gp = GaussianProcessRegressor(kernel, normalize_y=True, optimizer=None, alpha=1e-10)
    gp.fit(np.asarray(spec.X), np.asarray(spec.y))
    return gp


def dumps(d: dict) -> str:
    d = {"pointspro_volumetric_model": FORMAT, **d}
    d["sha256"] = _digest(d)
    return json.dumps(d, indent=1) + "\n"


def loads(text: str, source: str) -> VolumetricModelSpec:
    try:
        d = json.loads(text)
    except ValueError as e:
        from ..io.text import json_problem  # quotes nothing of the file

        raise InputError(f"{source}: {json_problem(e)}") from None
    if not isinstance(d, dict) or d.get("pointspro_volumetric_model") != FORMAT:
        raise InputError(f"{source}: not a PointsPro volumetric model of format {FORMAT}")
    try:
        spec = VolumetricModelSpec.model_validate(d)
    except ValidationError as e:
        err = e.errors()[0]  # the top key only: keys further down are the file's content
        key = err["loc"][0] if err["loc"] and err["loc"][0] in VolumetricModelSpec.model_fields else None
        what = "an unknown key" if err["type"] == "extra_forbidden" or key is None else f"key '{key}'"
        raise InputError(f"{source}: {what}: {err['msg']}") from None
    if _digest(d) != spec.sha256:
        raise InputError(f"{source}: the file was changed after it was written (checksum mismatch); "
                         "run the fiducial calibration again")
    return spec


ERROR_COMPONENTS = ("ex", "ey", "ez")


def fit_error_gps(X, errors, Q: int = 10, check=None) -> tuple[dict, dict, dict]:
    """A GP of each volumetric-error component (ex, ey, ez) at the positions X (machine frame, mm),
    the kernel chosen by leave-one-out (core.calibration.gp.fit_gp). Returns (regressors, their
    specs for the model file, {component: LOO RMS µm per kernel and the chosen one}). ``check`` (e.g.
    a Progress's) is called before each component, so a cancel stops between fits."""
    from .gp import fit_gp

    errors = np.asarray(errors, dtype=np.float64)
    gps, specs, loo = {}, {}, {}
    for k, name in enumerate(ERROR_COMPONENTS):
        if check is not None:
            check()
        gp, info = fit_gp(X, errors[:, k], Q=Q)
        gps[name] = gp
        specs[name] = encode_gp(gp, info["chosen"], X, errors[:, k])
        loo[name] = {kk: v * 1e3 for kk, v in info["loo_rms"].items()} | {"chosen": info["chosen"]}
    return gps, specs, loo


def model_text(fit, X, gp_specs: dict, loo_rms_um: dict) -> str:
    """volumetric_model.json's text: the transform (an AffineFit), the workspace (bounding box of
    the machine-frame positions X) and the GP specs."""
    X = np.asarray(X, dtype=np.float64)
    workspace = np.column_stack([X.min(axis=0), X.max(axis=0)]).tolist()
    return dumps({"transform": fit.to_dict(), "workspace": workspace, "gp": gp_specs,
                  "loo_rms_um": loo_rms_um})
