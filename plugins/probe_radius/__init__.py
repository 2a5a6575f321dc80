"""`probe_radius`: probe-ball radius compensation of CMM probe-centre points (paper 002 §3).

A CMM records the centre P0 of the probe ball, not the contact point P. The centres lie at exactly
the ball radius ρ from the part along its normal, so P = P0 − s·ρ·n̂ (s = +1 when the ball touches from
the +z side). PointsPro 1.0 fitted an asphere *plus a z offset* to the centres and took n̂ from that
model; an offset asphere is not an asphere, which limited it to ~4 nm (Table 2: 4.08 / 4.06 / 0.50 nm
RMS in x / y / z). Here the exact geometry is fitted instead: the design surface posed in the
measuring frame, with the orthogonal distance of every centre from it equal to s·ρ,

    minimise Σ (dᵢ − s·ρ)²,   dᵢ = signed distance of Rᵀ(qᵢ − t) from the surface,

dᵢ from an exact foot-point solve (1-D Newton in the meridian plane for a surface of revolution) and
an analytic Jacobian (core/geometry/posed_fit.py). By default the design is fixed and the pose is fitted;
the paper's option of fitting c, k and chosen A_n too is `dof: [alpha, beta, dx, dy, dz, radius,
conic, A4, A6]`. Each centre then moves by −s·ρ·n̂ with n̂ the design normal at its foot point, refined
from the data's own slopes where the part has form error (normals.py). The output stays in the
measuring frame, as the input. Stylus profiles (core.profiles) get the same exact fit in each
profile's plane: the 2-D offset curve of the meridian (profile.py).

A nominal whose curvature has the wrong sign (concave for convex: the example with c and A negated)
makes the fit fail ("cannot separate … fit fewer DOF", "did not converge") or converge to a distance
residual the size of the nominal's sag; either way the centres mirrored in z are fitted to the nominal
and, when they fit far better, the sign of `surface.c` is named (core/geometry/nominal_check.py, shared with misalignment).
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import field_validator

from pointspro.core.errors import DomainError, StepError
from pointspro.core.geometry.posed_fit import FIT_WEIGHTS_NOTE, PosedSurfaceFit, fit_over_the_area
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

from .normals import refined_normals, residual_slopes


class ProbeRadiusParams(Params):
    radius: float = param(..., unit="mm", gt=0, le=100, help="probe-ball radius (half the ball diameter)")
    side: Literal[1, -1] = param(1, help="+1: the ball touches the part from the +z side; −1: from below")
    dof: list[str] = param(default_factory=lambda: list(FIVE_DOF),
                           help="fitted degrees of freedom: alpha, beta, dx, dy, dz (pose) and, as paper 002 "
                                "does, radius, conic, A4, A6, … (the design surface)")
    initial: InitialPose = param(default_factory=InitialPose, help=INITIAL_HELP)
    normals: Literal["refined", "design"] = param(
        "refined", help="refined: design normals tilted by the data's own slopes (exact on parts with "
                        "form error); design: the fitted surface's normals")
    neighbours: int = param(16, ge=6, le=200, help="points per local slope fit when normals are refined")
    max_iterations: int = param(100, ge=1, le=10000, help=MAX_ITER_HELP)
    exclude_beyond: float | None = param(8.0, gt=2.0, le=1000.0, help=EXCLUDE_HELP)

    @field_validator("dof")
    @classmethod
    def _dof(cls, v):
        return validate_dof(v)


def check_no_fold(surface, foot: np.ndarray, side: int, radius: float) -> None:
    """The offset surface at distance s·ρ folds where s·ρ·κ ≥ 1 (κ a principal curvature, > 0 when
    its centre is on +z): the ball cannot touch there and the centres do not define a surface."""
    from pointspro.core.surfaces import SurfaceOfRevolution

    if not isinstance(surface, SurfaceOfRevolution) or len(foot) == 0:
        return
    rho = np.sqrt(foot[:, 0] ** 2 + foot[:, 1] ** 2)
    km, ks = surface.principal_curvatures(rho)
    worst = np.maximum(side * km, side * ks) * radius
    i = int(np.argmax(worst))
    if worst[i] >= 1.0:
        rc = radius / worst[i]
        raise StepError(f"the probe radius {radius:g} mm exceeds the part's local radius of curvature "
                        f"({rc:.4g} mm at r = {rho[i]:.4g} mm) on the ball's side: the offset surface folds "
                        "there and the centres cannot be compensated — use a smaller ball or check `side`")


#: a distance residual above this RMS (mm) makes the step try the other probe side
SIDE_CHECK_RMS = 1e-3
#: the other side fits this much better (RMS ratio): refused; below SIDE_WARN_RATIO a warning
SIDE_REFUSE_RATIO, SIDE_WARN_RATIO = 0.05, 0.3
#: points the other side is fitted on at most (evenly spread rows)
SIDE_CHECK_POINTS = 20_000


def _other_side_check(surface, centres, dof, params, e, ctx) -> str | None:
    """A wrong ``side`` on a steep part is no fit failure: the pose absorbs most of the 2ρ offset and
    leaves a smooth power/spherical residual that reads as form error (a paraboloid with 56° slopes,
    side −1 for +1 data: RMS 219.6 µm for a true 0.107 µm, exit 0). When the distance residual is
    large (RMS > SIDE_CHECK_RMS) the other side is fitted on ≤ SIDE_CHECK_POINTS of the centres:
    fitting ≥ 20× better (RMS ratio) is refused, ≥ 3× better a warning. Returns the warning or None."""
    rms = float(np.sqrt(np.mean(e * e)))
    if not rms > SIDE_CHECK_RMS:
        return None
    step = max(1, len(centres) // SIDE_CHECK_POINTS)
    sub = centres[::step]
    other = -params.side
    # the other side with the same DOF; where that fit cannot separate the tilts from the decentres (a
    # nearly spherical part), with the tilts and the piston only — a review: the right side's fit
    # failed so, the wrong side's converged with a 2 µm false form error, and the check's own fit of
    # the right side failed alike and was passed over in silence
    tries = [dof] + ([[d for d in dof if d not in ("dx", "dy")]]
                     if {"dx", "dy"} & set(dof) and {"alpha", "beta"} & set(dof) else [])
    d = why = None
    for dofs in tries:
        try:
            alt = PosedSurfaceFit(surface, sub, dofs, params.initial.as_dof(), "normal",
                                  offset=other * params.radius, max_iter=params.max_iterations,
                                  check=ctx.progress.check).fit()
            _, _, d = alt.foot_point()
            break
        except (StepError, DomainError) as err:
            why = str(err).split(":")[0]
    if d is None:
        return (f"the distance residual RMS {rms * 1e3:.4g} µm is far above a probing error, and the "
                f"centres could not be fitted with side {other:+d} to compare ({why}): check `side` "
                "(+1: the ball touches the part from +z, −1: from below)")
    e_alt = d - other * params.radius
    rms_sub = float(np.sqrt(np.mean(e[::step] ** 2)))
    rms_alt = float(np.sqrt(np.mean(e_alt * e_alt)))
    text = (f"with side {other:+d} the centres fit {rms_sub / max(rms_alt, 1e-300):.3g}× better (distance "
            f"residual RMS {rms_alt * 1e3:.4g} µm against {rms_sub * 1e3:.4g} µm with side "
            f"{params.side:+d}): check `side` (+1: the ball touches the part from +z, −1: from below)")
    if rms_alt < SIDE_REFUSE_RATIO * rms_sub:
        raise StepError(text)
    return text if rms_alt < SIDE_WARN_RATIO * rms_sub else None


class ProbeRadiusStep(Step):
    id = "probe_radius"
    title = "Probe-radius compensation"
    moves_points = True  # and hands a residual it finds on untouched (core/step.py)
    summary = "Probe-ball centres → contact points by the exact offset-surface fit."
    Params = ProbeRadiusParams
    needs_surface = True  # the batch refuses a recipe without `surface:` before any input

    @classmethod
    def example_params(cls) -> dict:
        return {"radius": 2.0, "side": 1}

    def run(self, cloud, params: ProbeRadiusParams, ctx: Context) -> StepResult:
        ctx.progress.check()
        surface = ctx.require_surface(self.id)
        if "probe_residual" in cloud.channels:
            # a second compensation moves contact points by the radius again (a review: 28 µm RMS, exit 0)
            raise StepError("the points are contact points already: an earlier probe_radius compensated "
                            "them (the cloud has its probe_residual) — run probe_radius once")
        s, rho_b = params.side, params.radius
        from pointspro.core.profiles import profiles_of

        profiles = profiles_of(cloud)
        if profiles is not None:  # stylus profiles: the 2-D offset curve in each plane (profile.py)
            from .profile import run_profiles

            out, report = run_profiles(cloud, profiles, params, ctx, surface, check_no_fold)
            return StepResult(out, report)
        dof, note = dof_for_surface(surface, params.dof, "dof" in params.model_fields_set)
        try:
            # weighted by the points' areas when the fit takes form out (radius, conic, A_n free)
            fit, weights = fit_over_the_area(surface, cloud.xyz, dof, params.initial.as_dof(), "normal",
                                             offset=s * rho_b, max_iter=params.max_iterations,
                                             check=ctx.progress.check)
        except (StepError, DomainError) as e:
            # a ball larger than the part's radius of curvature makes the offset surface fold, which
            # the fit meets as "outside the conic's domain" (a review: 55 mm on a 50 mm sphere): say so
            try:
                check_no_fold(surface, cloud.xyz, s, rho_b)
            except DomainError:  # points beyond the conic itself: the fit's own message says more
                pass
            if isinstance(e, DomainError):
                raise
            # a flipped curvature (c's sign) makes the fit fail — "cannot separate …: fit fewer DOF" or
            # "did not converge" on the example: the centres mirrored in z fit the nominal then
            from pointspro.core.geometry.nominal_check import check_failed_fit
            from pointspro.core.profiles import with_profile_hint

            flipped = check_failed_fit(
                surface, cloud.xyz, dof, params.initial.as_dof(), params.max_iterations, ctx.progress.check,
                e, kind="normal", offset=s * rho_b)
            raise (StepError(flipped) if flipped else with_profile_hint(e)) from None
        ctx.progress.update(0.8, "compensating")
        foot, n, dist = fit.foot_point()  # warm-started from the fit's last foot radii
        e = dist - s * rho_b  # envelope residual: form error along the normal, plus noise (mm)
        # ... or it converges to a distance residual the size of the nominal's own sag (the tilts held)
        from pointspro.core.geometry.nominal_check import check_sign

        flipped = check_sign(surface, fit.surface, cloud.xyz, foot, e, dof,
                                             params.initial.as_dof(), params.max_iterations,
                                             ctx.progress.check, kind="normal", offset=s * rho_b)
        if flipped:
            raise StepError(flipped)
        exclusion, excluded = {}, None
        if params.exclude_beyond is not None:  # the pose without the outliers (core/geometry/outliers.py)
            from pointspro.core.geometry.outliers import refit_without_outliers

            first = fit
            fit, part, e, excluded, exclusion = refit_without_outliers(
                surface, cloud.xyz, dof, params.initial.as_dof(), "normal", params.exclude_beyond, fit, None, e,
                offset=s * rho_b, max_iter=params.max_iterations, check=ctx.progress.check, weights=weights)
            if fit is not first:
                foot, n, dist = fit.surface.foot_point(part)
        check_no_fold(fit.surface, foot, s, rho_b)
        side_warning = _other_side_check(surface, cloud.xyz, dof, params, e, ctx)
        report = fit.report()
        if weights is not None:  # the design parameters' fit over the area (core/geometry/posed_fit.py)
            report["fit_weights"] = FIT_WEIGHTS_NOTE
        report.update(exclusion)
        if excluded is not None:
            rows = cloud["index"][excluded] if "index" in cloud.channels else np.flatnonzero(excluded)
            report["excluded_from_pose_rows"] = [int(r) for r in rows[:50]]
        if params.normals == "refined":
            slopes, n_out = residual_slopes(foot[:, :2], e, params.neighbours)
            report["normal_outliers_set_aside"] = n_out
            n_used = refined_normals(n, slopes)
            tilt = np.linalg.norm(n_used - n, axis=1)  # chord = angle for small angles (arccos would
            # turn the rounding of a dot product of 1 into 1e-8 rad)
            report["normal_correction_rms_urad"] = float(np.sqrt(np.mean(tilt ** 2)) * 1e6)
            report["normal_correction_max_urad"] = float(tilt.max() * 1e6)
        else:
            n_used = n
        # contact = centre − s·ρ·n̂, with n̂ taken from the part frame to the measuring frame
        contact = cloud.xyz - s * rho_b * (n_used @ fit.pose.rotation.T)
        from pointspro.core.metrics.area_weights import area_weights, rms_about_zero, weighting_words

        # the distance residual's RMS over the area (docs/conventions.md, Summary figures): the foot
        # points' areas in the part frame (None on an even sampling: the plain mean); about zero, as
        # before, on any sampling: √(Σ w e² / Σ w)
        area = weights if weights is not None else area_weights(foot[:, 0], foot[:, 1])
        report.update(
            probe_radius=rho_b, side=s, normals=params.normals,
            distance_residual_rms_um=rms_about_zero(e, area) * 1e3,
            distance_residual_rms_over=weighting_words(area),
            distance_residual_pv_um=float(np.ptp(e) * 1e3),
            warnings=list(fit.warnings) + ([note] if note else []) + ([side_warning] if side_warning else [])
            + report.pop("warnings", []))
        if fit.surface is not surface:
            report["surface"] = fit.surface.describe()
        ctx.log.info("probe radius %.6g mm (side %+d, %s normals); distance residual RMS %.4g µm, "
                     "PV %.4g µm", rho_b, s, params.normals, report["distance_residual_rms_um"],
                     report["distance_residual_pv_um"])
        out = cloud.replace(xyz=contact, channels={"probe_residual": e})
        return StepResult(out, report)
