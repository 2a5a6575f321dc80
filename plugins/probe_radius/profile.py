"""`probe_radius` on stylus profiles: the 2-D offset curve in each profile's plane (core.profiles).

The tip centres of a profile lie at exactly the tip radius ρ from the part's meridian, along its
in-plane normal: centre = contact + s·ρ·n̂. The meridian posed in the profile's plane (tilt in the
plane, decentre along it, height; optionally R, k, A_n) is fitted to the centres by the exact normal
distance (core/profiles/fit.py), then each centre moves by −s·ρ·n̂, n̂ the meridian's normal at its
foot point, refined from the data's own slope along the profile as for clouds (normals.py: local line
fits with the noise shrinkage; across the line there is nothing to refine). Each profile is fitted on
its own; points stay in the measuring frame, across-coordinates untouched.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.params.pose import dof_for_surface
from pointspro.core.profiles import NOT_DETERMINED, check_scan, place
from pointspro.core.profiles.fit import ProfileFit, initial_for, pose_record, profile_dof

from .normals import refined_normals, residual_slopes


def run_profiles(cloud, profiles, params, ctx, surface, check_no_fold):
    s, rho = params.side, params.radius
    dof, note = dof_for_surface(surface, params.dof, "dof" in params.model_fields_set)
    free, note2 = profile_dof(dof, surface, "dof" in params.model_fields_set)
    contact = np.array(cloud.xyz)
    e_all = np.empty(cloud.n)
    records, warnings, corr_rms, corr_max = [], [], [], []
    for k, p in enumerate(profiles):
        ctx.progress.check()
        check_scan(p, cloud.index)
        z = cloud.z[p.rows]
        fit = ProfileFit(surface, p.s, z, free, initial_for(p.angle_deg, params.initial.as_dof()),
                         "normal", offset=s * rho, max_iter=params.max_iterations,
                         check=ctx.progress.check, name=p.name).fit()
        foot, n, dist = fit.surface.foot_point(np.column_stack([fit.u, np.zeros_like(fit.u), fit.w]))
        check_no_fold(fit.surface, foot, s, rho)
        e = dist - s * rho
        if params.normals == "refined":
            xy = np.column_stack([foot[:, 0], np.zeros(len(foot))])
            slopes, _ = residual_slopes(xy, e, params.neighbours)
            n_used = refined_normals(n, slopes)
            tilt = np.linalg.norm(n_used - n, axis=1)
            corr_rms.append(np.mean(tilt ** 2))
            corr_max.append(tilt.max())
        else:
            n_used = n
        ns, nz = fit.rotate(n_used[:, 0], n_used[:, 2])
        x, y = place(p, p.s - s * rho * ns)
        contact[p.rows] = np.column_stack([x, y, z - s * rho * nz])
        e_all[p.rows] = e
        rep = fit.report()
        rec = pose_record(p, rep)
        rec["distance_residual_rms_um"] = float(np.sqrt(np.mean(e ** 2)) * 1e3)
        records.append(rec)
        warnings += fit.warnings
        ctx.progress.update(0.9 * (k + 1) / len(profiles), f"profile {k + 1} of {len(profiles)}")
    report = dict(records[0]) if len(records) == 1 else {}
    report.pop("profile", None)
    report.update(
        profiles=records, parameters=list(free), not_determined=NOT_DETERMINED,
        probe_radius=rho, side=s, normals=params.normals,
        distance_residual_rms_um=float(np.sqrt(np.mean(e_all ** 2)) * 1e3),
        distance_residual_pv_um=float(np.ptp(e_all) * 1e3),
        warnings=warnings + [n for n in (note, note2) if n])
    if corr_rms:
        report["normal_correction_rms_urad"] = float(np.sqrt(np.mean(corr_rms)) * 1e6)
        report["normal_correction_max_urad"] = float(np.max(corr_max) * 1e6)
    ctx.log.info("probe radius %.6g mm on %d profile(s); distance residual RMS %.4g µm", rho,
                 len(profiles), report["distance_residual_rms_um"])
    return cloud.replace(xyz=contact, channels={"probe_residual": e_all}), report
