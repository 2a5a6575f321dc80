"""The quantities of ISO 10110-5:2015 as ISO 14999-4:2015 defines them, computed on the final
cloud's form deviation (docs/tolerance.md, "Quantities"). Every value is in µm of surface height, in
the sign of the residual (``z − sag``, docs/conventions.md: positive = material above the nominal).

The form deviation w (ISO 14999-4:2015, "surface form deviation") is the ``residual`` channel over the
points the recipe kept (its aperture applied), or — a height map with no nominal or a flat — the
heights with their least-squares plane removed, as ``summary.rms_um`` (core.pipeline.summarize).

One least-squares fit of the Fringe Zernike terms Z1…Z37 (every azimuthal order through radial order
10 and the rotationally symmetric terms m = 0 through n = 12 — Z37 is (12, 0), fit_terms; fewer on
few points) over the test area (the disk about the pupil centre of core.metrics.pupil that holds
every point) splits w into

    piston + tilt (Z1–Z3) + power P (Z4) + rotationally symmetric S (m = 0, n ≥ 4) + the rest.

Why one joint fit: the Zernike terms are orthogonal over the disk, so the coefficient of Z4 in a full
expansion *is* the area-weighted least-squares best-fit sphere (paraboloid) of ISO 14999-4; fitting
all 37 together recovers it whatever the sampling (a star or spiral scan, denser at the centre, would
pull a 4-term fit towards its centre). That holds over a full disk; where the points sample their
area evenly (uniform_sampling: a pixel map, a raster) the best-fit plane and sphere are the plain
least-squares fits over the points instead, the area's shape whatever it is (a rectangular map's
circumscribed disk has corners without points, where the joint fit's higher terms trade with tilt
and power). Why a radial polynomial for S and not radial bins: a fit
averages the noise over all points, needs no bin width, and leaves no empty bins between the spokes
of a star or on an annulus; m = 0 up to n = 12 (6th degree in ρ²) follows an edge roll-off down to
about R/6 wide. Rotationally symmetric structure finer than that stays in RMSa (stated).

    sag_um   A  sagitta deviation: the power term's departure at the test area's edge from its
                centre, P(ρ = 1) − P(0) = 2√3·c₄ (signed: > 0 when the edge lies higher relative to
                the centre than on the nominal, i.e. the part is more concave, seen from +z); the
                tolerance bounds |A| (ISO 14999-4:2015, the sagitta of the best-fit sphere's
                departure over the test area)
    irr_um   B  irregularity: PV of w − piston − tilt − P over the points (ISO 14999-4:2015)
    rsi_um   C  rotationally symmetric irregularity: PV of S(ρ) over the radii the points span
                (ISO 14999-4:2015)
    rmst_um     RMSt: RMS of w − piston − tilt (ISO 14999-4:2015)
    rmsi_um     RMSi: RMS of the irregularity w − piston − tilt − P
    rmsa_um     RMSa: RMS of the irregularity minus S (the non-rotationally symmetric part)

RMS values are about the mean (a remaining piston does not count).
"""
from __future__ import annotations

import numpy as np

from ..errors import PointsProError
from ..metrics.area_weights import area_weights, weighted_rms
from ..metrics.sampling import plain_best_fits

#: the ISO quantities (key → how the notation names it)
ISO_KEYS = {"sag_um": "sagitta deviation A", "irr_um": "irregularity B",
            "rsi_um": "rotationally symmetric irregularity C", "rmst_um": "RMSt", "rmsi_um": "RMSi",
            "rmsa_um": "RMSa"}
#: the summary's figures (core.pipeline.summarize), which a plain limit may name too
SUMMARY_KEYS = {"rms_um": "RMS", "pv_um": "PV", "pvr_um": "PVr", "slope_rms_urad": "slope RMS"}
#: those that need an area (a stylus profile has none)
AREAL = frozenset(ISO_KEYS) | {"pvr_um", "slope_rms_urad"}
#: how the Monte Carlo removes each quantity's noise bias (core.uncertainty.estimate.kind_of)
KINDS = {"sag_um": "linear", "irr_um": "extreme", "rsi_um": "smooth", "rmst_um": "quadratic",
         "rmsi_um": "quadratic", "rmsa_um": "quadratic"}

