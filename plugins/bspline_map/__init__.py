"""`bspline_map`: the form-error map — a smoothing bicubic B-spline of the residual on a grid.

Scattered points (raster, star, spiral, CMM) → smoothing spline (core.maps.bspline: penalised least
squares on uniform knots) → grid nodes at multiples of ``spacing`` inside the clear aperture and the
measured region (core.maps.grid). Seed paper 000 builds its form maps the same way (B-splines).

Artifacts: ``map.csv`` (x, y, z in mm per valid node), ``map.x3p`` (ISO 25178-72), ``map.asc``
(ASCII matrix for polishing machines), ``profiles.csv``, ``psd.csv`` (every CSV states its units in
its header: ``x [mm]``, ``angle [deg]``, ``f_x [1/mm]``, ``psd_x [mm^3]``), and the figures
``map.png``, ``profiles.png``, ``psd.png``.
With ``mesh: ply|stl|obj``, ``map_mesh.<fmt>``: the map grid triangulated over its valid nodes for
CAD/FEA (core.io.mesh.grid_mesh: two triangles per cell whose four nodes are valid; mm), z = the
mapped value (``mesh_z: map``) or the nominal's sag plus it (``mesh_z: surface`` — the measured
surface; misalignment's residual is vertical, so this is exact for it). Default none: the batch
writes no mesh unless asked (File → Export mesh… in the window triangulates the map on demand).
The cloud passes through unchanged.
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from pointspro.core.errors import StepError
from pointspro.core.metrics.pupil import pupil_of
from pointspro.core.params.pupil import PupilCentreParams
from pointspro.core.step import Context, Step, StepResult, param


class BSplineMapParams(PupilCentreParams):
    channel: Literal["auto", "residual", "z"] = param(
        "auto", help="what to map: the residual (form error) or z; auto: residual when present")
    spacing: float | None = param(None, unit="mm", gt=0,
                                  help="grid spacing of the map; empty: half the knot spacing, rounded down to 1, 2 or 5 × 10ⁿ "
                                  "(up to 2× finer: 77.8 nm knots give a 20 nm grid)")
    knot_spacing: float | None = param(
        None, unit="mm", gt=0, help="B-spline knot spacing, the finest detail the map holds; empty: "
        "twice the mean point spacing (at most 150 intervals across)")
    smoothing: float = param(1e-3, ge=0, le=1e6, help="penalty on the coefficients' second "
                             "differences, relative to the data (dimensionless; 0 = none)")
    diameter: float | None = param(None, unit="mm", gt=0,
                                   help="clear-aperture diameter of the map; empty: the outer diameter of "
                                        "the last circular `aperture` step applied, else the surface's "
                                        "aperture, else the measured region only")
    extrapolate: bool = param(False, help="also fill nodes of the aperture outside the measured "
                              "region (continued smoothly by the penalty)")
    x3p_revision: Literal["2000", "2017"] = param(
        "2000", help="map.x3p record: 2000 = 'ISO5436 - 2000', read by every X3P reader; 2017 = "
        "'ISO25178-72:2017/DAM1' (newer; SurfaceTopography and older tools refuse it)")
    matrix_unit: Literal["mm", "um", "nm"] = param("um", help="height unit of the ASCII matrix")
    mesh: Literal["none", "ply", "stl", "obj"] = param(
        "none", help="also write the map as a triangle mesh for CAD/FEA, map_mesh.<format> (mm): "
        "binary PLY (float64), binary STL (float32) or OBJ text; none: no mesh")
    mesh_z: Literal["map", "surface"] = param(
        "map", help="z of the mesh: the mapped value itself (the error map), or the nominal "
        "surface's sag plus it (the measured surface; needs the recipe's surface:)")
    profile_angles: list[float] = param(default_factory=lambda: [0.0, 90.0], unit="deg",
                                        help="angles of the profiles through the aperture's centre "
                                             "(from +x towards +y)")


class BSplineMapStep(Step):
    id = "bspline_map"
    title = "Form-error map (B-spline)"
    reads_residual = True
    summary = "Smoothing bicubic B-spline of the residual on a grid: map.csv, map.x3p, map.asc."
    Params = BSplineMapParams

    @classmethod
    def example_cloud(cls, cloud):
        from pointspro.core.step import with_example_residual

        return with_example_residual(cloud)

    def run(self, cloud, params: BSplineMapParams, ctx: Context) -> StepResult:
        from pointspro.core.figures import grid_map_figure, png_artifact, profiles_figure, psd_figure
        from pointspro.core.maps import fit_bspline, grid_map
        from pointspro.core.maps.bspline import DEFAULT_SMOOTHING
        from pointspro.core.maps.grid import nice_spacing

        channel = params.channel
        if channel == "auto":
            channel = "residual" if "residual" in cloud.channels else "z"
            from pointspro.core.metrics.pupil import heights_are_sag

            if channel == "z" and heights_are_sag(ctx.surface, cloud.x, cloud.y, cloud.z):  # a map of the sag
                raise StepError("the cloud has no residual, and its heights z are the part's sag, not its "
                                "form error: run misalignment (or register) before bspline_map, or give "
                                "channel: z for heights that are already a form-error map")
        if channel == "residual" and "residual" not in cloud.channels:
            raise StepError("channel 'residual' asked for, but the cloud has none (run misalignment "
                            "first, or map z)")
        v = cloud.z if channel == "z" else cloud[channel]
        x, y = cloud.x, cloud.y
        # the clear aperture: given, else the last circular `aperture` step the recipe applied (as
        # `correction` takes it: the example's map said 1300 mm over a part its recipe cut to 1290 —
        # a newcomer's review), else the surface's
        from pointspro.core.metrics.pupil import applied_aperture_step

        ap = applied_aperture_step(cloud)
        diameter = params.diameter
        given = params.given_centre
        inner = 0.0
        if diameter is None and ap is not None:
            diameter = ap["diameter"]
            if given is None and not ap["moved"]:  # where the aperture step cut (its default (0, 0) is
                given = ap["centre"]                # the nominal's axis); after a pose fit the axis
        if diameter is None and ctx.surface is not None:
            diameter = getattr(ctx.surface, "aperture", None)
        # the aperture's and the profiles' centre: given, else the surface's axis, else the measured
        # region's bounding-box centre (never a file's corner origin)
        center = pupil_of(x, y, ctx.surface, given).center
        if (ap is not None and diameter == ap["diameter"] and ap["inner_diameter"] > 0
                and np.hypot(center[0] - ap["centre"][0], center[1] - ap["centre"][1]) <= 1e-9 * diameter):
            inner = ap["inner_diameter"]  # the annulus's hole, where it was cut (as correction takes it)
        # the spline covers the points' own box (fit_bspline's default): the aperture's box only
        # when the map is to be extrapolated over the whole aperture, where the penalty's
        # continuation fills it. Over the aperture's box, a 100 mm patch of a 1300 mm part had its
        # knots coarsened to 15 mm until the coefficients were no more than the points, and the map
        # missed the form error it was measured for (issue 16's review).
        bounds, whole = None, True
        if diameter is not None:
            inside = (x - center[0]) ** 2 + (y - center[1]) ** 2 <= (diameter / 2) ** 2
            if not inside.any():
                raise StepError(f"no point lies inside the {diameter:g} mm aperture centred at "
                                f"({center[0]:g}, {center[1]:g}) mm")
            if not inside.all():
                x, y, v, whole = x[inside], y[inside], v[inside], False
            if params.extrapolate:
                r = diameter / 2
                bounds = (center[0] - r, center[0] + r, center[1] - r, center[1] + r)
        ctx.progress.check()
        sub = ctx.progress.sub(0.0, 0.8)
        try:
            spline = fit_bspline(x, y, v, knot_spacing=params.knot_spacing,
                                 smoothing=params.smoothing, bounds=bounds,
                                 progress=lambda f, m: sub.update(f, m))
        except ValueError as e:
            raise StepError(str(e)) from None
        ctx.progress.check()
        cells = _empty_fraction(x, y, spline)
        spacing = params.spacing if params.spacing is not None else nice_spacing(spline.h / 2)
        try:
            grid = grid_map(spline, spacing, x, y, diameter=diameter, center=center,
                            extrapolate=params.extrapolate, inner_diameter=inner)
        except ValueError as e:
            raise StepError(str(e)) from None
        ctx.progress.update(0.9, "map")
        fit_res = spline(x, y)
        np.subtract(v, fit_res, out=fit_res)  # in place: one full-length column (issue 26)
        zv = grid.z[grid.valid]
        warnings = []
        if cells > 0.3:
            warnings.append(f"{cells:.0%} of the knot cells over the points hold no point: the map "
                            "there is the penalty's continuation — use a larger knot_spacing")
        if zv.size == 0:
            raise StepError("no map node lies in the measured region; check spacing and diameter")
        resolution = _resolution_note(spline)
        report = {
            "channel": channel, "knot_spacing": spline.h, "intervals": list(spline.intervals),
            "smoothing": params.smoothing, "spacing": spacing, "grid": [len(grid.xs), len(grid.ys)],
            "nodes": int(zv.size), "diameter": diameter, "centre_mm": [float(center[0]), float(center[1])],
            **({"inner_diameter": inner} if inner else {}),
            "fit_residual_rms_um": float(np.sqrt(fit_res @ fit_res / len(fit_res)) * 1e3),
            "map_rms_um": float(np.std(zv) * 1e3), "map_pv_um": float(np.ptp(zv) * 1e3),
            "empty_cell_fraction": cells, "warnings": warnings,
        }
        shown = grid
        if channel == "z":
            # an instrument's heights carry the set-up's piston and tilt (a MetroPro map: 50.7 µm of
            # offset and 75 nm of tilt over 13 nm of form): the figure shows them removed, as the
            # summary's figures are, and says so (a review: map.png was one saturated colour, its
            # RMS 75.28 nm beside the summary's 13.33 nm), and profiles.png likewise (its raw z was a
            # 270 nm tilt ramp on a "form error" axis). map.csv, profiles.csv and the others keep z.
            shown = _less_plane(grid)
            flat = shown.z[shown.valid]
            report["map_rms_tilt_removed_um"] = float(np.std(flat) * 1e3)
            report["map_pv_tilt_removed_um"] = float(np.ptp(flat) * 1e3)
        if resolution:
            report["resolution_note"] = resolution
        if params.extrapolate:
            _extrapolation_report(report, grid, spline, spacing, x, y, diameter, center)
        unit = params.matrix_unit
        mesh_art = None
        if params.mesh != "none":
            mesh_art = _map_mesh(grid, channel, params, ctx)
            report["mesh"] = {"file": f"map_mesh.{params.mesh}", "z": mesh_art.z_label,
                              "vertices": int(len(mesh_art.vertices)), "faces": int(len(mesh_art.faces))}
        arts = {
            # keep map.csv the grid's bound write_csv: the window's Export mesh… finds the grid there
            # (core.io.mesh.map_mesh_of)
            "map.csv": grid.write_csv,
            "map.x3p": lambda p: grid.write_x3p(p, params.x3p_revision),
            "map.asc": lambda p: grid.write_ascii_matrix(p, unit),
            "map.png": png_artifact(grid_map_figure, shown, title=_map_title(channel, report)),
            "profiles.png": png_artifact(profiles_figure, shown, tuple(params.profile_angles), center,
                                         "form error" if shown is grid else "z, piston and tilt removed"),
            "profiles.csv": lambda p: _write_profiles(p, grid, params.profile_angles, center),
            "psd.png": png_artifact(psd_figure, grid),
            "psd.csv": lambda p: _write_psd(p, grid),
        }
        if mesh_art is not None:
            arts[f"map_mesh.{params.mesh}"] = mesh_art
        out = cloud.replace()
        reuse = {}
        if (bounds is None and whole and params.knot_spacing is None
                and params.smoothing == DEFAULT_SMOOTHING and channel == "residual"):
            # fit_bspline's defaults on the cloud's own arrays: the summary's slope-RMS spline
            # (core.pipeline._reusable), which need not be fitted again
            reuse["slope_spline"] = {"spline": spline, "xyz": out.xyz, "values": out["residual"]}
        return StepResult(out, report, arts, reuse)

    @classmethod
    def example_params(cls) -> dict:
        return {}


#: the map's PV over all its nodes above this many times its PV over the measured ones: warned
EXTRAPOLATION_PV_RATIO = 1.5


def _extrapolation_report(report, grid, spline, spacing, x, y, diameter, center) -> None:
    """With ``extrapolate``, the nodes beyond the measured points are the continuation of the outermost
    knot cells, where the noise is least held: a review's 9 mm of points mapped over 20 mm read PV
    3155 nm for a true 418 nm at 10 nm of noise (791 nm at 2 nm), with no word. The report gives the
    map's RMS and PV over the measured nodes too, the share of extrapolated nodes, and a warning when
    the PV over all of them is well above the measured nodes' (EXTRAPOLATION_PV_RATIO)."""
    from pointspro.core.maps import grid_map

    try:
        measured = grid_map(spline, spacing, x, y, diameter=diameter, center=center, extrapolate=False)
    except ValueError:  # too few nodes over the points to be a map of them
        return
    # both grids' nodes lie at multiples of the spacing: the measured one is a window of the whole
    ox, oy = (int(np.rint((m[0] - g[0]) / spacing)) for m, g in ((measured.xs, grid.xs),
                                                                  (measured.ys, grid.ys)))
    inside_grid = np.zeros(grid.z.shape, bool)
    ny, nx = measured.z.shape
    if 0 <= ox and 0 <= oy and oy + ny <= grid.z.shape[0] and ox + nx <= grid.z.shape[1]:
        inside_grid[oy:oy + ny, ox:ox + nx] = measured.valid
    ok = grid.valid
    inside = inside_grid[ok]
    zv = grid.z[ok]
    if np.count_nonzero(inside) < 4:  # too few measured nodes to state a PV of them
        report["extrapolated_node_fraction"] = float(1.0 - inside.mean())
        return
    pv_all, pv_in = float(np.ptp(zv)), float(np.ptp(zv[inside]))
    report.update(map_rms_measured_um=float(np.std(zv[inside]) * 1e3), map_pv_measured_um=pv_in * 1e3,
                  extrapolated_node_fraction=float(1.0 - inside.mean()))
    if pv_all > EXTRAPOLATION_PV_RATIO * pv_in:
        from pointspro.core.units import format_length

        report["warnings"].append(
            f"the map's PV {format_length(pv_all, 4)} includes {100 * (1.0 - inside.mean()):.3g} % of its nodes "
            f"extrapolated beyond the points; over the measured nodes it is {format_length(pv_in, 4)}. "
            "Beyond the points the map is the continuation of the outermost knot cells, which their noise "
            "swings (a few nm of noise: µm at the rim) — use extrapolate only where the map must cover the "
            "whole aperture (map_pv_measured_um, map_rms_measured_um in the report)")


