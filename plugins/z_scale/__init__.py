"""`z_scale`: correct the z axis's amplification error (seed paper 000 §2.6, §3.2).

Either from ``calibration`` — a CSV of step-artefact scans (columns x, z in mm, optional `scan` for
repeats) with the certified ``heights`` (µm, one per edge in the order the edges occur along x; an
ISO 5436-1 type A1 groove is its depth twice) — evaluated by core.calibration.zscale (each scan
levelled by a robust line, ISO 5436-1 line fits at each edge, amplification = slope of measured vs
certified: a line with its linearity for two or more distinct heights, through the origin for a single
one; its standard uncertainty from the fit's residuals), or from a known ``amplification``. Heights are
corrected about the cloud's mean: z' = z̄ + (z − z̄)/m (and the residual likewise, when present).
"""
from __future__ import annotations

import numpy as np
from pydantic import model_validator

from pointspro.core.errors import StepError
from pointspro.core.step import Context, Params, Step, StepResult, param


class ZScaleParams(Params):
    calibration: str | None = param(None, file=True, help="step-artefact scans (CSV x, z [, scan]), relative to "
                                    "the recipe; give this or amplification")
    heights: list[float] = param(default_factory=list, unit="µm",
                                 help="certified step heights, one per edge in their order along x (a "
                                 "groove: its depth twice)")
    amplification: float | None = param(None, gt=0.5, lt=2.0, help="known amplification coefficient "
                                        "(measured / true height); give this or calibration")

    @model_validator(mode="after")
    def _one_source(self):
        if (self.calibration is None) == (self.amplification is None):
            raise ValueError("give exactly one of calibration and amplification")
        if self.amplification is not None and self.heights:
            # they would be ignored silently (a review): the heights belong to a calibration file
            raise ValueError("heights go with a calibration file; a given amplification takes none — "
                             "leave heights out")
        if self.calibration is not None and len(self.heights) < 2:
            raise ValueError("a calibration needs at least two calibrated heights (one per edge; a single "
                             "groove: its depth twice)")
        if any(not (h > 0 and np.isfinite(h)) for h in self.heights):
            # a step's height is its magnitude: −3 for a step down gave amplification −1, refused
            # later with a message about the order
            raise ValueError("the calibrated heights are step heights, positive µm (a step down too)")
        return self


class ZScaleStep(Step):
    id = "z_scale"
    title = "z-scale correction"
    summary = "Amplification of the z axis from a step artefact (or given), removed from the heights."
    Params = ZScaleParams

    def run(self, cloud, params: ZScaleParams, ctx: Context) -> StepResult:
        ctx.progress.check()
        report = {"warnings": []}
        arts = {}
        if params.calibration is not None:
            from pointspro.core.calibration.zscale import calibrate
            from pointspro.core.io.text import read_table

            p = ctx.resolve(params.calibration, "calibration")
            cols = read_table(p, ("x", "z"))
            scan = cols.get("scan", np.zeros(cols["x"].size))
            cal = calibrate(cols["x"], cols["z"], scan, np.asarray(params.heights) * 1e-3)
            m = cal.amplification
            if not 0.5 < m < 2.0:  # the bounds a given amplification has (a review: 975, −0.85, exit 0)
                raise StepError(f"the calibration gives amplification {m:.4g}, outside 0.5…2: check that "
                                "the heights are in µm, positive, and in their order along x")
            report.update(cal.describe())
            if cal.dof < 1:
                report["warnings"].append("the amplification's uncertainty is not known: the fit has no "
                                          "residual degrees of freedom (repeat the scans)")
            import json

            arts["z_scale.json"] = json.dumps({"pointspro_z_scale": 1, **cal.describe()}, indent=2) + "\n"
        else:
            m = params.amplification
            report["amplification"] = m
        from pointspro.core.metrics.pupil import is_flat

        if "residual" in cloud.channels and not is_flat(ctx.surface):
            # in the part frame a curved part's heights are its sag: scaling them about their mean
            # changes z − sag by µm while the residual scales its own deviations (a review: z − sag −
            # residual 7 µm PV after it) — the machine's heights are scaled before the pose fit
            raise StepError("z_scale corrects the measuring machine's heights: put it before misalignment "
                            "(or register)")
        z = cloud.z
        zbar = float(z.mean()) if cloud.n else 0.0
        znew = zbar + (z - zbar) / m
        ch = {}
        if "residual" in cloud.channels:
            r = cloud["residual"]
            ch["residual"] = r.mean() + (r - r.mean()) / m
        out = cloud.replace(xyz=np.column_stack([cloud.x, cloud.y, znew]), channels=ch or None)
        report["z_change_pv_um"] = float(np.ptp(znew - z) * 1e3) if cloud.n else 0.0
        return StepResult(out, report, arts)

    @classmethod
    def example_params(cls) -> dict:
        return {"amplification": 0.9754}
