"""`kinematic`: subtract the machine's kinematic error map from on-machine heights (003 §5).

Each point's probe radius r = sqrt(x² + y²) (mm, workpiece frame on the spindle axis) and spindle
angle c (channel, deg) look up e(r, c) in ``map`` (kinematic_map.json from `kinematic_map`,
bilinear, periodic in c); z − e replaces z (and residual − e the residual, when present). The
channel ``kinematic_error`` keeps e (mm). The report gives the removed error and the flatness
(PV about the least-squares plane) before and after, in nm.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context, Params, Step, StepResult, param


class KinematicParams(Params):
    map: str = param(file=True, help="kinematic_map.json (from the kinematic_map step), relative to the recipe")
    c: str = param("c", help="spindle-angle channel (deg)")


def flatness(x, y, z) -> float:
    """PV about the least-squares plane (same unit as z)."""
    A = np.column_stack([np.ones_like(x), x, y])
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    return float(np.ptp(z - A @ coef))


class KinematicStep(Step):
    id = "kinematic"
    title = "Kinematic error compensation"
    summary = "Subtract the kinematic error map e(r, c) from on-machine heights (003)."
    Params = KinematicParams

    def run(self, cloud, params: KinematicParams, ctx: Context) -> StepResult:
        from pointspro.core.kinematics.errormap import KinematicMap
        ctx.progress.check()
        if params.c not in cloud.channels:
            raise StepError(f"the scan has no spindle-angle channel '{params.c}' (deg)")
        from pointspro.core.io.text import read_parameter_text

        p = ctx.resolve(params.map, "map")
        if not p.is_file():
            raise InputError(f"{p}: kinematic map file not found")
        m = KinematicMap.from_json(read_parameter_text(p, "kinematic map"), str(p))
        from pointspro.core.units import channel_in

        c = channel_in(cloud, params.c, "deg", self.id)  # deg, from the unit the file states (c [rad])
        r = np.hypot(cloud.x, cloud.y)
        try:
            e = m(r, c)
        except InputError as err:
            raise StepError(str(err)) from None
        z = cloud.z - e
        ch = {"kinematic_error": e}
        if "residual" in cloud.channels:
            ch["residual"] = cloud["residual"] - e
        out = cloud.replace(xyz=np.column_stack([cloud.x, cloud.y, z]), channels=ch)
        report = {"removed_rms_nm": float(np.std(e) * 1e6), "removed_pv_nm": float(np.ptp(e) * 1e6),
                  "flatness_before_nm": flatness(cloud.x, cloud.y, cloud.z) * 1e6,
                  "flatness_after_nm": flatness(cloud.x, cloud.y, z) * 1e6, "map": str(p),
                  "map_components": m.components, "warnings": []}
        return StepResult(out, report)

    @classmethod
    def example_cloud(cls, cloud):
        return cloud.replace(channels={"c": np.arange(cloud.n) * 7.0 % 360.0})

    @classmethod
    def example_params(cls) -> dict:
        import tempfile
        from pathlib import Path

        from pointspro.core.kinematics.errormap import KinematicMap

        r = np.linspace(0, 1000.0, 11)
        c = np.arange(0, 360, 30.0)
        m = KinematicMap(r, c, 1e-6 * np.outer(r / 1000, np.cos(np.deg2rad(2 * c))))
        p = Path(tempfile.mkdtemp(prefix="pointspro-kin-")) / "map.json"
        p.write_text(m.to_json(), encoding="utf-8")
        return {"map": str(p)}
