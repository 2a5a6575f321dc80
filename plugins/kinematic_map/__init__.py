"""`kinematic_map`: the machine's kinematic error map from reversal measurements (paper 003 §4).

Inputs (CSV files, relative to the recipe; lengths mm, angles deg unless the header states a unit):
  straightness  x, m1, m2          forward and reversed scans of a flat along X   → EZX(x)
  facial        c, m1, m2, m3, m4  facial reversal all round the spindle angle     → EZC(c), EBC(c)
                (no gap of 12° or more: core.kinematics.errormap.facial_coverage)
  squareness    x, m1, m2          scans along X at c = 0° and c = 180°            → EB0C
(core.kinematics.reversal for the measurement models). Writes ``kinematic_map.json`` — e(X, c) by
the selective model over the probe's position X on the slide, 0 ≤ X ≤ r_max and, as far as the
straightness scan reaches there, X < 0 (a scan through the centre) — that the `kinematic` step
subtracts, and a polar figure. The cloud passes through unchanged.

EZX is known only over the x the straightness scan covers, and is never extrapolated: the map stops
there, and EB0C is fitted over |x| ≤ a, the largest range symmetric about the spindle axis that both
the squareness scans and the straightness scan cover (a warning names both ranges when that drops
squareness samples). The squareness reversal needs the flat scanned across its centre: turned by
180° the flat is read at −x, and only over ±x does its own form drop out of the slopes — a one-sided
scan (x from 0 to R) puts the flat's power into EB0C (0.08″ read as −0.245″), so squareness samples
on only one side of x = 0 (fewer than 3 on either side within that range) are refused, with the
ranges found and the one needed.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.step import Context, Params, Step, StepResult, param


class KinematicMapParams(Params):
    straightness: str = param(file=True, help="CSV x, m1, m2: EZX reversal scans (mm)")
    facial: str = param(file=True, help="CSV c, m1, m2, m3, m4: facial reversal readings (deg, mm)")
    probe_distance: float = param(gt=0, unit="mm", help="distance L of the facial probe from the axis")
    squareness: str | None = param(None, file=True, help="CSV x, m1, m2: scans along X at c = 0° and 180°, "
                                   "across the centre (x on both sides of 0); empty: EB0C = 0")
    r_max: float | None = param(None, gt=0, unit="mm", help="largest radius of the map; empty: the "
                                "straightness scan's reach on +X")
    n_r: int = param(101, ge=2, le=10000, help="radii in the table over 0…r_max (as many again at X < 0 "
                     "when the straightness scan covers negative x)")
    n_c: int = param(360, ge=8, le=36000, help="spindle angles in the table")


def map_figure(m):
    from pointspro.core.figures import _figure

    fig = _figure(6.4, 5.2)
    fig.subplots_adjust(top=0.86)
    ax = fig.add_subplot(projection="polar")
    k = m.r >= 0  # the probe on +X: the polar view (X < 0 is the same workpiece ring at c + 180°)
    C, R = np.meshgrid(np.deg2rad(np.r_[m.c_deg, 360.0]), m.r[k])
    E = np.concatenate([m.e[k], m.e[k][:, :1]], axis=1) * 1e6
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
        from pointspro.core.errors import InputError
        from pointspro.core.figures import png_artifact
        from pointspro.core.io.text import read_table
        from pointspro.core.kinematics.errormap import (
            ARCSEC,
            MAX_UPR,
            build_map,
            facial_coverage,
            periodic,
            squareness_window,
            undulations_per_rev,
        )
        from pointspro.core.kinematics.reversal import (
            facial_reversal,
            squareness_reversal,
            straightness_reversal,
        )
        ctx.progress.check()
        stp = ctx.resolve(params.straightness, "straightness")
        st = read_table(stp, ("x", "m1", "m2"))
        ezx, flat_s = straightness_reversal(st["m1"], st["m2"])
        fp = ctx.resolve(params.facial, "facial")
        fa = read_table(fp, ("c", "m1", "m2", "m3", "m4"), units={"c": "deg"}, reader=f"the {self.id} step")
        facial_coverage(fa["c"], fp, self.id)
        ezc, ebc, flat_f = facial_reversal(fa["m1"], fa["m2"], fa["m3"], fa["m4"], params.probe_distance)
        ctx.progress.update(0.4, "squareness")
        eb0c, warnings = 0.0, []
        if params.squareness is not None:
            sp = ctx.resolve(params.squareness, "squareness")
            sq = read_table(sp, ("x", "m1", "m2"))
            # EZX only where the straightness scan measured it, symmetric about the axis (the method)
            keep, _, note = squareness_window(sq["x"], st["x"], sp, stp, self.id)
            if note:
                warnings.append(note)
            ebc_at = periodic(fa["c"], ebc)
            ezx_at = np.interp(sq["x"][keep], np.sort(st["x"]), ezx[np.argsort(st["x"])])
            eb0c = squareness_reversal(sq["x"][keep], sq["m1"][keep], sq["m2"][keep], float(ebc_at(0.0)),
                                       float(ebc_at(180.0)), ezx=ezx_at)
        if params.r_max is not None:
            r_max = params.r_max
            if r_max > float(np.max(st["x"])) + 1e-9:
                # a review: the message named neither the key nor the file
                raise InputError(f"{stp}: the straightness scan covers x ≤ {np.max(st['x']):g} mm, but r_max "
                                 f"is {r_max:g} mm — the map stops where the scan does (EZX is not "
                                 "extrapolated): lower r_max, or leave it empty for the scan's reach")
        elif np.max(st["x"]) > 0:
            r_max = float(np.max(st["x"]))
        else:
            raise InputError(f"{stp}: the straightness scan covers x {np.min(st['x']):g}…"
                             f"{np.max(st['x']):g} mm, none of it at x > 0 where the map starts")
        m = build_map(st["x"], ezx, fa["c"], ezc, ebc, eb0c, r_max, params.n_r, params.n_c)
        if params.n_c < 2 * MAX_UPR:
            # a review: n_c 8 or 16 was accepted silently, and the table's linear interpolation between
            # its angles flattens the undulations the facial reversal resolved (up to MAX_UPR per turn)
            warnings.append(f"n_c = {params.n_c}: the table's {360 / params.n_c:g}° between spindle angles "
                            f"cannot hold the up to {MAX_UPR} undulations per revolution that EZC and EBC are "
                            f"analysed for (Nyquist: n_c ≥ {2 * MAX_UPR}; for linear interpolation well above "
                            "that — the default 360)")
        if m.r[0] > 0:
            warnings.append(f"the straightness scan starts at x = {m.r[0]:g} mm: the map (EZX) covers X "
                            f"{m.r[0]:g}…{r_max:g} mm only, and the kinematic step refuses points nearer the "
                            f"spindle axis (EZX is not extrapolated)")
        report = {**m.components, "r_max": r_max, "x_range_mm": [float(m.r[0]), float(m.r[-1])],
                  "ebc_harmonics": [{"upr": h["upr"], "amplitude_arcsec": h["amplitude"] / ARCSEC}
                                    for h in undulations_per_rev(fa["c"], ebc)],
                  "ezc_harmonics": [{"upr": h["upr"], "amplitude_nm": h["amplitude"] * 1e6}
                                    for h in undulations_per_rev(fa["c"], ezc)],
                  "straightness_flat_pv_nm": float(np.ptp(flat_s) * 1e6),
                  "facial_flat_pv_nm": float(np.ptp(flat_f) * 1e6),
                  "map_pv_nm": float(np.ptp(m.e) * 1e6), "warnings": warnings}
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