#: Fringe terms of the joint fit, most first; the largest with ≥ 4 points a term is used. Never fewer
#: than 9 (through Z9, primary spherical): with Z1–Z4 alone (16–35 points) C had no term to come from
#: (0 µm, "conforms") and power took the spherical aberration into A (30 points of pure SA read
#: A 0.07 µm, C 0)
FIT_TERM_COUNTS = (37, 25, 16, 9)
#: points on which S(ρ) is evaluated for C
RADIAL_SAMPLES = 513


def form_deviation(cloud, surface):
    """(x, y, w, what) of a cloud: w the residual (mm), or the heights less their plane on a height
    map with no nominal or a flat; PointsProError when neither (module doc)."""
    from ..metrics.pupil import is_flat
    from ..pipeline import remove_piston_tilt

    x, y = cloud.x, cloud.y
    if "residual" in cloud.channels:
        return x, y, np.asarray(cloud["residual"], dtype=np.float64), "residual"
    if is_flat(surface) and cloud.n >= 3:
        return x, y, remove_piston_tilt(x, y, cloud.z), "heights, piston and tilt removed"
    raise PointsProError("tolerance: no form deviation to judge: the steps made no residual and the nominal "
                         "surface is not a flat (add misalignment or register)")


def iso_quantities(x, y, w, center, keys=None, weights=None) -> dict[str, float]:
    """The ISO 10110-5 quantities (µm) of form deviation ``w`` (mm) at points (x, y) (mm) about
    ``center`` (module doc); ``keys`` limits which are returned (all by default). ``weights``: the
    points' areas for the RMS figures (core.metrics.area_weights; None: an even sampling)."""
    from ..metrics import zernike as zk

    x, y, w = (np.asarray(a, dtype=np.float64) for a in (x, y, w))
    keys = list(ISO_KEYS) if keys is None else [k for k in keys if k in ISO_KEYS]
    n = w.size
    count = next((c for c in FIT_TERM_COUNTS if n >= 4 * c), None)
    if count is None:
        raise PointsProError(f"tolerance: {n} points are too few for the sagitta and irregularity (at least "
                             f"{4 * FIT_TERM_COUNTS[-1]})")
    cx, cy = float(center[0]), float(center[1])
    rr = np.hypot(x - cx, y - cy)
    R = float(rr.max())
    if not R > 0:
        raise PointsProError("tolerance: the points have no extent (one position)")
    pairs = fit_terms(count)
    A = zk.design_matrix(x, y, R, pairs, "rms", (cx, cy))
    coef = _solve(A, w)
    idx = {p: i for i, p in enumerate(pairs)}
    pt = [idx[(0, 0)], idx[(1, 1)], idx[(1, -1)]]
    ip = idx[(2, 0)]
    rs = [idx[p] for p in pairs if p[1] == 0 and p[0] >= 4]
    if plain_best_fits(x, y, (cx, cy), R):  # core.metrics.sampling
        # every point stands for the same area: the area-weighted best-fit plane and sphere of ISO
        # 14999-4 are the plain least-squares fits over the points, whatever the test area's shape.
        # The joint fit's Z1–Z4 equal them only over a full disk: on a rectangular map (the disk about
        # it holds corners without points) higher terms trade with tilt and power — a review's square
        # map read A 0.139 µm where its best-fit sphere gives −0.009, RMSt 0.060 µm beside RMS 0.035
        plane = _solve(A[:, pt], w)
        sphere = _solve(A[:, pt + [ip]], w)
        d_t = w - A[:, pt] @ plane
        coef = coef.copy()
        coef[ip] = sphere[-1]
        irr = w - A[:, pt + [ip]] @ sphere
        if rs:  # S: the least-squares m = 0 part of that irregularity (RMSa ≤ RMSi by construction;
            # the joint fit's S beside this sphere read RMSa 8.7 nm against RMSi 6.8 on a MetroPro map)
            coef[rs] = _solve(A[:, rs], irr - irr.mean())
    else:
        d_t = w - A[:, pt] @ coef[pt]
        irr = d_t - A[:, ip] * coef[ip]
    out = {}
    if "sag_um" in keys:
        z4 = zk.zernike(2, 0, np.array([0.0, 1.0]), 0.0)
        out["sag_um"] = float(coef[ip] * (z4[1] - z4[0])) * 1e3
    if "irr_um" in keys:
        out["irr_um"] = float(np.ptp(irr)) * 1e3
    if "rmst_um" in keys:
        out["rmst_um"] = weighted_rms(d_t, weights) * 1e3
    if "rmsi_um" in keys:
        out["rmsi_um"] = weighted_rms(irr, weights) * 1e3
    if "rsi_um" in keys:
        rho = np.linspace(float(rr.min()) / R, 1.0, RADIAL_SAMPLES)
        s = np.zeros_like(rho)
        for j in rs:
            nn, _ = pairs[j]
            s += coef[j] * zk.zernike(nn, 0, rho, 0.0)
        out["rsi_um"] = float(np.ptp(s)) * 1e3
    if "rmsa_um" in keys:
        out["rmsa_um"] = weighted_rms(irr - A[:, rs] @ coef[rs] if rs else irr, weights) * 1e3
    return out


