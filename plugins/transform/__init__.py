"""`transform`: apply a pose (docs/conventions.md "Frames and signs") or a 4 × 4 affine matrix to the cloud.

    pose, direction to_measuring:  p' = Rx(alpha) · Ry(beta) · p + (dx, dy, dz)
    pose, direction to_part:       p' = (Rx(alpha) · Ry(beta))ᵀ · (p − (dx, dy, dz))
    matrix:                        p' = M[:3, :3] · p + M[:3, 3]

Used to bring a measurement into a known frame (e.g. a pose from a previous fit, or a fixture's
calibration matrix). The cloud's `frame` metadata follows the direction.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, field_validator, model_validator

from pointspro.core.geometry import Pose, apply_affine
from pointspro.core.step import Context, Params, Step, StepResult, param


class PoseParams(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN, ±inf: never
    alpha_deg: float = param(0.0, unit="deg", help="rotation about x")
    beta_deg: float = param(0.0, unit="deg", help="rotation about y")
    dx: float = param(0.0, unit="mm", help="shift along x")
    dy: float = param(0.0, unit="mm", help="shift along y")
    dz: float = param(0.0, unit="mm", help="shift along z")


class TransformParams(Params):
    pose: PoseParams | None = param(None, help="part pose in the measuring frame (docs/conventions.md, Frames and signs)")
    direction: Literal["to_part", "to_measuring"] = param(
        "to_part", help="to_part removes the pose from measured points; to_measuring applies it")
    matrix: list[list[float]] | None = param(
        None, help="4 × 4 (or 3 × 4) affine matrix [[...], ...] applied as p' = M·p (mm)")

    @field_validator("matrix")
    @classmethod
    def _shape(cls, m):
        if m is None:
            return m
        a = np.asarray(m, dtype=np.float64)
        if a.shape not in ((4, 4), (3, 4)):
            raise ValueError(f"matrix must be 4 × 4 or 3 × 4, got {a.shape[0]} × "
                             f"{a.shape[1] if a.ndim == 2 else '?'}")
        if not np.all(np.isfinite(a)):
            raise ValueError("matrix holds NaN/inf")
        if a.shape == (4, 4) and not np.allclose(a[3], [0, 0, 0, 1]):
            raise ValueError("the last row of an affine matrix must be [0, 0, 0, 1]")
        # singular relative to its own scale: |det| < 1e-12 let a rank-2 matrix of 1e-5 rounding
        # pass and refused a well-conditioned one of scale 1e-4 (a review); a condition number above
        # 1e12 leaves fewer than 4 significant digits of the flattest axis
        cond = np.linalg.cond(a[:3, :3])
        if not np.isfinite(cond) or cond > 1e12:
            raise ValueError(f"matrix is singular (the 3 × 3 part's condition number is {cond:.3g}): it "
                             "would flatten the points onto a plane or a line")
        return m

    @model_validator(mode="after")
    def _one(self):
        if (self.pose is None) == (self.matrix is None):
            raise ValueError("give exactly one of pose and matrix")
        return self


class TransformStep(Step):
    id = "transform"
    title = "Transform"
    drops_residual = True  # it referred to the old frame (core/step.py)
    summary = "Apply a pose or an affine matrix."
    Params = TransformParams

    @classmethod
    def example_params(cls) -> dict:
        return {"pose": {"alpha_deg": 0.1, "beta_deg": -0.2, "dx": 1.0, "dy": 2.0, "dz": -3.0}}

    def run(self, cloud, params: TransformParams, ctx: Context) -> StepResult:
        ctx.progress.check()
        report: dict = {"warnings": []}
        meta = {}
        if params.pose is not None:
            pose = Pose(**params.pose.model_dump())
            if params.direction == "to_part":
                xyz = pose.to_part(cloud.xyz)
                meta["frame"] = "part"
            else:
                xyz = pose.to_measuring(cloud.xyz)
                meta["frame"] = "measuring"
            report.update(pose.as_dict(), direction=params.direction)
        else:
            m = np.asarray(params.matrix, dtype=np.float64)
            xyz = apply_affine(m, cloud.xyz)
            r = m[:3, :3]
            if not np.allclose(r.T @ r, np.eye(3), atol=1e-9):
                report["warnings"].append("the matrix is not rigid (scale or shear): distances change")
            if np.linalg.det(r) < 0:
                # a mirror makes a left-handed frame: the part's z up and its probe side flip relative
                # to x, y (docs/conventions.md, Frames and signs)
                report["warnings"].append("the matrix mirrors the points (determinant < 0): the frame "
                                          "becomes left-handed")
            report["matrix"] = m.tolist()
        ctx.progress.update(1.0, "transformed")
        # a residual channel refers to the old frame's nominal; it no longer holds after a move
        drop = ["residual"] if "residual" in cloud.channels else []
        if drop:
            report["warnings"].append("the residual channel was dropped: it referred to the old frame")
        return StepResult(cloud.replace(xyz=xyz, meta=meta, drop=drop), report)