def _map_mesh(grid, channel, params, ctx):
    """The map's mesh artifact (core.io.mesh): z the map, or the nominal's sag plus the map."""
    from pointspro.core.errors import DomainError
    from pointspro.core.io.mesh import MeshArtifact, grid_mesh

    V, F = grid_mesh(grid.xs, grid.ys, grid.z)
    label = f"{channel} map (mm)"
    if params.mesh_z == "surface" and channel != "z":  # a map of z is the surface already
        if ctx.surface is None:
            raise StepError("mesh_z: surface needs the recipe's nominal `surface:` (its sag plus the "
                            "map); use mesh_z: map for the error map")
        try:
            V[:, 2] = V[:, 2] + ctx.surface.sag(V[:, 0], V[:, 1])
        except DomainError as e:
            raise StepError(f"mesh_z: surface: the nominal is not defined at every map node: {e}") from None
        label = f"nominal sag + {channel} map (mm)"
    art = MeshArtifact(V, F, params.mesh)
    art.z_label = label
    return art


#: the headers of profiles.csv and psd.csv: names and units (docs/formats.md, Files PointsPro writes)
PROFILES_HEADER = "angle [deg],s [mm],x [mm],y [mm],z [mm]\n"
PSD_HEADER = "f_x [1/mm],psd_x [mm^3],f_y [1/mm],psd_y [mm^3]\n"


