"""volumetric_model.json: the fiducial calibration written once, applied to many measurements.

Plain JSON, validated field by field on loading (pydantic) and sealed with a SHA-256 of its content,
so a file from another version or edited by hand is refused with a clear message — nothing in it is
ever executed (no pickle). Contents: the 12-parameter transform and its covariance, the workspace
bounds (mm), and per error component (ex, ey, ez) the GP: kernel kind and hyperparameters, training
positions and values; prediction rebuilds the regressor with those hyperparameters fixed. Beside
them, how the kernel was chosen (``gp_selection``: the cross-validated RMS of every candidate) and
the in-sample closed-form LOO (``loo_rms_um``, biased low: for comparison only).
"""
from __future__ import annotations

import hashlib
import json
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..errors import InputError

FORMAT = 1


class GPSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)  # NaN, ±inf: a damaged model file
    kind: Literal["spectral_mixture", "rbf", "matern52", "none"]   # none: no GP (zero, σ = sqrt(noise))
    params: dict[str, list[float] | float]
    noise: float
    X: list[list[float]]
    y: list[float]


class UCalibrationSpec(BaseModel):
    """u_k² = s_k² + τ²·d per component k (core.calibration.gp.blocked_cv and distance_term): s_k the GP's
    predictive σ, d the distance (mm, machine frame) from the point to the nearest ball of the GP's X,
    τ² = ``excess_variance_um2_per_mm``."""
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    method: str
    excess_variance_um2_per_mm: Annotated[float, Field(ge=0)]
    blocks: int
    held_out: int
    #: the farthest a held-out ball lay from the training balls (mm): beyond it τ² is extrapolated
    max_distance_mm: Annotated[float, Field(ge=0)] | None = None


class VolumetricModelSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)  # NaN, ±inf: a damaged model file
    pointspro_volumetric_model: int
    transform: dict
    workspace: list[list[float]]          # [[xmin, xmax], [ymin, ymax], [zmin, zmax]]
    gp: dict[str, GPSpec]                 # "ex", "ey", "ez"
    loo_rms_um: dict                      # closed-form LOO at the all-points hyperparameters (biased low)
    gp_selection: dict = {}               # how the kernel was chosen: criterion, chosen, cross-validated RMS
    # the distance term of u from the blocked cross-validation (UCalibrationSpec); absent in a file written
    # before it (issue 16 part 1): u is then the GP's σ alone, as it was
    u_calibration: UCalibrationSpec | None = None
    sha256: str


