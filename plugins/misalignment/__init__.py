"""`misalignment`: remove the part's five-DOF pose and return the form error (paper 002 §4).

The measured points carry a tilt about x and y and shifts in x, y, z relative to the design equation
(rotation about the optical axis is not observable on a surface of revolution). With the design
surface fixed, the pose (docs/conventions.md "Frames and signs": q = Rx(α) Ry(β) p + t) is fitted by least squares on
the vertical residual in the part frame,

    rᵢ = p_z,i − f(p_x,i, p_y,i),   pᵢ = Rᵀ (qᵢ − t),

with an analytic Jacobian (core/geometry/posed_fit.py) and Levenberg–Marquardt on the normal
equations, so that it converges from zero for misalignments of degrees and tens of millimetres and
runs in well under a second on 10⁶ points. Optional DOF: the vertex radius (`radius`) and the conic
(`conic`) for users who want them. Stylus profiles (core.profiles: an x, z file, an `angle` or
`profile` channel) are fitted in their own planes (profile.py). The output is the cloud in the part frame with
``residual = z − sag(x, y)`` (mm). A residual that is a large share of the nominal's own sag
variation over the points — a wrong nominal, not a form error — is refused, naming the curvature's sign
when the points fit the nominal turned upside down (core/geometry/nominal_check.py).

Uncertainties are Type A: s²(JᵀJ)⁻¹ with s² the residual variance — they treat the form error as
random, so read them as the spread the data allows, not as a calibration uncertainty.
"""
from __future__ import annotations

import numpy as np
from pydantic import field_validator

from pointspro.core.errors import StepError
from pointspro.core.geometry.posed_fit import FIT_WEIGHTS_NOTE, fit_over_the_area
from pointspro.core.params.pose import (
    EXCLUDE_HELP,
    FIVE_DOF,
    INITIAL_HELP,
    MAX_ITER_HELP,
    InitialPose,
    dof_for_surface,
    validate_dof,
)
from pointspro.core.step import Context, Params, Step, StepResult, param


class MisalignmentParams(Params):
    dof: list[str] = param(default_factory=lambda: list(FIVE_DOF),
                           help="fitted degrees of freedom among alpha, beta, dx, dy, dz, radius, "
                                "conic; leave one out to hold it at its initial value")
    initial: InitialPose = param(default_factory=InitialPose, help=INITIAL_HELP)
    max_iterations: int = param(100, ge=1, le=10000, help=MAX_ITER_HELP)
    exclude_beyond: float | None = param(8.0, gt=2.0, le=1000.0, help=EXCLUDE_HELP)

    @field_validator("dof")
    @classmethod
    def _dof(cls, v):
        return validate_dof(v, aspheric_allowed=False)


