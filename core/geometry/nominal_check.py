"""Is the nominal the part's? A residual that is the nominal's own shape is refused (the check
`misalignment` and `probe_radius` share).

A real part's form error is µm against the mm of its sag. A wrong nominal gives a "form error" the size
of the sag itself, and every step after the fit (Zernike, map, tolerance) then reports it with exit 0: a
review ran the example asphere with c, A4, A6 negated (a concave/convex mix-up, the commonest
drawing-reading mistake) and got "residual RMS 41.98 mm, PV 139.8 mm", map.csv and all; the batch's
sanity check (core/pipeline.py) only refuses a residual above the input's whole height range (72 mm).

The check compares, over the points in the part frame, the residual's RMS with the RMS of the fitted
nominal's sag variation — both less their best-fit plane, so that a tilt held by `dof` is not counted
against the nominal, and the ratio is about the surface's shape. Measured on the example (its 4,680
contact points after probe_radius, sag variation 21.0 mm RMS; 5-DOF fits unless said):

    nominal                        residual RMS      ratio       points fitted to −sag
    the part's                      0.853 µm         4.1e-5      42.0 mm
    c, A negated (the review's)     42.0 mm          2.0         0.853 µm
    c negated, k 0, no A            42.2 mm          2.0         0.185 mm
    R × 1.5                         6.99 mm          0.50        35.0 mm
    R × 3 (dof dx, dy, dz)          14.0 mm          2.0         28.0 mm
    R × 1.1                         1.91 mm          0.10        40.1 mm  (passes: see RATIO_LIMIT)
    k 0 instead of −0.98            0.220 mm         0.010       42.2 mm  (passes)

When the share is large the likely cause is tested: the same fit on the points mirrored in z (the fit
of the nominal turned upside down, −sag: the pose family is closed under the mirror, α → −α, β → −β,
dz → −dz) — when it fits far better, the sign of the curvature is wrong; else the points do not match
the nominal (and when their heights barely vary at all, they are probably deviations already).
A fit to the nominal that fails outright (no convergence) is tried mirrored too, so that a flipped
sign the fit cannot even start from is named as such rather than as a convergence problem.

probe_radius, which meets the nominal first, asks the same of its normal-distance fit of probe-ball
centres (check_sign, check_failed_fit with kind "normal"): the mirrored centres are fitted at −s·ρ
(the ball's side turns with them), which is exact — the example flipped leaves 0.839 µm, the correct
fit's own; c alone negated 68.9 µm, c negated without k and A 0.182 mm (ratios 4e-5 to 0.009). Their
vertical fit, as on contact points, would leave the ball's own 1–1.6 × ρ/R of the sag variation: 0.0013
to 0.0075 on the example, but 0.27–0.58 on small lenses probed with a ball a fifth to a third of R (R
10 mm ball 2.5: 0.40), above RATIO_LIMIT. The correct nominals' mirrored fits leave 2–5.
"""
from __future__ import annotations

import re

import numpy as np

from pointspro.core.errors import DomainError, StepError

#: refuse when the residual's RMS exceeds this share of the nominal's own sag variation (RMS, both less
#: a plane). A wrong sign gives 2, a radius 1.5× or 3× wrong 0.5 and 2; the example part 4.1e-5, and a
#: rough ground part's 20–50 µm form error against 1–20 mm of sag variation 0.0004–0.042 (measured: the
#: paper-002 aspheres, R 50 and R −20 lenses, Q-con, freeform) — the limit is six times above the worst
#: of those, 6,000 times above the example. It passes a radius 10 % wrong (0.10, 1.9 mm of "form
#: error" in plain sight in the summary) rather than come near legitimate parts. Probe-centre points
#: left uncompensated give 1–1.6 × ρ/R (ball radius over vertex radius; measured on spheres R ±10 and
#: 50 mm): 0.0013 on the example; a quarter only for a ball a sixth of the radius or more (R 10 mm,
#: ball 2.5 mm: 0.40), where the residual is no form error either — the message then names probe_radius.
RATIO_LIMIT = 0.25
#: ... and only when the residual's RMS is above this (mm): on a near-flat nominal the sag variation
#: tends to zero and the ratio means nothing — R 10 m over 100 mm has 36 µm RMS of sag variation, a
#: window of R 50 m 7 µm, and a rough part 20–50 µm of form error (measured: 50 µm passes at 0.1 mm).
#: No ground or polished optic has a form error of 0.1 mm RMS; a generated blank might, and passes
#: unless its residual is also a quarter of its nominal's sag variation.
RESIDUAL_FLOOR_MM = 0.1
#: the wrong sign is named from a residual of this RMS (mm) — lower, as the mirrored fit is evidence
#: of its own (below): a flip is found down to a sag variation of 25 µm RMS (its residual is twice
#: that). Not lower: on a near-flat nominal a part whose real power is opposite to the design's (a
#: bad part, not a bad nominal) fits the mirror too, and must be reported, not refused.
SIGN_FLOOR_MM = 0.05
#: the mirrored fit's residual must be at most this share of the fit's own to blame the sign (a flip
#: gives ~1e-5 on the example; with form error σ and sag variation s the flip is √(σ² + 4s²) against
#: σ, and the mirrored fit must also pass RATIO_LIMIT itself, σ ≤ s/4, so a true flip gives ≤ 1/8)
MIRROR_GAIN = 0.25
#: the check's figures from every k-th point, ~this many (a ratio to 1 %; the pose fit's own start
#: takes its median height from 20,000 points alike): no full-length temporary on 10⁶ points
SAMPLE = 20_000
MIRROR = np.array([1.0, 1.0, -1.0])


