"""`kinematic_map`: the machine's kinematic error map from reversal measurements (paper 003 §4).

Inputs (CSV files, relative to the recipe; lengths mm, angles deg unless the header states a unit):
  straightness  x, m1, m2          forward and reversed scans of a flat along X   → EZX(x)
  facial        c, m1, m2, m3, m4  facial reversal all round the spindle angle     → EZC(c), EBC(c)
                (no gap of 12° or more: core.kinematics.errormap.facial_coverage)
  squareness    x, m1, m2          scans along X at c = 0° and c = 180°            → EB0C
(core.kinematics.reversal for the measurement models). Writes ``kinematic_map.json`` — e(r, c) over
0 ≤ r ≤ r_max by the selective model — that the `kinematic` step subtracts, and a polar figure.
The cloud passes through unchanged.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.step import Context, Params, Step, StepResult, param


class KinematicMapParams(Params):
    straightness: str = param(file=True, help="CSV x, m1, m2: EZX reversal scans (mm)")
    facial: str = param(file=True, help="CSV c, m1, m2, m3, m4: facial reversal readings (deg, mm)")
    probe_distance: float = param(gt=0, unit="mm", help="distance L of the facial probe from the axis")
    squareness: str | None = param(None, file=True, help="CSV x, m1, m2: scans along X at c = 0° and 180°; empty: "
                                   "EB0C = 0")
    r_max: float | None = param(None, gt=0, unit="mm", help="largest radius of the map; empty: the "
                                "straightness scan's reach")
    n_r: int = param(101, ge=2, le=10000, help="radii in the table")
    n_c: int = param(360, ge=8, le=36000, help="spindle angles in the table")


def map_figure(m):
    from pointspro.core.figures import _figure

    fig = _figure(6.4, 5.2)
    fig.subplots_adjust(top=0.86)
    ax = fig.add_subplot(projection="polar")
    C, R = np.meshgrid(np.deg2rad(np.r_[m.c_deg, 360.0]), m.r)
    E = np.concatenate([m.e, m.e[:, :1]], axis=1) * 1e6
    lim = float(np.max(np.abs(E))) or 1.0
    pc = ax.pcolormesh(C, R, E, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    fig.colorbar(pc, ax=ax, label="kinematic error e (nm)", shrink=0.8)
    ax.set_title("kinematic error map e over spindle angle c and radius r (mm)", fontsize=10, pad=18)
    return fig


class KinematicMapStep(Step):
    id = "kinematic_map"
    title = "Kinematic error map (reversal)"
    summary = "EZX, EZC, EBC, EB0C by reversal → kinematic_map.json (003)."
    Params = KinematicMapParams

    def run(self, cloud, params: KinematicMapParams, ctx: Context) -> StepResult:
        from pointspro.core.figures import png_artifact
        from pointspro.core.io.text import read_table
        from pointspro.core.kinematics.errormap import (
            ARCSEC,
            build_map,
            facial_coverage,
            periodic,
            undulations_per_rev,
        )
        from pointspro.core.kinematics.reversal import (
            facial_reversal,
            squareness_reversal,
            straightness_reversal,
        )
        ctx.progress.check()
        st = read_table(ctx.resolve(params.straightness, "straightness"), ("x", "m1", "m2"))
        ezx, flat_s = straightness_reversal(st["m1"], st["m2"])
        fp = ctx.resolve(params.facial, "facial")
        fa = read_table(fp, ("c", "m1", "m2", "m3", "m4"), units={"c": "deg"}, reader=f"the {self.id} step")
        facial_coverage(fa["c"], fp, self.id)
        ezc, ebc, flat_f = facial_reversal(fa["m1"], fa["m2"], fa["m3"], fa["m4"], params.probe_distance)
        ctx.progress.update(0.4, "squareness")
        eb0c = 0.0
        if params.squareness is not None:
            sq = read_table(ctx.resolve(params.squareness, "squareness"), ("x", "m1", "m2"))
            ebc_at = periodic(fa["c"], ebc)
            ezx_at = np.interp(sq["x"], np.sort(st["x"]), ezx[np.argsort(st["x"])])
            eb0c = squareness_reversal(sq["x"], sq["m1"], sq["m2"], float(ebc_at(0.0)),
                                       float(ebc_at(180.0)), ezx=ezx_at)
        r_max = params.r_max if params.r_max is not None else float(np.max(np.abs(st["x"])))
        m = build_map(st["x"], ezx, fa["c"], ezc, ebc, eb0c, r_max, params.n_r, params.n_c)
        report = {**m.components, "r_max": r_max,
                  "ebc_harmonics": [{"upr": h["upr"], "amplitude_arcsec": h["amplitude"] / ARCSEC}
                                    for h in undulations_per_rev(fa["c"], ebc)],
                  "ezc_harmonics": [{"upr": h["upr"], "amplitude_nm": h["amplitude"] * 1e6}
                                    for h in undulations_per_rev(fa["c"], ezc)],
                  "straightness_flat_pv_nm": float(np.ptp(flat_s) * 1e6),
                  "facial_flat_pv_nm": float(np.ptp(flat_f) * 1e6),
                  "map_pv_nm": float(np.ptp(m.e) * 1e6), "warnings": []}
        arts = {"kinematic_map.json": m.to_json(), "kinematic_map.png": png_artifact(map_figure, m)}
        return StepResult(cloud.replace(), report, arts)

    @classmethod
    def example_params(cls) -> dict:
        import tempfile
        from pathlib import Path

        d = Path(tempfile.mkdtemp(prefix="pointspro-kinmap-"))
        x = np.linspace(-19, 19, 77)
        np.savetxt(d / "s.csv", np.column_stack([x, 1e-6 * x, -1e-6 * x]), delimiter=",",
                   header="x,m1,m2", comments="")
        c = np.arange(0, 360, 2.0)
        w = 1e-6 * np.cos(np.deg2rad(2 * c))
        np.savetxt(d / "f.csv", np.column_stack([c, w, w, w, -w]), delimiter=",",
                   header="c,m1,m2,m3,m4", comments="")
        return {"straightness": str(d / "s.csv"), "facial": str(d / "f.csv"), "probe_distance": 10.0}