def _write_profiles(path, grid, angles, center) -> None:
    """angle (degrees), s (mm along the cut through the centre), x, y, z (mm); one block per angle;
    the header states the units (PROFILES_HEADER)."""
    from pointspro.core.metrics.profiles import cos_sin_deg, profile

    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(PROFILES_HEADER)
        for a in angles:
            s, z = profile(grid, a, center)
            c, sn = cos_sin_deg(a)  # exact at 0°, 90°: the cut's x, y are the nodes' own
            for si, zi in zip(s.tolist(), z.tolist()):
                f.write(f"{float(a)!r},{si!r},{float(center[0] + si * c)!r},"
                        f"{float(center[1] + si * sn)!r},"
                        f"{'nan' if zi != zi else repr(zi)}\n")


def _less_plane(grid):
    """The map less its least-squares plane over the valid nodes (core.pipeline.remove_piston_tilt)."""
    from pointspro.core.maps import MapGrid
    from pointspro.core.pipeline import remove_piston_tilt

    X, Y = np.meshgrid(grid.xs, grid.ys)
    ok = grid.valid
    z = np.full(grid.z.shape, np.nan)
    z[ok] = remove_piston_tilt(X[ok], Y[ok], grid.z[ok])
    return MapGrid(grid.xs, grid.ys, z, grid.spacing)