def _digest(d: dict) -> str:
    body = {k: v for k, v in d.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def encode_gp(gp, kind: str, X, y) -> dict:
    if kind == "none":  # no GP: a zero correction; noise = the variance of the error left (mm²) — 0
        # where it is unknown (4 balls), which gp_selection's "sigma_basis" says (volumetric reads it)
        noise = float(gp.sigma) ** 2 if np.isfinite(gp.sigma) else 0.0
        return {"kind": kind, "params": {}, "noise": noise, "X": np.asarray(X).tolist(),
                "y": np.asarray(y).tolist()}
    k = gp.kernel_
    main, white = k.k1, k.k2
    if kind == "spectral_mixture":
        params = {name: np.asarray(getattr(main, name), dtype=np.float64).ravel().tolist()
                  for name in ("weights", "means", "variances")}
    else:
        params = {"constant": float(main.k1.constant_value),
                  "length_scale": np.atleast_1d(main.k2.length_scale).tolist()}
    return {"kind": kind, "params": params, "noise": float(white.noise_level),
            "X": np.asarray(X).tolist(), "y": np.asarray(y).tolist()}


def decode_gp(spec: GPSpec):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

    from .gp import SpectralMixture, ZeroGP

    if spec.kind == "none":
        return ZeroGP(float(np.sqrt(spec.noise)))
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


def fit_error_gps(X, errors, Q: int = 10, check=None, noise_var=None, ref=None,
                  noise_max=None) -> tuple[dict, dict, dict, dict]:
    """A GP of each volumetric-error component (ex, ey, ez) at the positions X (machine frame, mm),
    their kernel chosen by K-fold cross-validation with the hyperparameters re-fitted in each fold
    (core.calibration.gp.select_gps) among the candidate kernels and "none" (no GP: the affine
    transform alone, kind "none" in the model file). ``ref``: the calibrated centres (mm) the transform
    was fitted to (errors = transform(ref) − X); given, the transform is re-fitted in each fold too,
    so the held-out errors are out of sample. ``noise_var``: the known variance (mm²) of each component's
    error at a fiducial (measured and calibrated centres' σ²), a floor for the GP's noise;
    ``noise_max`` its ceiling. Returns
    (regressors, their specs for the model file, {component: closed-form LOO RMS µm per kernel and
    the chosen one — in-sample, for comparison}, the selection: {"criterion", "chosen",
    "cv_rms_um": {kernel: {component: RMS}}, "gp_cv_rms_um": the chosen kernel's {component: RMS,
    "norm": RMS of |e|}, "no_gp_rms_um": the same without a GP (held out, the transform re-fitted
    without the held-out fiducials when ``ref`` is given), "no_gp_in_sample_rms_um": the errors' own RMS
    at the fiducials the transform was fitted to (smaller: not a fair comparison), "sigma_basis",
    "held_out", "never_held_out" (indices into X), "notes": how the folds were made, or why there was
    no cross-validation (gp.affine_folds, gp._without_cv)}). ``check`` (e.g. a Progress's) is
    called between candidate kernels, so a cancel stops between fits."""
    from .gp import select_gps

    errors = np.asarray(errors, dtype=np.float64)
    affine = None
    if ref is not None:
        X = np.asarray(X, dtype=np.float64)
        design = np.column_stack([np.asarray(ref, dtype=np.float64), np.ones(len(X))])
        # e_k = design · θ_k − X_k with θ_k the least-squares fit of X_k (the transform's components)
        affine = [(design, X[:, k]) for k in range(3)]
    gp_list, info = select_gps(X, errors, Q=Q, noise_var=noise_var, check=check, affine=affine,
                               noise_max=noise_max)
    chosen, kind = info["chosen"], info["kind"]
    gps, specs, loo = {}, {}, {}
    for k, name in enumerate(ERROR_COMPONENTS):
        gps[name] = gp_list[k]
        specs[name] = encode_gp(gp_list[k], kind, X, errors[:, k])
        loo[name] = {kk: v[k] * 1e3 for kk, v in info["loo_rms"].items()} | {"chosen": chosen}

    def um(v):  # None where unknown: the model file is JSON without NaN
        return float(v) * 1e3 if np.isfinite(v) else None

    def per_component(v):
        d = {n: um(v[k]) for k, n in enumerate(ERROR_COMPONENTS)}
        return d | {"norm": um(np.sqrt(np.sum(np.square(v))))}

    never = info.get("never_held_out", [])
    selection = {"criterion": info["criterion"], "chosen": chosen, "kind": kind,
                 # how the error left (σ of "none", gp_cv_rms_um) was found: "cross-validation",
                 # "in-sample residuals" (too few balls to hold out) or "unknown" (4 balls)
                 "sigma_basis": info.get("sigma_basis", "cross-validation"),
                 "held_out": info.get("held_out"), "never_held_out": never if len(never) < len(X) else "all",
                 "notes": info.get("notes", []),
                 "gp_cv_rms_um": per_component(info["cv_rms"][chosen]),
                 "no_gp_rms_um": per_component(info["cv_rms"]["none"]),
                 "no_gp_in_sample_rms_um": per_component(info["zero_rms"]),
                 "cv_rms_um": {kk: per_component(v) for kk, v in info["cv_rms"].items()}}
    if "spectral_mixture_block_test" in info:  # (gp.select_gps: K-fold's mixture against spatial blocks)
        selection["spectral_mixture_block_test"] = info["spectral_mixture_block_test"]
    if "blocked_cv" in info:
        selection["blocked_cv"] = blocked_summary(info["blocked_cv"])
    return gps, specs, loo, selection


BLOCKED_METHOD = ("blocked cross-validation: spatial blocks of ~4 neighbouring balls (k-means) held out whole, "
                  "the transform and the hyperparameters re-fitted without them; u_k² = s_k² + τ²·d, "
                  "τ² = Σ_k max(0, Σ_i(r² − s²)) / (3 Σd) over the held-out balls i and the 3 components k (d: to the "
                  "nearest training ball, mm)")


def blocked_summary(b: dict) -> dict:
    """The fiducials report's and the model file's account of the blocked cross-validation
    (``select_gps``' info["blocked_cv"]: per component r, s (mm), d (mm), τ² (mm²/mm)): per component the
    held-out RMS, the RMS of the σ the GP predicted there, their ratio (1: the GP's σ is right away from
    the balls), τ² (µm²/mm), and the share of the held-out errors within 2s and within 2u (u² = s² +
    τ²d; in sample for τ², a check of the fit, not a coverage figure)."""
    d = np.asarray(b["d"], dtype=np.float64)
    ok = np.isfinite(d)
    r = np.column_stack(b["r"])[ok]
    s = np.column_stack(b["s"])[ok]
    tau2 = float(b["tau2"])
    u = np.sqrt(s**2 + tau2 * d[ok, None])
    comp = dict(zip(ERROR_COMPONENTS, range(3)))
    return {"method": BLOCKED_METHOD, "blocks": len(b["blocks"]), "held_out": int(ok.sum()),
            "distance_mm": {"median": float(np.median(d[ok])), "max": float(np.max(d[ok]))},
            "held_out_rms_um": {n: float(np.sqrt(np.mean(r[:, k] ** 2)) * 1e3) for n, k in comp.items()},
            "predicted_rms_um": {n: float(np.sqrt(np.mean(s[:, k] ** 2)) * 1e3) for n, k in comp.items()},
            "ratio": {n: float(np.sqrt(np.mean(r[:, k] ** 2) / np.mean(s[:, k] ** 2))) for n, k in comp.items()},
            "within_2s": float(np.mean(np.abs(r) <= 2 * s)), "within_2u": float(np.mean(np.abs(r) <= 2 * u)),
            "excess_variance_um2_per_mm": tau2 * 1e6,
            # what the term adds at 10 mm from a ball (µm, in quadrature)
            "u_added_at_10mm_um": float(np.sqrt(tau2 * 10.0)) * 1e3}


def model_text(fit, X, gp_specs: dict, loo_rms_um: dict, gp_selection: dict | None = None) -> str:
    """volumetric_model.json's text: the transform (an AffineFit), the workspace (bounding box of
    the machine-frame positions X), the GP specs and how their kernel was chosen."""
    X = np.asarray(X, dtype=np.float64)
    workspace = np.column_stack([X.min(axis=0), X.max(axis=0)]).tolist()
    d = {"transform": fit.to_dict(), "workspace": workspace, "gp": gp_specs,
         "loo_rms_um": loo_rms_um, "gp_selection": gp_selection or {}}
    b = (gp_selection or {}).get("blocked_cv")
    if b:  # the distance term `volumetric` adds to u (UCalibrationSpec)
        d["u_calibration"] = {"method": b["method"], "excess_variance_um2_per_mm": b["excess_variance_um2_per_mm"],
                              "blocks": b["blocks"], "held_out": b["held_out"],
                              "max_distance_mm": b["distance_mm"]["max"]}
    return dumps(d)


def distance_u(spec: VolumetricModelSpec, P, u):
    """(u with the blocked cross-validation's distance term, d (mm) from each point to the nearest ball):
    u_k² + τ²·d per component (UCalibrationSpec); u unchanged (and d None) for a model file without
    ``u_calibration`` — one written before it, the old behaviour."""
    cal = spec.u_calibration
    if cal is None:
        return u, None
    from scipy.spatial import cKDTree

    balls = np.asarray(spec.gp["ex"].X, dtype=np.float64)
    d = cKDTree(balls).query(np.asarray(P, dtype=np.float64))[0]
    tau2 = cal.excess_variance_um2_per_mm * 1e-6  # mm²/mm
    return np.sqrt(u**2 + tau2 * d[:, None]), d