class MisalignmentStep(Step):
    id = "misalignment"
    title = "Misalignment (pose fit)"  # which degrees of freedom: the report's `parameters`
    makes_residual = True
    summary = "Fit and remove tilt and decenter; residual = z − sag in the part frame."
    Params = MisalignmentParams
    needs_surface = True  # the batch refuses a recipe without `surface:` before any input

    def run(self, cloud, params: MisalignmentParams, ctx: Context) -> StepResult:
        ctx.progress.check()
        surface = ctx.require_surface(self.id)
        from pointspro.core.profiles import profiles_of

        profiles = profiles_of(cloud)
        if profiles is not None:  # stylus profiles: each fitted in its own plane (profile.py)
            from .profile import run_profiles

            out, report, arts = run_profiles(cloud, profiles, params, ctx, surface)
            return StepResult(out, report, arts)
        dof, note = dof_for_surface(surface, params.dof, "dof" in params.model_fields_set)
        try:
            # weighted by the points' areas when the fit takes form out (radius, conic, A_n free)
            fit, weights = fit_over_the_area(surface, cloud.xyz, dof, params.initial.as_dof(), "vertical",
                                             max_iter=params.max_iterations, check=ctx.progress.check)
            part, residual = fit.part, fit.residuals  # p = Rᵀ(q − t) and z − sag(x, y) at the solution
            excluded, exclusion = None, {}
            if params.exclude_beyond is not None:
                from pointspro.core.geometry.outliers import refit_without_outliers

                ctx.progress.update(0.6, "outliers")
                fit, part, residual, excluded, exclusion = refit_without_outliers(
                    surface, cloud.xyz, dof, params.initial.as_dof(), "vertical", params.exclude_beyond,
                    fit, part, residual, max_iter=params.max_iterations, check=ctx.progress.check,
                    weights=weights)
        except StepError as e:
            from pointspro.core.geometry.nominal_check import check_failed_fit
            from pointspro.core.profiles import with_profile_hint

            # a flipped curvature the fit cannot even converge on is named as such (core/geometry/nominal_check.py)
            flipped = check_failed_fit(surface, cloud.xyz, dof, params.initial.as_dof(),
                                       params.max_iterations, ctx.progress.check, e)
            raise (StepError(flipped) if flipped else with_profile_hint(e)) from None
        from pointspro.core.geometry.nominal_check import check_fit

        # a residual the size of the nominal's own sag is a wrong nominal (a flipped c), not a form error
        check_fit(surface, fit.surface, cloud.xyz, part, residual, dof, params.initial.as_dof(),
                  params.max_iterations, ctx.progress.check)
        ctx.progress.update(0.9, "residual")
        report = fit.report()
        if weights is not None:  # the design parameters' fit over the area (core/geometry/posed_fit.py)
            report["fit_weights"] = FIT_WEIGHTS_NOTE
        from pointspro.core.metrics.area_weights import area_weights, rms_about_zero, weighting_words

        # the residual's RMS over the area (docs/conventions.md, Summary figures): a star or spiral
        # crowds its centre, where a plain mean over the points read ±20 % off; the points' areas in
        # the part frame, as the design fit's (None on an even sampling: the plain mean). About zero,
        # as before — the pose's piston (dz held) counts, on any sampling: √(Σ w r² / Σ w)
        area = weights if weights is not None else area_weights(part[:, 0], part[:, 1])
        report.update(residual_rms_um=rms_about_zero(residual, area) * 1e3,
                      residual_rms_over=weighting_words(area),
                      residual_pv_um=float(np.ptp(residual) * 1e3),
                      warnings=list(fit.warnings) + ([note] if note else []) + exclusion.pop("warnings", []),
                      **exclusion)
        if excluded is not None and excluded.any():
            rows = cloud["index"][excluded] if "index" in cloud.channels else np.flatnonzero(excluded)
            report["excluded_from_pose_rows"] = [int(r) for r in rows[:50]]
        if fit.surface is not surface:
            report["surface"] = fit.surface.describe()
        ctx.log.info("pose %s; residual RMS %.4g µm, PV %.4g µm (%d iterations)", ", ".join(
            f"{k} {report[k]:.6g}" for k in ("alpha_deg", "beta_deg", "dx", "dy", "dz") if k in report),
            report["residual_rms_um"], report["residual_pv_um"], report.get("iterations", 0))
        out = cloud.replace(xyz=part, channels={"residual": residual}, meta={"frame": "part"})
        from pointspro.core.figures import png_artifact

        arts = {"misalignment.png": png_artifact(_before_after, surface, cloud.xyz, part, residual, area)}
        return StepResult(out, report, arts)


def _before_after(surface, measured, part, residual, area):
    """z − sag(x, y) as measured (the pose still in it) beside the residual in the part frame;
    ``area``: the points' areas in the part frame (None: an even sampling)."""
    from pointspro.core.errors import DomainError
    from pointspro.core.figures import before_after, scattered_map

    try:  # by blocks: the sag's temporaries stay block-sized (issue 26)
        before = np.empty(len(measured))
        for s in range(0, len(measured), 1 << 16):
            m = measured[s:s + (1 << 16)]
            np.subtract(m[:, 2], surface.sag(m[:, 0], m[:, 1]), out=before[s:s + len(m)])
    except DomainError:
        return scattered_map(part[:, 0], part[:, 1], residual, "residual after removing the pose")
    # the titles' RMS over the area (docs/conventions.md, Summary figures): the same points in both
    # panels, each standing for its area in the part frame (as the summary weighs the residual)
    from pointspro.core.metrics.area_weights import rms_about_zero

    return before_after(measured[:, 0], measured[:, 1], before, residual, what="pose removal",
                        x2=part[:, 0], y2=part[:, 1], weights=area,
                        after_rms_mm=rms_about_zero(residual, area))  # the report's residual_rms_um