def _map_title(channel: str, report: dict) -> str:
    from pointspro.core.units import format_length

    if channel == "z":
        return (f"z map, piston and tilt removed: RMS {format_length(report['map_rms_tilt_removed_um'] * 1e-3, 4)}, "
                f"PV {format_length(report['map_pv_tilt_removed_um'] * 1e-3, 4)}")
    return (f"{channel} map: RMS {format_length(report['map_rms_um'] * 1e-3, 4)}, "
            f"PV {format_length(report['map_pv_um'] * 1e-3, 4)}")


def _write_psd(path, grid) -> None:
    """The PSD along x against its own frequencies f_x, and along y against f_y (1/mm; mm^3 = mm² per
    1/mm), one-sided, Hann window; the header states the units (PSD_HEADER). Each direction has its
    own frequencies (1/(n·Δ) steps up to Nyquist): a non-square map's psd_y was written against f_x
    (a review: a 5 mm ripple along y peaked at 0.0995 /mm instead of 0.2, and the rows stopped at
    the shorter direction's length). The shorter pair's columns are left empty below its end."""
    from pointspro.core.metrics.profiles import psd_1d

    fx, px = (a.tolist() for a in psd_1d(grid, "x"))  # Python floats: repr is the shortest exact text
    fy, py = (a.tolist() for a in psd_1d(grid, "y"))
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(PSD_HEADER)
        for i in range(max(len(fx), len(fy))):
            a = f"{fx[i]!r},{px[i]!r}" if i < len(fx) else ","
            b = f"{fy[i]!r},{py[i]!r}" if i < len(fy) else ","
            f.write(f"{a},{b}\n")