def _less_plane_rms(x, y, *values) -> list[float]:
    """RMS of each of ``values`` less its least-squares plane a + b x + c y (mm), in one solve."""
    V = np.column_stack(values)
    if len(x) < 3:
        return [float(v) for v in np.sqrt(np.mean((V - V.mean(axis=0)) ** 2, axis=0))]
    A = np.column_stack([np.ones_like(x), x - x.mean(), y - y.mean()])
    coef, *_ = np.linalg.lstsq(A, V, rcond=None)
    return [float(v) for v in np.sqrt(np.mean((V - A @ coef) ** 2, axis=0))]


def _figures(surface, part, residual, rows=slice(None)):
    """(residual RMS, sag variation RMS), both less a plane, over ``part[rows]`` (mm); None when the
    sag is not defined there."""
    x, y = part[rows, 0], part[rows, 1]
    try:
        sag = np.asarray(surface.sag(x, y), dtype=np.float64)
    except (DomainError, ValueError):
        return None
    if not np.all(np.isfinite(sag)):
        return None
    res, var = _less_plane_rms(x, y, residual[rows], sag)
    return res, var


def _mirrored_fit(nominal, q, dof, initial, max_iter, check, kind="vertical", offset=0.0):
    """(residual RMS, sag variation RMS) of the pose fit of the points mirrored in z — the fit of the
    nominal turned upside down — or None when that fit fails. ``kind``, ``offset``: those of the fit to
    the nominal; "normal" with offset s·ρ is probe_radius's fit of probe-ball centres, whose mirror
    images lie at −s·ρ from the nominal when its sign is wrong (the ball's side turns with the part):
    the mirrored fit's figures are then those of its distance residual at its foot points, as exact as
    on contact points."""
    from pointspro.core.geometry.posed_fit import PosedSurfaceFit

    init = {k: (-v if k in ("alpha", "beta", "dz") else v) for k, v in initial.items()}
    mirrored = q * MIRROR
    # on a sphere (or nearly) a tilt is a decenter and the 5-DOF fit may refuse as ill-posed: the same
    # residual then comes from the fit with the tilts held (a flipped R 50 mm lens: refused, then found)
    tries = [list(dof)]
    held = [d for d in dof if d not in ("alpha", "beta")]
    if len(held) < len(dof) and held:
        tries.append(held)
    for free in tries:
        try:
            fit = PosedSurfaceFit(nominal, mirrored, free, init, kind, offset=-offset, max_iter=max_iter,
                                  check=check).fit()
            if kind == "normal":
                foot, _, dist = fit.foot_point()
                return _figures(fit.surface, foot, dist + offset)
        except (StepError, DomainError, np.linalg.LinAlgError, FloatingPointError, ValueError):
            continue
        return _figures(fit.surface, fit.part, fit.residuals)
    return None


def _is_flat(surface) -> bool:
    from pointspro.core.metrics.pupil import is_flat

    return is_flat(surface)


def _sign_message(res, mirrored, sag, failed: str | None = None) -> str:
    from pointspro.core.units import format_length as L

    if failed:
        head = (f"the pose fit to the nominal failed ({failed}), but the points fit the nominal turned "
                f"upside down (the opposite curvature) to {L(mirrored)} RMS")
    else:
        head = (f"the points fit the nominal turned upside down (the opposite curvature) far better than "
                f"the nominal: residual {L(mirrored)} RMS against {L(res)}")
    return (f"{head}, where the nominal's sag varies by {L(sag)} RMS over the points — is the sign of "
            "`surface.c` (or `R`) right? (concave vs convex: with c > 0 the surface rises toward its "
            "edge, concave seen from +z; the aspheric coefficients change sign with it)")


