"""The pose fitted without the points the first fit shows as outliers (misalignment, probe_radius).

A least-squares pose follows a few wild points: on a near-spherical part along the tilt/decentre
valley, where a small change of the sum of squares moves the pose far. The example's five spikes of
12–25 µm among 4,640 points moved dy by 92 µm and put 44 nm of false coma into the form error.

``refit_without_outliers`` leaves out of the fit the points beyond ``k`` robust σ of the first fit's
residual, |r − median(r)| > k · 1.4826 · MAD(r), fits again from the first pose, and repeats until that
set no longer changes (at most ROUNDS rounds). The points stay in the cloud: every point's part-frame
coordinates and residual are those at the final pose. At most MAX_EXCLUDED_SHARE of the points are
left out — beyond that the "outliers" are the form itself (a turned-down edge, a zone) and the pose is
fitted on every point, with a warning.
"""
from __future__ import annotations

import numpy as np

from .posed_fit import POSE_DOF, PosedSurfaceFit

MAD_TO_SIGMA = 1.482602218505602
MAX_EXCLUDED_SHARE = 0.02
ROUNDS = 4


def residuals_at(fit, xyz, kind: str, offset: float):
    """(part-frame points, residual) of all ``xyz`` at ``fit``'s pose and surface: the vertical
    residual z − sag(x, y), or the normal one (distance to the surface − offset), by blocks."""
    pose = fit.pose  # every DOF, the held ones at their values
    vals = {"alpha": pose.alpha_deg, "beta": pose.beta_deg, "dx": pose.dx, "dy": pose.dy, "dz": pose.dz}
    part = PosedSurfaceFit(fit.surface, xyz, ["dz"]).part_points(vals)
    if kind == "normal":
        _, _, dist = fit.surface.foot_point(part)
        return part, dist - offset
    r = np.empty(len(part))
    for s in range(0, len(part), 1 << 16):
        p = part[s:s + (1 << 16)]
        np.subtract(p[:, 2], fit.surface.sag(p[:, 0], p[:, 1]), out=r[s:s + len(p)])
    return part, r


#: the outliers' first-order pull on every pose parameter below this many standard uncertainties:
#: no refit (five spikes among 10⁶ points pull by ~0.01 u; a refit would cost 0.5–0.8 s there)
PULL_TOLERANCE = 0.05


def pull_on_pose(surface, xyz_out, fit, kind: str, offset: float, residual_all) -> float | None:
    """max_j |Δx_j| / u_j of leaving the points ``xyz_out`` out of the least-squares fit ``fit``, to
    first order: Δx = (JᵀJ)⁻¹ J_outᵀ r_out with (JᵀJ)⁻¹ = cov / s² (the fit's covariance and residual
    variance). None when the fit has design DOF (radius, conic: other units) or no finite covariance."""
    names = list(fit.names)
    if any(nm not in POSE_DOF for nm in names):
        return None
    key = {"alpha": "alpha_deg", "beta": "beta_deg"}
    u = np.array([fit.uncertainty[nm] for nm in names])
    if not (np.all(np.isfinite(u)) and np.all(u > 0)):
        return None
    cov = np.asarray(fit.correlation) * np.outer(u, u)
    n, p = len(residual_all), len(names)
    s2 = float(residual_all @ residual_all) / max(n - p, 1)
    pose = fit.pose
    x = np.array([getattr(pose, key.get(nm, nm)) for nm in names])
    probe = PosedSurfaceFit(fit.surface, xyz_out, names, {}, kind, offset=offset)
    r, J = probe.model(x, True)
    dx = cov @ (J.T @ r) / s2
    return float(np.max(np.abs(dx) / u))


def refit_without_outliers(surface, xyz, dof, initial: dict, kind: str, k: float, fit, part, residual, *,
                           offset: float = 0.0, max_iter: int = 100, check=None, weights=None):
    """(fit, part, residual, excluded mask or None, report entries) — module doc. ``fit``, ``part``
    and ``residual``: the fit on every point, its part-frame points (or None) and its residual;
    ``initial``: the recipe's initial/held pose; ``kind``: "vertical" or "normal". When the points
    beyond the threshold pull the pose by less than PULL_TOLERANCE standard uncertainties
    (``pull_on_pose``) the first fit stands."""
    n = len(xyz)
    excluded = np.zeros(n, dtype=bool)
    sigma = 0.0
    first = True
    for _ in range(ROUNDS):
        med = float(np.median(residual))
        sigma = MAD_TO_SIGMA * float(np.median(np.abs(residual - med)))
        if not sigma > 0:
            break
        beyond = np.abs(residual - med) > k * sigma
        if np.array_equal(beyond, excluded):
            break
        if beyond.sum() > MAX_EXCLUDED_SHARE * n or n - beyond.sum() <= 2 * len(dof):
            warning = (f"{int(beyond.sum())} points ({beyond.mean():.1%}) lie beyond {k:g} robust σ "
                       f"({k * sigma * 1e3:.3g} µm) of the residual — more than {MAX_EXCLUDED_SHARE:.0%}: "
                       "the pose is fitted on every point (a form error much larger than the noise, or "
                       "many outliers: run knn_denoise, then this step again)")
            if excluded.any():  # back to the fit on all points
                fit = PosedSurfaceFit(surface, xyz, dof, initial, kind, offset=offset, max_iter=max_iter,
                                      check=check, weights=weights).fit()
                part, residual = residuals_at(fit, xyz, kind, offset)
            return fit, part, residual, None, {"excluded_from_pose": 0, "warnings": [warning]}
        if first:
            first = False
            pull = pull_on_pose(surface, xyz[beyond], fit, kind, offset, residual) if beyond.any() else 0.0
            if pull is not None and pull < PULL_TOLERANCE:
                return fit, part, residual, None, {
                    "excluded_from_pose": 0,
                    "excluded_from_pose_rule": (f"{int(beyond.sum())} points lie beyond {k:g} × 1.4826·MAD = "
                                                f"{k * sigma * 1e3:.4g} µm; leaving them out would move the "
                                                f"pose by {pull:.2g} standard uncertainties at most: kept")}
        excluded = beyond
        if check is not None:
            check()
        start = {**initial, **{nm: fit.values[nm] for nm in fit.names if nm in POSE_DOF}}
        fit = PosedSurfaceFit(surface, xyz[~excluded], dof, start, kind, offset=offset, max_iter=max_iter,
                              check=check, weights=None if weights is None else weights[~excluded]).fit()
        part, residual = residuals_at(fit, xyz, kind, offset)
    if not excluded.any():
        return fit, part, residual, None, {"excluded_from_pose": 0}
    return fit, part, residual, excluded, {
        "excluded_from_pose": int(excluded.sum()),
        "excluded_from_pose_rule": (f"|residual − median| > {k:g} × 1.4826·MAD = {k * sigma * 1e3:.4g} µm "
                                    "(still in the cloud, residual at the pose of the others)")}