def _resolution_note(spline) -> str | None:
    """When the automatic knots are set by the scan pattern's gaps (between a star's spokes, a coarse
    spiral's turns) well above what the points' density alone would give, say what the map then
    cannot hold: a review's 0.4 µm ring 40 mm wide on a star scan sampled every 5 mm along its lines
    came out flattened (−111 nm in a band where the truth averages −37 nm), and the map's fit
    residual, being at the noise, did not show it."""
    t = spline.knot_terms
    if not t or t["gaps"] < max(t["points"], t["size"]) or t["gaps"] < 1.5 * t["points"]:
        return None
    return (f"knots every {spline.h:.4g} mm, set by the widest gaps between the scan's lines (the points' "
            f"density alone would give {t['points']:.3g} mm): the map holds no detail narrower than about "
            f"{2 * spline.h:.3g} mm, however densely each line is sampled — a raster or more lines resolve "
            "more; knot_spacing chooses finer knots where the lines allow")


def _empty_fraction(x, y, spline) -> float:
    """Fraction of knot cells inside the points' hull-ish box that hold no point."""
    nx, ny = spline.intervals
    occ = np.zeros((nx, ny), bool)
    for s in range(0, len(x), 1 << 18):  # chunks: no full-length index columns (issue 26)
        kx = np.clip(((x[s:s + (1 << 18)] - spline.x0) / spline.h).astype(np.intp), 0, nx - 1)
        ky = np.clip(((y[s:s + (1 << 18)] - spline.y0) / spline.h).astype(np.intp), 0, ny - 1)
        occ[kx, ky] = True
    # cells between occupied cells along x (inside the measured outline)
    first = np.where(occ.any(axis=0), occ.argmax(axis=0), 0)
    last = np.where(occ.any(axis=0), nx - 1 - occ[::-1].argmax(axis=0), -1)
    inside = (np.arange(nx)[:, None] >= first[None, :]) & (np.arange(nx)[:, None] <= last[None, :])
    n_in = inside.sum()
    return float((inside & ~occ).sum() / n_in) if n_in else 0.0