def _mismatch_message(res, sag, part, residual) -> str:
    from pointspro.core.units import format_length as L

    msg = (f"the points do not match the nominal `surface`: the residual after the pose fit has RMS "
           f"{L(res)} against the nominal's own sag variation of {L(sag)} RMS over the points (both less "
           f"a plane; a form error is a small fraction of it) — check `surface` (c or R, k, the aspheric "
           "coefficients and their units) against the drawing, that the file is of this part, and that "
           "probe-ball centres are compensated first (probe_radius before misalignment)")
    z = part[:, 2]
    span_z = float(np.ptp(z)) if len(z) else 0.0
    span_sag = float(np.ptp(z - residual)) if len(z) else 0.0  # the sag at the points
    if span_z < 0.05 * span_sag:
        msg += (f"; the heights vary by only {L(span_z)} where the nominal's sag varies by {L(span_sag)}: "
                "if they are deviations from the nominal (a form-error map) already, leave misalignment out")
    return msg


def _large_share(fitted, part, residual):
    """(residual RMS, sag variation RMS) over every point (less a plane, mm) when the residual is a
    large share of the sag variation (SIGN_FLOOR_MM and RATIO_LIMIT, tested on ≤ SAMPLE points); else
    None."""
    n = len(residual)
    rows = slice(None, None, max(1, n // SAMPLE))
    figs = _figures(fitted, part, residual, rows)
    if figs is None:
        return None
    res, sag = figs
    if not (res > SIGN_FLOOR_MM and res > RATIO_LIMIT * sag):
        return None
    full = _figures(fitted, part, residual)  # the message's figures over every point
    return full if full is not None else figs


def _mirror_verdict(nominal, q, dof, initial, max_iter, check, res, sag, kind="vertical", offset=0.0):
    """The message naming the sign when the mirrored fit passes RATIO_LIMIT itself and fits
    MIRROR_GAIN better than the fit's residual ``res``; else None."""
    mirrored = _mirrored_fit(nominal, q, dof, initial, max_iter, check, kind, offset)
    if mirrored is not None:
        m_res, m_sag = mirrored
        if m_res <= RATIO_LIMIT * m_sag and m_res <= MIRROR_GAIN * res:
            return _sign_message(res, m_res, sag)
    return None


def check_fit(nominal, fitted, q, part, residual, dof, initial, max_iter, check) -> None:
    """StepError when the residual ``residual`` at part-frame points ``part`` (the pose fit of points
    ``q`` to ``nominal``; ``fitted``: the fit's surface, the nominal with any design DOF fitted) is no
    form error but a wrong nominal — module doc. Passes quietly otherwise."""
    if len(residual) < 4 or _is_flat(nominal) or _is_flat(fitted):
        return
    figs = _large_share(fitted, part, residual)
    if figs is None:
        return
    res, sag = figs
    flipped = _mirror_verdict(nominal, q, dof, initial, max_iter, check, res, sag)
    if flipped:
        raise StepError(flipped)
    if res > RESIDUAL_FLOOR_MM and res > RATIO_LIMIT * sag:
        raise StepError(_mismatch_message(res, sag, part, residual))


def check_sign(nominal, fitted, q, part, residual, dof, initial, max_iter, check, kind="vertical",
               offset=0.0) -> str | None:
    """check_fit's test of the curvature's sign alone: the message naming it, or None (no verdict on
    anything else). probe_radius: ``kind`` "normal" and ``offset`` s·ρ (its fit's), ``part`` the foot
    points and ``residual`` the distance residual less s·ρ (_mirrored_fit)."""
    if len(residual) < 4 or _is_flat(nominal) or _is_flat(fitted):
        return None
    figs = _large_share(fitted, part, residual)
    if figs is None:
        return None
    return _mirror_verdict(nominal, q, dof, initial, max_iter, check, *figs, kind=kind, offset=offset)


def check_failed_fit(nominal, q, dof, initial, max_iter, check, error: StepError, kind="vertical",
                     offset=0.0) -> str | None:
    """After the pose fit to ``nominal`` failed with ``error``: the error naming the curvature's sign
    when the points mirrored in z fit well (their residual within RATIO_LIMIT of the sag variation,
    and that sag variation large enough for the flip to matter); else None (the caller re-raises).
    ``kind``, ``offset``: those of the failed fit (probe_radius: "normal", s·ρ; _mirrored_fit)."""
    if _is_flat(nominal) or len(q) < 4:
        return None
    mirrored = _mirrored_fit(nominal, q, dof, initial, max_iter, check, kind, offset)
    if mirrored is None:
        return None
    m_res, m_sag = mirrored
    if 2 * m_sag > SIGN_FLOOR_MM and m_res <= RATIO_LIMIT * m_sag:
        failed = re.split(r"[:(]", str(error))[0].strip() or "no solution"
        return _sign_message(None, m_res, m_sag, failed=failed)
    return None
