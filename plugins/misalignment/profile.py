"""`misalignment` on stylus profiles (core.profiles): each profile's pose in its own plane.

A profile determines the tilt in its plane, the decentre along it and the height (and, with `radius`
and `conic` in `dof`, R and k); not the decentre across it nor the tilt about its own line, which are
held at zero — the report says so (`not_determined`). Residual = z − sag at the contact point, in the
part frame, as for clouds; the output puts each profile on its azimuth through the axis,
x = u·cos θ, y = u·sin θ. The report gives per profile the pose and R, k with their uncertainties,
PV, RMS and slope error (µrad) of the residual, and with profiles at two azimuths or more a coarse
astigmatism (core.metrics.profiles.profile_astigmatism); the figures are the residual and slope
error along each profile and their 1-D PSD.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.params.pose import dof_for_surface
from pointspro.core.profiles import NOT_DETERMINED, check_scan, place
from pointspro.core.profiles.fit import ProfileFit, initial_for, pose_record, profile_dof


def run_profiles(cloud, profiles, params, ctx, surface):
    from pointspro.core.metrics.profiles import profile_astigmatism, profile_psd, profile_slope

    dof, note = dof_for_surface(surface, params.dof, "dof" in params.model_fields_set)
    free, note2 = profile_dof(dof, surface, "dof" in params.model_fields_set)
    part = np.empty((cloud.n, 3))
    residual = np.empty(cloud.n)
    records, warnings, items, astig_items = [], [], [], []
    for k, p in enumerate(profiles):
        ctx.progress.check()
        check_scan(p, cloud.index)
        fit = ProfileFit(surface, p.s, cloud.z[p.rows], free,
                         initial_for(p.angle_deg, params.initial.as_dof()), "vertical",
                         max_iter=params.max_iterations, check=ctx.progress.check, name=p.name).fit()
        r = fit.residuals
        x, y = place(p, fit.u, np.zeros_like(fit.u))
        part[p.rows] = np.column_stack([x, y, fit.w])
        residual[p.rows] = r
        slope, window = profile_slope(fit.u, r)
        rep = fit.report()
        rec = pose_record(p, rep)
        rec.update(rms_um=float(np.sqrt(np.mean((r - r.mean()) ** 2)) * 1e3),
                   pv_um=float(np.ptp(r) * 1e3),
                   slope_rms_urad=float(np.sqrt(np.mean((slope - slope.mean()) ** 2)) * 1e6),
                   slope_max_urad=float(np.max(np.abs(slope)) * 1e6),
                   slope_window_mm=window, condition_number=fit.condition_number)
        records.append(rec)
        warnings += fit.warnings
        label = f"{p.angle_deg:g}°" if len(profiles) == 1 else f"{p.label} ({p.angle_deg:g}°)"
        items.append({"label": label, "u": fit.u, "residual": r, "slope": slope})
        # the profile's own power, R free or not: the residual plus the fitted design's departure
        au = np.abs(fit.u)
        astig_items.append((p.angle_deg, fit.u, r + fit.surface.sag_r(au) - surface.sag_r(au)))
        ctx.progress.update(0.9 * (k + 1) / len(profiles), f"profile {k + 1} of {len(profiles)}")
    report = dict(records[0]) if len(records) == 1 else {}
    report.pop("profile", None)
    report.update(profiles=records, parameters=list(free), not_determined=NOT_DETERMINED,
                  residual_rms_um=float(np.sqrt(np.mean(residual ** 2)) * 1e3),
                  residual_pv_um=float(np.ptp(residual) * 1e3),
                  warnings=warnings + [n for n in (note, note2) if n])
    astig = profile_astigmatism(astig_items) if len(profiles) > 1 else None
    if astig:
        report["astigmatism"] = astig
    ctx.log.info("%d profile(s); residual RMS %.4g µm, PV %.4g µm", len(profiles),
                 report["residual_rms_um"], report["residual_pv_um"])
    out = cloud.replace(xyz=part, channels={"residual": residual}, meta={"frame": "part"})
    from pointspro.core.figures import png_artifact, stylus_profile_figure, stylus_psd_figure

    psd = []
    for it in items:
        f, pw = profile_psd(it["u"], it["residual"])
        psd.append({"label": it["label"], "f": f, "psd": pw})
    arts = {"profile.png": png_artifact(stylus_profile_figure, items),
            "profile_psd.png": png_artifact(stylus_psd_figure, psd),
            "profile_psd.csv": _psd_csv(psd)}
    return out, report, arts


def _psd_csv(psd) -> str:
    """The 1-D PSD of each profile: ``profile,f [1/mm],psd [mm^3]``."""
    lines = ["profile,f [1/mm],psd [mm^3]"]
    for it in psd:
        lab = str(it["label"]).replace(",", " ").replace("°", " deg")
        lines += [f"{lab},{f!r},{p!r}" for f, p in zip(it["f"].tolist(), it["psd"].tolist())]
    return "\n".join(lines) + "\n"
