"""`correction`: the form error turned into what the next cutting or polishing run takes.

Sign convention (docs/conventions.md, Correction): residual = z − sag in the part frame (positive =
material above the nominal, a high spot); the correction ``dz`` is the height to ADD to the
programmed surface for the next run, dz = −gain × (the error low-passed), piston and tilt removed
(set-up, not form). The material to remove (polishing) is gain × (the error low-passed) − its minimum
over the clear aperture + bias, ≥ 0 everywhere. The math is core.correction (module doc there).

Input: a cloud with a ``residual`` (after `misalignment`, `probe_radius`, `register`…) or a map
whose z is the error (a `bspline_map` map.csv read back, an instrument's error map). Points on one
square lattice are taken node for node; scattered points are fitted by the smoothing B-spline of
core.maps first (as `bspline_map` does).

Outputs (``outputs``; empty: every one the inputs allow):
- cutting:   ``correction.csv`` (x, y, dz; mm, part frame) and ``correction.x3p`` over the clear
             aperture extended by ``extend_mm``;
- radial:    ``correction_radial.csv`` (r, dz: the azimuthal mean about the axis — for an off-axis
             part the mean over each ring's arc on the part, r over the radii it covers; for a flat,
             about the clear aperture's centre) and ``corrected_surface.yaml`` (the recipe's
             `surface:` syntax, even asphere or Forbes Q-con, fitted to programmed + radial dz within
             ``fit_tolerance_nm`` RMS); the non-symmetric remainder in the report (it needs a
             slow/fast tool servo or polishing); needs a rotationally symmetric nominal or a flat;
- freeform:  ``corrected_sag.csv`` (x, y, z = programmed sag + dz) and ``corrected_surface.stl``
             (the same grid triangulated, mm) for CAM; needs a nominal;
- polishing: ``removal.csv`` (x, y, removal in µm) and ``removal.x3p`` (metres, as the standard
             stores heights), ≥ 0 everywhere, the total volume removed in the report; what is excess
             material follows the side the surface was probed from (`probe_radius` side; +z when
             none was given), and the depth is judged inside the clear aperture.
Figures: ``correction.png`` (dz and the predicted error after it), ``correction_radial.png``,
``correction_history.png`` (RMS run by run with ``history_rms_um``). The cloud passes unchanged.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import field_validator

from pointspro.core.errors import DomainError, StepError
from pointspro.core.params.pupil import PupilCentreParams
from pointspro.core.step import Context, Step, StepResult, param

OUTPUTS = ("cutting", "radial", "freeform", "polishing")
#: files of each output, for messages
FILES = {"cutting": "correction.csv, correction.x3p",
         "radial": "correction_radial.csv, corrected_surface.yaml",
         "freeform": "corrected_sag.csv, corrected_surface.stl",
         "polishing": "removal.csv, removal.x3p"}
SIGN = ("dz = height to ADD to the programmed surface for the next run (mm, part frame); "
        "dz = -gain x low-passed form error, form error = residual = z - sag")


class CorrectionParams(PupilCentreParams):
    outputs: list[Literal["cutting", "radial", "freeform", "polishing"]] = param(
        default_factory=list, help="what to write: cutting (correction.csv), radial (turning: "
        "correction_radial.csv, corrected_surface.yaml), freeform (corrected sag grid and STL), "
        "polishing (removal map); empty: every one the inputs allow")
    channel: Literal["auto", "residual", "z"] = param(
        "auto", help="the form error: the residual, or z of a map whose heights are the error (a "
        "map.csv); auto: residual when present")
    gain: float = param(1.0, gt=0, le=1.5, help="share of the error corrected per run (below 1: "
                        "converges more gently through noise and process scatter)")
    cutoff_mm: float | None = param(
        None, unit="mm", gt=0, help="cutoff wavelength of the Gaussian low-pass (ISO 16610-61: 50 % "
        "transmission): the finest detail the process can correct; empty: 2 × tool_radius_mm, else "
        "4 × the map spacing")
    tool_radius_mm: float | None = param(
        None, unit="mm", gt=0, help="radius of the tool's footprint (polishing spot, or the nose "
        "radius of a cutting tool): the cutoff defaults to its diameter")
    extend_mm: float | None = param(
        None, unit="mm", ge=0, help="continue the correction smoothly this far past the clear "
        "aperture (the tool's run-out); empty: one cutoff, as far as the surface exists (its domain)")
    diameter: float | None = param(None, unit="mm", gt=0,
                                   help="clear-aperture diameter; empty: the outer diameter of the "
                                   "last circular `aperture` step applied (about its centre, an "
                                   "annulus without its hole), else the surface's aperture")
    spacing: float | None = param(None, unit="mm", gt=0, help="grid spacing of the outputs; empty: "
                                  "the input grid's, or half the knot spacing for scattered points")
    knot_spacing: float | None = param(None, unit="mm", gt=0, help="B-spline knot spacing for "
                                       "scattered points; empty: automatic (as bspline_map)")
    smoothing: float = param(1e-3, ge=0, le=1e6, help="B-spline penalty for scattered points "
                             "(dimensionless, as bspline_map)")
    bias_um: float = param(0.0, unit="µm", ge=0, help="uniform depth added to the removal map "
                           "(polishing: a minimum removal everywhere)")
    max_depth_um: float | None = param(None, unit="µm", gt=0, help="largest removal depth allowed "
                                       "inside the clear aperture; a deeper removal map is refused "
                                       "(nothing written)")
    fit_tolerance_nm: float = param(1.0, unit="nm", gt=0, help="corrected_surface.yaml must match "
                                    "programmed + radial correction to this RMS over the aperture")
    programmed_surface: dict[str, float | bool | str | list[float] | dict[int | str, float] | None] | None = param(
        None, help="the surface this run was cut with, in the recipe's surface syntax (a previous "
        "corrected_surface.yaml's surface); empty: the recipe's nominal")
    history_rms_um: list[float] = param(
        default_factory=list, unit="µm", help="RMS form error of the previous runs over the clear "
        "aperture, oldest first (from their reports' error_rms_um): plotted with this run")

    @field_validator("programmed_surface", mode="before")
    @classmethod
    def _no_empty_keys(cls, v):
        # `{type:even_asphere, R:-200}` (no space after the colons) is YAML for keys with no value:
        # said so, instead of four lines of the value type's union (a review)
        if isinstance(v, dict):  # only such keys: `aperture: null` is a surface's own way to say none
            for key, val in v.items():
                if val is None and ":" in str(key):
                    raise ValueError(f"key '{key}' has no value: write `{str(key).replace(':', ': ', 1)}` "
                                     "(a space after the colon)")
        return v

    @field_validator("programmed_surface")
    @classmethod
    def _surface(cls, v):
        if v is not None:
            from pointspro.core.surfaces import parse_surface_spec

            parse_surface_spec(v)
        return v

    @field_validator("history_rms_um")
    @classmethod
    def _positive(cls, v):
        if any(not (x > 0) for x in v):
            raise ValueError("RMS values must be > 0")
        return v


def _rotational(surface) -> bool:
    from pointspro.core.surfaces import SurfaceOfRevolution

    return isinstance(surface, SurfaceOfRevolution) and not surface.is_flat()


def _turnable(surface) -> bool:
    """A nominal a lathe can take as a radial program: a surface of revolution, or a flat (faced:
    sag 0 + dz(r) about the part's centre on the spindle)."""
    from pointspro.core.metrics.pupil import is_flat

    return surface is not None and (_rotational(surface) or is_flat(surface))


def _domain_radius(surface) -> float:
    """Largest radius (mm) about the axis where the surface exists (a conic's r_max; inf if none)."""
    for s in (surface, getattr(surface, "_base", None)):
        r = getattr(s, "r_max", None)
        if r is not None:
            return float(r)
    return float("inf")


#: the steepest form error a correction is made for (rad, 99th percentile of the slope of the error
#: low-passed at the cutoff — what the correction is made of — over the aperture; the raw map's pixel
#: noise, σ/h, made a profiler's 0.2 µm pixels read 0.1 rad: a review): 0.1 rad is 5.7° — a form
#: error (what a machine or a polisher corrects) has
#: slopes of µrad to mrad; a map this steep is heights in µm or nm read as mm (a review: an instrument's
#: error map written "x,y,z" in nm became a 99 mm deep removal on a 40 mm part, status ok)
MAX_ERROR_SLOPE = 0.1
#: a form error deeper than this (mm, PV over the aperture) is warned of: possible (a ground blank),
#: rarely what a correction is for, and what heights in µm read as mm look like
WARN_ERROR_PV_MM = 0.05


def _check_plausible(F, h: float, cutoff: float, channel: str) -> None:
    """Refuse an error map whose low-passed form error ``F`` (NaN outside the aperture) no machine
    correction is for (MAX_ERROR_SLOPE), naming the likely unit mistake; the warning for a deep one is
    the caller's (``_deep_warning``). The slope is taken over the cutoff (k nodes): what the filter
    leaves of the noise is still rough from node to node (a profiler's map at 0.2 µm pixels with
    30 nm of noise read 0.11 rad node to node at the default cutoff, 0.02 rad over it)."""
    E = F
    if not np.isfinite(E).any():
        return
    # over the cutoff, but never more than a quarter of the aperture's width in nodes: a cutoff as wide
    # as the aperture (a big polishing tool: 2 × tool_radius_mm) left no pair of nodes inside it and
    # the check was skipped (a 400 nm map in nm read as mm passed with 3e5 µm of correction — a review)
    rows, cols = np.nonzero(np.isfinite(E))
    width = min(np.ptp(rows), np.ptp(cols)) + 1
    k = max(1, min(int(round(cutoff / h)), width // 4))
    gx = (E[:, k:] - E[:, :-k]) / (k * h)
    gy = (E[k:, :] - E[:-k, :]) / (k * h)
    slope = np.concatenate([np.abs(gx[np.isfinite(gx)]), np.abs(gy[np.isfinite(gy)])])
    if slope.size and float(np.percentile(slope, 99)) > MAX_ERROR_SLOPE:
        pv = float(np.nanmax(E) - np.nanmin(E))
        raise StepError(
            f"the form error to correct ({channel}), low-passed at the cutoff, has slopes of "
            f"{np.percentile(slope, 99):.3g} rad (99th percentile) and a PV of {pv:.6g} mm over the "
            "clear aperture: no machine correction "
            f"is that steep (above {MAX_ERROR_SLOPE:g} rad) — the heights are probably in µm or nm but "
            "were read as mm; state the unit in the file's header (e.g. `x [mm],y [mm],z [nm]`, "
            "docs/formats.md)")


def _deep_warning(E) -> list[str]:
    pv = float(np.nanmax(E) - np.nanmin(E)) if np.isfinite(E).any() else 0.0
    if pv > WARN_ERROR_PV_MM:
        return [f"the form error to correct is {pv * 1e3:.4g} µm PV over the clear aperture: deeper than a "
                f"correction usually is ({WARN_ERROR_PV_MM * 1e3:g} µm) — if the heights were in µm or nm, "
                "state the unit in the file's header (docs/formats.md)"]
    return []


def _probe_side(cloud) -> int | None:
    """The side the points were probed from: the last `probe_radius` step's ``side`` (+1 from +z,
    −1 from below), None when no step said (an instrument's map)."""
    for entry in reversed(cloud.provenance):
        if entry.get("id") == "probe_radius":
            side = (entry.get("params") or {}).get("side")
            return None if side is None else (1 if int(side) > 0 else -1)
    return None


def _check_same_side(nominal, programmed) -> None:
    """The programmed surface is the part as cut last run: its sag at 0.7 of the aperture's radius
    must lie on the nominal's side (a programmed R −500 against a nominal R 500 was accepted, and the
    corrected surface then bent the wrong way)."""
    from pointspro.core.errors import DomainError
    from pointspro.core.metrics.pupil import is_flat

    ap = getattr(nominal, "aperture", None) or getattr(programmed, "aperture", None)
    if nominal is None or not ap or is_flat(nominal) or is_flat(programmed):
        return
    r = np.array([0.35 * float(ap)])
    try:
        a, b = float(nominal.sag(r, np.zeros(1))[0]), float(programmed.sag(r, np.zeros(1))[0])
    except (DomainError, ValueError, TypeError):
        return
    if a * b < 0 and min(abs(a), abs(b)) > 1e-3:
        raise StepError(f"programmed_surface bends the other way from the nominal (sag {b:.4g} mm against "
                        f"{a:.4g} mm at r = {r[0]:g} mm): check the sign of its R or c — it is the surface "
                        "the machine cut last run")


class CorrectionStep(Step):
    id = "correction"
    title = "Correction for the next run"
    reads_residual = True
    summary = ("Form error → what the machine or polishing tool takes: correction.csv (dz to add), "
               "radial program and corrected surface, corrected sag + STL, removal map.")
    Params = CorrectionParams

    def run(self, cloud, params: CorrectionParams, ctx: Context) -> StepResult:
        import time

        from pointspro.core import correction as C
        from pointspro.core.metrics.pupil import pupil_of

        t0 = time.perf_counter()
        ctx.progress.check()
        channel = params.channel
        if channel == "auto":
            channel = "residual" if "residual" in cloud.channels else "z"
            from pointspro.core.metrics.pupil import heights_are_sag

            if channel == "z" and heights_are_sag(ctx.surface, cloud.x, cloud.y, cloud.z):
                # the heights of a curved part are its sag, not its form error: a "correction" of
                # them is the whole surface (a 624 µm removal map of a sphere with 0.1 µm of error);
                # an instrument's map of deviations under a curved nominal is corrected as zernike and
                # bspline_map map it (the same test: core/metrics/pupil.py heights_are_sag)
                raise StepError("the cloud has no residual, and its heights z are the part's sag, not its "
                                "form error: run misalignment (or register) before correction, or give "
                                "channel: z for heights that are already a form-error map")
        if channel == "residual" and "residual" not in cloud.channels:
            raise StepError("channel 'residual' asked for, but the cloud has none (run misalignment "
                            "first, or give a map with channel: z)")
        from pointspro.core.metrics.pupil import is_flat

        if channel == "z" and "residual" in cloud.channels and not is_flat(ctx.surface):
            # after misalignment z is the part's sag in the part frame (a review: dz −34 mm written
            # under a header saying "form error = residual")
            raise StepError("channel 'z' asked for, but z holds the part's heights (its sag) and the form "
                            "error is the cloud's residual: leave channel at auto (or give residual)")
        v = cloud.z if channel == "z" else cloud[channel]
        x, y = cloud.x, cloud.y
        nominal = ctx.surface
        programmed = nominal
        if params.programmed_surface is not None:
            from pointspro.core.surfaces import surface_from_spec

            programmed = surface_from_spec(params.programmed_surface, ctx.base_dir)
            if getattr(programmed, "aperture", None) is None and nominal is not None:
                programmed.aperture = getattr(nominal, "aperture", None)
            _check_same_side(nominal, programmed)
        # which outputs: asked, else all the inputs allow
        asked = list(dict.fromkeys(params.outputs))
        skipped = {}
        if asked:
            for o in asked:
                if o in ("radial", "freeform") and programmed is None:
                    raise StepError(f"output '{o}' ({FILES[o]}) needs the nominal surface — give the "
                                    "recipe's `surface:` (or programmed_surface)")
                if o == "radial" and not _turnable(programmed):
                    raise StepError(f"output 'radial' ({FILES['radial']}) needs a rotationally "
                                    "symmetric nominal (even_asphere, qcon, qbfs) or a flat; this one "
                                    f"is {getattr(programmed, 'kind', '?')}, not a surface of revolution")
            outputs = asked
        else:
            outputs = ["cutting"]
            if programmed is None:
                skipped["radial"] = skipped["freeform"] = "no nominal surface"
            else:
                if _turnable(programmed):
                    outputs.append("radial")
                else:
                    skipped["radial"] = f"the nominal ({programmed.kind}) is not a surface of revolution"
                outputs.append("freeform")
            outputs.append("polishing")
        # the clear aperture
        from pointspro.core.metrics.pupil import applied_aperture_step

        ap = applied_aperture_step(cloud)
        diameter = params.diameter
        if diameter is None and ap is not None:  # the clear aperture the recipe applied, else the surface's
            diameter = ap["diameter"]
        if diameter is None and nominal is not None:
            diameter = getattr(nominal, "aperture", None)
        if diameter is None:
            raise StepError("the correction needs the clear aperture: give diameter: (mm) or the "
                            "surface's aperture")
        given = params.given_centre
        from_aperture = False
        if given is None and ap is not None and not ap["moved"] and (ap["centre"] != (0.0, 0.0) or is_flat(nominal)):
            # the zone the recipe's `aperture` kept is about its centre, as its diameter is the
            # clear aperture (a review: an off-centre aperture's diameter taken about the axis, and
            # the step refused "no data from r = 0")
            given, from_aperture = ap["centre"], True
        pupil = pupil_of(x, y, nominal, given)
        if from_aperture:
            import dataclasses

            pupil = dataclasses.replace(pupil, how="the last `aperture` step's centre (center_x, center_y)")
        center = pupil.center
        radius = diameter / 2.0
        hole = 0.0
        if (ap is not None and ap["inner_diameter"] > 0
                and np.hypot(center[0] - ap["centre"][0], center[1] - ap["centre"][1]) <= 1e-9 * radius):
            # an annulus: its hole holds no data, and the coverage is over the ring (a review: Ø40/Ø8
            # refused as "96.1 % covered … give a smaller diameter")
            hole = ap["inner_diameter"] / 2.0
            if hole >= radius:
                raise StepError(f"diameter {diameter:g} mm is not larger than the `aperture` annulus's "
                                f"inner_diameter {2 * hole:g} mm: give a diameter that holds the ring")
        # the radial program's axis: the nominal's (the spindle), or for a flat the part's centre
        axis = (0.0, 0.0) if not is_flat(programmed) else center
        # how far the written region may reach: the programmed surface exists out to its domain (a
        # sphere R 25 mm exists to r = 25 mm; a review: the default extension took Ø46 to r = 26 mm
        # and the whole step failed in the radial fit)
        r_dom = _domain_radius(programmed) if programmed is not None and not is_flat(programmed) else np.inf
        far = float(np.hypot(center[0] - axis[0], center[1] - axis[1])) + radius
        room = r_dom * (1.0 - 1e-6) - far  # just inside: the conic's slope is vertical at its edge
        extend_max = np.floor(room * 1e3) / 1e3 if np.isfinite(room) else np.inf  # whole µm
        if room < 0:  # the aperture itself reaches the domain's edge: no sag to add dz to there
            beyond = (f"the clear aperture (diameter {diameter:g} mm about ({center[0]:g}, {center[1]:g}) "
                      f"mm) reaches r = {far:.6g} mm from the surface's axis, the surface's domain "
                      f"ends at r = {r_dom:.6g} mm")
            for o in ("radial", "freeform"):
                if o in asked:
                    raise StepError(f"output '{o}' ({FILES[o]}): {beyond} — check diameter, centre and "
                                    "the surface's c/k")
                if o in outputs:
                    outputs.remove(o)
                    skipped[o] = beyond
            extend_max = 0.0
        if params.extend_mm is not None and params.extend_mm > extend_max:
            raise StepError(f"extend_mm {params.extend_mm:g} mm takes the correction to r = "
                            f"{far + params.extend_mm:.6g} mm, beyond the surface's domain r ≤ {r_dom:.6g} "
                            f"mm: give extend_mm ≤ {extend_max:g}")
        extend_warning = []
        # the grid spacing and the cutoff, checked before any work
        reg = None
        spacing = params.spacing
        if spacing is None:
            reg = C.regular_grid(x, y, v)
            if reg is not None:
                spacing = reg[3]
        cutoff = params.cutoff_mm
        cutoff_from = "given"
        if cutoff is None and params.tool_radius_mm is not None:
            cutoff, cutoff_from = 2.0 * params.tool_radius_mm, "2 × tool_radius_mm (the footprint)"
        if cutoff is not None and spacing is not None and cutoff < 2.0 * spacing:
            raise StepError(f"cutoff_mm {cutoff:g} mm is below twice the map spacing ({spacing:g} mm): "
                            f"the map holds no detail that fine — use cutoff_mm ≥ {2 * spacing:g} or a "
                            "finer spacing")
        ctx.progress.update(0.05, "error map")

        def defaults(h):
            c = cutoff if cutoff is not None else 4.0 * h
            e = params.extend_mm if params.extend_mm is not None else min(c, extend_max)
            return c, e

        def outer(h):  # the working grid: aperture, extension and the filter's reach beyond it
            c, e = defaults(h)
            return radius + e + 3.0 * C.gaussian_sigma(c)

        try:
            em = C.error_map(x, y, v, center=center, radius=radius, outer=outer, spacing=spacing,
                             knot_spacing=params.knot_spacing, smoothing=params.smoothing,
                             reg=reg if params.spacing is None else False)
        except C.CorrectionInputError as e:
            raise StepError(str(e)) from None
        h = em.spacing
        if cutoff is None:
            cutoff_from = "4 × the map spacing (default)"
        cutoff, extend = defaults(h)
        if params.extend_mm is None and extend < cutoff:
            extend_warning.append(
                f"extend_mm defaults to one cutoff ({cutoff:g} mm), but the surface exists only out to "
                f"r = {r_dom:.6g} mm (its domain): the correction is extended {extend:g} mm past the "
                f"clear aperture, as far as it can go")
        if cutoff < 2.0 * h:
            raise StepError(f"cutoff_mm {cutoff:g} mm is below twice the map spacing ({h:g} mm): "
                            f"the map holds no detail that fine — use cutoff_mm ≥ {2 * h:g} or a "
                            "finer spacing")
        resolution_warning = None
        if params.cutoff_mm is not None and em.knot_spacing is not None and cutoff < 0.99 * 2.0 * em.knot_spacing:
            # a cubic spline resolves wavelengths down to ~2 knot intervals: what the filter passes
            # below that is the spline's interpolation, not the data
            resolution_warning = (
                f"cutoff_mm {cutoff:g} mm is below twice the knot spacing of the map ({em.knot_spacing:.4g} "
                f"mm, scattered points): the map resolves no detail that fine, so the correction holds "
                f"none — give knot_spacing ≤ {cutoff / 2:.3g} (where the points are dense enough) or a "
                "larger cutoff_mm")
        ctx.progress.check()
        ctx.progress.update(0.3, "filter")
        try:
            cor = C.compute_correction(em, center=center, radius=radius, extend=extend,
                                       cutoff=cutoff, gain=params.gain, inner=hole)
        except C.CorrectionInputError as e:
            raise StepError(str(e)) from None
        inside = cor.aperture_mask
        _check_plausible(np.where(inside, cor.filtered, np.nan), h, cutoff, channel)
        RR = np.hypot(cor.xs[None, :] - center[0], cor.ys[:, None] - center[1])
        inner = inside & (RR <= radius - cutoff)
        rep = {
            "outputs": outputs, "skipped": skipped, "sign": SIGN, "channel": channel,
            "map_from": em.source, "spacing_mm": h, "grid": [int(cor.xs.size), int(cor.ys.size)],
            "diameter_mm": diameter, **({"inner_diameter_mm": 2 * hole} if hole > 0 else {}),
            **pupil.report(),
            "gain": params.gain, "cutoff_mm": cutoff, "cutoff_from": cutoff_from,
            "filter": "Gaussian, ISO 16610-61 (σ = α λc / √(2π), 50 % at the cutoff)",
            "extend_mm": extend, "coverage": cor.info["coverage"],
            "holes_filled": cor.info["holes_filled"],
            "piston_removed_um": cor.plane_error[0] * 1e3,
            "tilt_removed_urad": [cor.plane_error[1] * 1e6, cor.plane_error[2] * 1e6],
            "error_rms_um": C.rms(cor.E) * 1e3, "error_pv_um": C.pv(cor.E) * 1e3,
            "correction_rms_um": C.rms(np.where(inside, cor.dz, np.nan)) * 1e3,
            "correction_pv_um": C.pv(cor.dz) * 1e3,
            "predicted_rms_um": C.rms(cor.predicted) * 1e3,
            "predicted_pv_um": C.pv(cor.predicted) * 1e3,
            "predicted_inner_rms_um": C.rms(np.where(inner, cor.predicted, np.nan)) * 1e3,
            "predicted_edge_rms_um": C.rms(np.where(inside & ~inner, cor.predicted, np.nan)) * 1e3,
            "predicted_note": ("error left after the correction, on the map's grid: detail finer than "
                               "the cutoff, the continuation within one cutoff of the rim (edge), and "
                               "(1 − gain) of the rest; inner = r ≤ aperture radius − cutoff"
                               + ("" if em.unresolved_rms is None else
                                  "; the points also hold what the map does not resolve "
                                  "(unresolved_rms_um: noise and detail finer than the knots), which "
                                  "stays")),
            "warnings": ([resolution_warning] if resolution_warning else []) + extend_warning
            + _deep_warning(cor.E),
        }
        if em.unresolved_rms is not None:
            rep["unresolved_rms_um"] = em.unresolved_rms * 1e3
        arts = {}
        comments = [f"PointsPro correction: {SIGN}",
                    f"gain {params.gain:g}; Gaussian low-pass cutoff {cutoff:g} mm (ISO 16610-61); "
                    f"piston {rep['piston_removed_um']:.6g} um and tilt removed (set-up, not form)",
                    f"clear aperture diameter {diameter:g} mm"
                    + (f" (annulus, inner diameter {2 * hole:g} mm)" if hole > 0 else "")
                    + f" about ({center[0]:g}, {center[1]:g}) mm, "
                    f"extended {extend:g} mm; grid spacing {h:g} mm; rows y-major"]
        ctx.progress.update(0.5, "outputs")
        if "cutting" in outputs:
            from pointspro.core.correction.files import write_grid_csv
            from pointspro.core.maps import MapGrid
            from pointspro.core.maps.grid import X3pWriter

            arts["correction.csv"] = lambda p: write_grid_csv(
                p, cor.xs, cor.ys, cor.dz, "x [mm],y [mm],dz [mm]\n", comments)
            arts["correction.x3p"] = X3pWriter(MapGrid(cor.xs, cor.ys, cor.dz, h),
                                               "\n".join(comments) + "\nheights: dz in metres")
        if "polishing" in outputs:
            # which side of the surface is material: a high spot (residual > 0) is excess only when
            # the surface is seen from +z; probed from below (probe_radius side −1) the material lies
            # above it and a low spot is excess (a review: 0.415 µm to remove where the part lacked
            # 0.276 µm). dz is geometric and the same either way
            side = _probe_side(cloud)
            seen = (side or 1)
            removal = C.removal_map(cor, params.bias_um * 1e-3, seen)
            # the depth a polisher must reach on the part: inside the clear aperture (the run-out
            # ring beyond it is no part; a review: 0.442 µm there against 0.422 µm inside)
            depth_um = float(np.nanmax(np.where(inside, removal, np.nan))) * 1e3
            depth_all_um = float(np.nanmax(removal)) * 1e3
            vol = float(np.nansum(removal)) * h * h
            vol_ap = float(np.nansum(np.where(inside, removal, 0.0))) * h * h
            if params.max_depth_um is not None and depth_um > params.max_depth_um:
                raise StepError(f"the removal map is {depth_um:.4g} µm deep inside the clear aperture (bias "
                                f"{params.bias_um:g} µm included), more than max_depth_um "
                                f"{params.max_depth_um:g} µm: nothing written — cut instead of polishing, "
                                "or lower gain/bias")
            if seen > 0:
                side_words = ("seen from +z (probe_radius side +1): the material lies below the surface, "
                              "a high spot (residual > 0) is excess" if side else
                              "seen from +z (no probe side known: an instrument's map): the material is "
                              "taken to lie below the surface, a high spot (residual > 0) is excess")
                formula = "gain × low-passed error − its minimum over the clear aperture + bias"
            else:
                side_words = ("seen from below (probe_radius side −1): the material lies above the "
                              "surface, a low spot (residual < 0) is excess")
                formula = "−gain × low-passed error − its minimum over the clear aperture + bias"
            rep["removal"] = {"max_depth_um": depth_um, "max_depth_written_um": depth_all_um,
                              "min_depth_um": float(np.nanmin(np.where(inside, removal, np.nan))) * 1e3,
                              "bias_um": params.bias_um, "volume_mm3": vol,
                              "volume_aperture_mm3": vol_ap, "probe_side": seen,
                              "side_from": "probe_radius" if side else "default (+z)",
                              "material": side_words,
                              "depth_note": "max_depth_um and min_depth_um (and the max_depth_um limit) "
                                            "are over the clear aperture; max_depth_written_um includes the "
                                            "run-out beyond it, where the removal is clipped at 0 (bias added)",
                              "sign": f"removal = material to remove (µm, ≥ 0) = {formula}; surface "
                                      f"{side_words}"}
            rcom = [f"PointsPro removal map (polishing): removal = material to REMOVE, um, >= 0 "
                    f"everywhere = {'' if seen > 0 else '-'}gain x low-passed form error - its minimum over "
                    f"the clear aperture (the run-out beyond it clipped at 0) + bias {params.bias_um:g} um",
                    f"surface {side_words}".replace("−", "-").replace("µ", "u"),
                    comments[1], comments[2],
                    f"max depth {depth_um:.6g} um inside the clear aperture ({depth_all_um:.6g} um with "
                    f"the run-out); volume removed {vol:.6g} mm^3"]
            from pointspro.core.correction.files import write_grid_csv
            from pointspro.core.maps import MapGrid
            from pointspro.core.maps.grid import X3pWriter

            arts["removal.csv"] = lambda p: write_grid_csv(
                p, cor.xs, cor.ys, removal, "x [mm],y [mm],removal [um]\n", rcom, scale=1e3,
                decimals=9)
            arts["removal.x3p"] = X3pWriter(MapGrid(cor.xs, cor.ys, removal, h), "\n".join(rcom)
                                            + "\nheights: removal in metres (not um as in removal.csv)")
        ctx.progress.check()
        if "radial" in outputs:
            ctx.progress.update(0.6, "radial program")
            self._radial(cor, programmed, params, rep, arts, comments, radius, h, axis)
        if "freeform" in outputs:
            ctx.progress.update(0.8, "corrected sag")
            self._freeform(cor, programmed, rep, arts, comments)
        from pointspro.core.correction.figures import correction_figure, history_figure
        from pointspro.core.figures import png_artifact

        arts["correction.png"] = png_artifact(correction_figure, cor, rep)
        runs = [*params.history_rms_um, rep["error_rms_um"]]
        rep["runs_rms_um"] = runs
        if len(runs) > 1:
            ratios = [b / a for a, b in zip(runs[:-1], runs[1:])]
            rep["run_ratios"] = ratios
            if ratios[-1] > 1.0:
                rep["warnings"].append(f"the form error grew from run {len(runs) - 1} to run "
                                       f"{len(runs)} ({runs[-2]:.4g} → {runs[-1]:.4g} µm RMS): lower "
                                       "the gain or check the sign of the correction the machine took")
            arts["correction_history.png"] = png_artifact(history_figure, runs, rep["predicted_rms_um"])
        rep["seconds"] = time.perf_counter() - t0
        return StepResult(cloud.replace(), rep, arts)

    def _radial(self, cor, programmed, params, rep, arts, comments, radius, h, axis):
        from pointspro.core import correction as C
        from pointspro.core.correction.figures import radial_figure
        from pointspro.core.correction.files import write_radial_csv
        from pointspro.core.figures import png_artifact
        from pointspro.core.metrics.pupil import is_flat
        from pointspro.core.surfaces import EvenAsphere

        flat = is_flat(programmed)
        if flat and not isinstance(programmed, EvenAsphere):
            programmed = EvenAsphere(0.0, 0.0, aperture=getattr(programmed, "aperture", None))
        # A lathe turns about its spindle, the nominal's axis. A part off that axis (an off-axis zone
        # of the parent, `centre` away from it) is turned there too: each ring about the axis crosses
        # it on an arc, and what a radial program can correct at that radius is the mean of dz over
        # that arc — computed so, over the radii the part covers, with no row where no arc lies on
        # the part. A machinist can trust that (it is what the part says about each radius, and the
        # lathe's symmetric errors are about the spindle); a value edge-clamped off the map, or a row
        # at r = 0 with no data under it, he could not (a review: r = 0…12 mm for a part at 5…25 mm)
        off = float(np.hypot(cor.center[0] - axis[0], cor.center[1] - axis[1]))
        on_axis = off <= 1e-9 * h
        r, mean, share = C.azimuthal_mean(cor, axis, return_share=True)
        if r.size < 2:
            raise StepError("output 'radial': the part covers fewer than two rings about the axis at "
                            f"spacing {h:g} mm — use the freeform outputs (corrected_sag.csv)")
        rem = C.radial_remainder(cor, r, mean, axis)
        if on_axis:  # an annulus's hole is continued like the run-out: weighted as it in the fit
            ins = (r <= radius + 1e-9 * h) & (r >= cor.inner - 1e-9 * h)
            fit_radius, norm = radius, cor.outer
        else:  # every row is on the part; no run-out rows
            ins = np.ones(r.size, bool)
            fit_radius = norm = float(r[-1])
        wr = np.maximum(r[ins], h / 4) * share[ins]
        rep["radial"] = {"non_symmetric_rms_um": C.rms(rem) * 1e3, "non_symmetric_pv_um": C.pv(rem) * 1e3,
                         "symmetric_rms_um": float(np.sqrt(np.average(
                             (mean[ins] - np.average(mean[ins], weights=wr)) ** 2, weights=wr))) * 1e3,
                         "note": "the non-symmetric remainder needs a slow/fast tool servo "
                                 "(freeform output) or polishing", "rings": int(r.size),
                         "axis_mm": [float(axis[0]), float(axis[1])],
                         "about": ("the clear aperture's centre (a flat has no axis: the faced part's "
                                   "centre on the spindle)" if flat else "the nominal's axis (the spindle)"),
                         "r_range_mm": [float(r[0]), float(r[-1])]}
        if not on_axis:
            rep["radial"].update(
                off_axis_mm=off, arc_share_max=float(share.max()),
                off_axis_note=f"the part (diameter {2 * radius:g} mm about ({cor.center[0]:g}, "
                              f"{cor.center[1]:g}) mm) lies {off:.4g} mm off the axis: each dz(r) is the "
                              "mean over the ring's arc on the part (the share of the ring on it: 0 at the "
                              "part's inner and outer edge, where the ring touches it, up to "
                              "arc_share_max; the fit weights each ring by it), rows only where an arc "
                              "lies on the part, no run-out rows")
        try:
            fit = C.refit_surface(programmed, r, mean, fit_radius, h, norm_radius=norm,
                                  tol_mm=params.fit_tolerance_nm * 1e-6,
                                  share=None if on_axis else share, inner=cor.inner if on_axis else 0.0)
        except DomainError as e:
            raise StepError(f"output 'radial': the corrected surface: {e}") from None
        surf = fit["surface"]
        if flat:
            about = (f"dz(r) = azimuthal mean of dz about the clear aperture's centre ({axis[0]:g}, "
                     f"{axis[1]:g}) mm (a flat has no axis: put that centre on the spindle); r in mm")
        elif on_axis:
            about = "dz(r) = azimuthal mean of dz about the surface's axis; r in mm"
        else:
            about = (f"off-axis part (diameter {2 * radius:g} mm about ({cor.center[0]:g}, {cor.center[1]:g}) "
                     f"mm): dz(r) = mean of dz over the arc of the ring about the surface's axis (the "
                     f"spindle) that lies on the part; r = {r[0]:g} ... {r[-1]:g} mm, rows only where an "
                     "arc lies on the part")
        rcom = [f"PointsPro radial correction (turning): {SIGN}", about, comments[1]]
        arts["correction_radial.csv"] = lambda p: write_radial_csv(p, r, mean, rcom)
        label = ""
        fitted = None
        if surf is not None:
            sel = r <= norm + 1e-9 * h
            try:
                fitted = surf.sag_r(r) + surf.piston - programmed.sag_r(r)
            except DomainError:
                fitted = None
            w = np.maximum(r[ins], h / 4) * share[ins]
            err = (fitted[ins] - mean[ins]) if fitted is not None else np.array([np.inf])
            rms_area = float(np.sqrt(np.average(err ** 2, weights=w))) if fitted is not None else np.inf
            rep["corrected_surface"] = {
                "type": fit["type"], "why": fit["why"], "fit_rms_nm": rms_area * 1e6,
                "fit_max_nm": float(np.max(np.abs(err))) * 1e6,
                "vertex_offset_um": float(surf.piston) * 1e3,
                "vertex_offset_note": "the radial correction's piston: the new surface has its vertex "
                                      "at z = 0, so program it with this z offset (or leave it: "
                                      "piston is set-up, not form)",
                "tried_rms_nm": {k: e * 1e6 for k, e in fit["tried"].items()},
                "surface": C.spec_of(surf)}
            if fitted is not None and sel.any():
                out = sel & ~ins
                if out.any():
                    rep["corrected_surface"]["extension_rms_nm"] = float(
                        np.sqrt(np.mean((fitted[out] - mean[out]) ** 2))) * 1e6
            label = f"{fit['type']} fit ({rms_area * 1e6:.2g} nm RMS)"
            if rms_area * 1e6 > params.fit_tolerance_nm:
                rep["warnings"].append(
                    f"corrected_surface.yaml matches nominal + radial correction to {rms_area * 1e6:.3g} nm "
                    f"RMS only (tolerance {params.fit_tolerance_nm:g} nm): program correction_radial.csv")
            arts["corrected_surface.yaml"] = _surface_yaml(surf, rep["corrected_surface"], comments,
                                                           about if not on_axis or flat else None)
        else:
            rep["warnings"].append(f"no corrected surface could be fitted: {fit['why']}")
        edges = radius if on_axis else (float(r[0]), float(r[-1]))
        arts["correction_radial.png"] = png_artifact(radial_figure, r, mean, edges, fitted, label)

    def _freeform(self, cor, programmed, rep, arts, comments):
        from pointspro.core.correction.files import write_grid_csv
        from pointspro.core.io.mesh import MeshArtifact, grid_mesh

        ok = np.isfinite(cor.dz)
        X, Y = np.meshgrid(cor.xs, cor.ys)
        Zs = np.full(cor.dz.shape, np.nan)
        try:
            Zs[ok] = programmed.sag(X[ok], Y[ok]) + cor.dz[ok]
        except DomainError as e:
            raise StepError(f"output 'freeform': the nominal is not defined over the extended "
                            f"correction (lower extend_mm): {e}") from None
        fcom = ["PointsPro corrected surface (freeform / tool servo): z = programmed sag + dz (mm, "
                "part frame); program this surface for the next run", comments[1], comments[2]]
        arts["corrected_sag.csv"] = lambda p: write_grid_csv(
            p, cor.xs, cor.ys, Zs, "x [mm],y [mm],z [mm]\n", fcom)
        V, F = grid_mesh(cor.xs, cor.ys, Zs)
        art = MeshArtifact(V, F, "stl")
        arts["corrected_surface.stl"] = art
        rep["freeform"] = {"nodes": int(ok.sum()), "faces": int(len(F)),
                           "z": "programmed sag + dz (mm)"}

    @classmethod
    def example_params(cls) -> dict:
        return {"diameter": 1000.0, "cutoff_mm": 200.0}

    @classmethod
    def example_cloud(cls, cloud):
        from pointspro.core.step import with_example_residual

        return with_example_residual(cloud)


def _surface_yaml(surface, info, comments, about=None) -> str:
    from pointspro.core.correction import spec_of
    from pointspro.core.yamlio import dump_yaml

    head = ["PointsPro corrected nominal for a turning program: sag = programmed sag + radial dz",
            f"form: {info['type']} ({info['why']}); matches programmed + dz(r) to "
            f"{info['fit_rms_nm']:.3g} nm RMS over the clear aperture",
            comments[0], comments[1], *([about] if about else [])]
    body = dump_yaml({"surface": spec_of(surface)}, sort_keys=False, default_flow_style=None)
    return "".join(f"# {h}\n" for h in head) + body