def fit_terms(count: int) -> list[tuple[int, int]]:
    """The (n, m) pairs of the Fringe terms Z1…Z``count``: Z37 is the 12th-order spherical term (12, 0)
    of the classical Fringe set (ISO 14999-4's "m = 0 through n = 12"), not the (6, 6) that the
    Fringe formula continues with (core.metrics.zernike's ordering beyond Z36) — a review: C read
    83 nm for a true 107 nm with 5 nm of Z37 in the form."""
    from ..metrics import zernike as zk

    pairs = zk.terms(min(count, 36), "fringe")
    return pairs + [(12, 0)] if count >= 37 else pairs


def _solve(A, w):
    """Least squares A·c ≈ w: by the normal equations (scaled) when they are well conditioned — a
    centred disk: cond ≈ 1–10, the Monte Carlo calls this on every sample — else by SVD (lstsq)."""
    G = A.T @ A
    s = np.sqrt(np.diag(G))
    s[s == 0] = 1.0
    Gs = G / np.outer(s, s)
    lam = np.linalg.eigvalsh(Gs)
    if lam[0] > 0 and lam[-1] / lam[0] < 1e6:  # cond(A)² < 1e6: ≤ 1e-10 relative lost
        return np.linalg.solve(Gs, (A.T @ w) / s) / s
    return np.linalg.lstsq(A, w, rcond=None)[0]


def summary_quantities(x, y, w, surface, keys, centre=None, weights=None) -> dict[str, float]:
    """The summary's figures named in ``keys``, computed as core.pipeline.summarize does (``centre``:
    the pupil centre the recipe gives, core.metrics.pupil.recipe_centre; ``weights``: the points'
    areas, core.metrics.area_weights)."""
    from ..metrics.form import pvr, slope_rms_urad
    from ..metrics.pupil import pupil_of

    out = {}
    if "rms_um" in keys:
        out["rms_um"] = weighted_rms(w, weights) * 1e3
    if "pv_um" in keys:
        out["pv_um"] = float(np.ptp(w)) * 1e3
    if "pvr_um" in keys:
        pupil = pupil_of(x, y, surface, centre)
        p = pvr(x, y, w, pupil.radius, center=pupil.center)
        if p is not None:  # else not computed on these points (the verdict says so)
            out["pvr_um"] = p * 1e3
    if "slope_rms_urad" in keys:
        s = slope_rms_urad(x, y, w, weights=weights)
        if s is not None:
            out["slope_rms_urad"] = s
    return out


def compute(cloud, surface, keys, centre=None) -> dict[str, float]:
    """The quantities ``keys`` of the final cloud (µm; slope in µrad), pupil-based ones about
    ``centre`` when the recipe gives one (core.metrics.pupil.recipe_centre)."""
    from ..metrics.pupil import pupil_of
    from ..profiles import is_profile

    keys = list(keys)
    if not cloud.n:
        raise PointsProError("tolerance: no points are left to judge (the steps removed them all)")
    x, y, w, _ = form_deviation(cloud, surface)
    areal = [k for k in keys if k in AREAL]
    if areal and _is_profile(cloud, is_profile):
        raise PointsProError(f"tolerance: {', '.join(ISO_KEYS.get(k, k) for k in areal)} need an area; a "
                             "stylus profile has none (a profile's limits: rms_um, pv_um)")
    # the RMS figures over the area, as the summary's (a stylus profile has none: its points' mean)
    weights = None if _is_profile(cloud, is_profile) else area_weights(x, y)
    out = summary_quantities(x, y, w, surface, keys, centre, weights)
    iso = [k for k in keys if k in ISO_KEYS]
    if iso:
        c = pupil_of(x, y, surface, centre).center
        out.update(iso_quantities(x, y, w, c, iso, weights))
    return out


def _is_profile(cloud, probe) -> bool:
    try:
        return bool(probe(cloud))
    except PointsProError:
        return False
