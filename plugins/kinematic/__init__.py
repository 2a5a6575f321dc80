"""`kinematic`: subtract the machine's kinematic error map from on-machine heights (003 §5).

Each point's probe position X on the X slide (mm, signed, the spindle axis at 0) and spindle angle c
(channel, deg) look up e(X, c) in ``map`` (kinematic_map.json from `kinematic_map`, bilinear,
periodic in c); z − e replaces z (and residual − e the residual, when present). The channel
``kinematic_error`` keeps e (mm). The report gives the removed error (its RMS over the area:
docs/conventions.md, Summary figures), the range of X, and the flatness (PV about the least-squares
plane) before and after, in nm, and warns when the compensation made the flatness worse.

X from the point's x, y (workpiece frame, mm, on the spindle axis) and c (``probe_x: auto``): in 003's
frame (core.kinematics.htm) the point probed is X·(cos c, −sin c), so X = x·cos c − y·sin c — negative
where the scan crosses the centre, and e(−X, c) ≠ e(X, c). A scan written with the other sense of c
(the point at X·(cos c, sin c), as `pointspro simulate` writes it) is read likewise. When the points lie
on neither line (farther than 1 % of the scan's radius from it: x, y not in the spindle's frame), the
probe's side cannot be told: X = √(x² + y²) (the probe on +X) with a warning. ``probe_x: radius`` takes
X = √(x² + y²) for every point without a word. Points at X < 0 need a map that holds X < 0 (built from a
straightness scan across the centre); one of X ≥ 0 only is refused rather than read at |X|.
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context, Params, Step, StepResult, param


class KinematicParams(Params):
    map: str = param(file=True, help="kinematic_map.json (from the kinematic_map step), relative to the recipe")
    c: str = param("c", help="spindle-angle channel (deg)")
    probe_x: Literal["auto", "radius"] = param(
        "auto", help="the probe's position X on the slide: auto — signed, from x, y and c (the point probed is "
        "X·(cos c, ∓sin c); X < 0 where the scan crosses the centre), or √(x² + y²) with a warning when the "
        "points lie on no such line; radius — √(x² + y²) throughout (the probe on +X)")


#: how far (a fraction of the scan's largest radius) a point may lie off the probe's line through the axis
LINE_TOL = 0.01


def probe_position(x, y, c_deg):
    """(X, sense, offset): the probe's signed position on the X slide for points x, y (mm, workpiece frame)
    probed at spindle angle c (deg) — X = x·cos c − y·sin c when every point lies within LINE_TOL of the
    scan's radius of X·(cos c, −sin c) (003's frame, sense −1), or X = x·cos c + y·sin c for X·(cos c, sin c)
    (sense +1); else (hypot(x, y), 0, the largest distance off the line of sense −1)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    a = np.deg2rad(np.asarray(c_deg, dtype=np.float64))
    ca, sa = np.cos(a), np.sin(a)
    r = np.hypot(x, y)
    tol = LINE_TOL * float(r.max()) if r.size else 0.0
    off = {}
    for sense in (-1, 1):
        d = np.abs(-sense * x * sa + y * ca)
        off[sense] = float(d.max()) if d.size else 0.0
        if off[sense] <= tol:
            return x * ca + sense * y * sa, sense, off[sense]
    return r, 0, off[-1]


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
        warnings = []
        if params.probe_x == "radius":
            r = np.hypot(cloud.x, cloud.y)
        else:
            r, sense, off = probe_position(cloud.x, cloud.y, c)
            if sense == 0:
                warnings.append(
                    f"the scan's points do not lie on the probe's line through the spindle axis at the angle c "
                    f"(X·(cos c, −sin c), or X·(cos c, sin c); up to {off:.4g} mm off it): x, y are not in the "
                    f"spindle's frame, so the probe's side cannot be told and it is taken on +X, X = √(x² + y²) — "
                    f"wrong where the scan crosses the centre; set probe_x: radius if the probe stays on +X")
        lo, hi = float(m.r[0]), float(m.r[-1])
        tol = 1e-9 * max(abs(lo), abs(hi), 1.0)
        below = (r < 0) & (r < lo - tol)
        if below.any():
            raise StepError(
                f"{int(below.sum())} of {r.size} points have the probe at X < 0 (down to {r.min():.4g} mm: the scan "
                f"crosses the spindle axis), where e(X, c) ≠ e(|X|, c); the kinematic map covers X {lo:g}…{hi:g} "
                f"mm — build it (kinematic_map) from a straightness scan that reaches x = {r.min():.4g} mm, or set "
                f"probe_x: radius if the probe in fact stays on +X")
        try:
            e = m(r, c)
        except InputError as err:
            raise StepError(str(err)) from None
        z = cloud.z - e
        ch = {"kinematic_error": e}
        if "residual" in cloud.channels:
            ch["residual"] = cloud["residual"] - e
        out = cloud.replace(xyz=np.column_stack([cloud.x, cloud.y, z]), channels=ch)
        before, after = flatness(cloud.x, cloud.y, cloud.z) * 1e6, flatness(cloud.x, cloud.y, z) * 1e6
        if after > 1.01 * before + 1e-3:  # + 1 pm: rounding on a flat scan read "0 nm before, 8.47e-15 after"
            warnings.append(
                f"the compensation made the flatness worse: {before:.4g} nm before, {after:.4g} nm after — the "
                f"map may not fit this scan (another machine or set-up, the spindle angle's zero or sense, the "
                f"probe's side: probe_x), or the machine's error happened to offset the surface's own form")
        from pointspro.core.metrics.area_weights import weighted_rms
        from pointspro.core.pipeline import area_weights_of

        # the removed error's RMS over the area (docs/conventions.md, Summary figures): an on-machine
        # spiral or star crowds its centre; an even sampling (and stylus profiles): np.std as before
        w = area_weights_of(cloud)
        removed_rms = np.std(e) if w is None else weighted_rms(e, w)
        report = {"removed_rms_nm": float(removed_rms * 1e6), "removed_pv_nm": float(np.ptp(e) * 1e6),
                  "flatness_before_nm": before, "flatness_after_nm": after, "map": str(p),
                  "probe_x_range_mm": [float(r.min()), float(r.max())] if r.size else [],
                  "points_at_negative_x": int(np.sum(r < 0)),
                  "map_components": m.components, "warnings": warnings}
        return StepResult(out, report)

    @classmethod
    def example_cloud(cls, cloud):
        # the spindle angle that brings each point under the probe at X = √(x² + y²) (003's frame)
        return cloud.replace(channels={"c": np.degrees(-np.arctan2(cloud.y, cloud.x)) % 360.0})

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
