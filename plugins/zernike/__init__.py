"""`zernike`: Zernike decomposition of the form error over the aperture, and removal of chosen terms.

All ``terms`` are fitted together by least squares (core.metrics.zernike: radial part by Jacobi
polynomials, orthonormal "rms" or "peak" normalisation, ANSI/Noll/Fringe ordering) over the disk of
radius ``norm_radius`` (default: half the surface's aperture, else the largest point radius). The
terms named in ``remove`` (names such as piston, tilt, power, astigmatism, coma, trefoil, spherical,
or single indices in the chosen ordering) are subtracted from the residual; the others stay. The
coefficients go to the report and to ``zernike.csv`` (nm, with standard uncertainties).

Input channel: ``residual`` when present (after misalignment), else z (an interferometer's map);
output: ``residual`` with the removed terms subtracted.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import field_validator, model_validator

from pointspro.core.errors import StepError
from pointspro.core.metrics import zernike as zk
from pointspro.core.metrics.form import PVR_TERMS
from pointspro.core.metrics.pupil import pupil_of
from pointspro.core.metrics.sampling import plain_best_fits
from pointspro.core.params.pupil import PupilCentreParams
from pointspro.core.step import Context, Step, StepResult, param


class ZernikeParams(PupilCentreParams):
    ordering: Literal["ansi", "noll", "fringe"] = param(
        "fringe", help="single-index ordering: fringe (Z1 piston…Z36), noll (Z1…), ansi/OSA (Z0…)")
    terms: int = param(36, ge=1, le=231, help="number of terms fitted (the first N of the ordering)")
    normalization: Literal["rms", "peak"] = param(
        "rms", help="rms: orthonormal, a coefficient is the RMS its term adds; peak: each term "
        "peaks at ±1 on the edge")
    remove: list[str | int] = param(
        default_factory=lambda: ["piston", "tilt", "power"],
        help="terms subtracted from the residual: names (" + ", ".join(zk.TERM_NAMES) + ") or "
             "indices in the chosen ordering")
    norm_radius: float | None = param(None, unit="mm", gt=0, help="normalisation radius; empty: "
                                      "half the surface's aperture when the centre is its axis, "
                                      "else the smallest radius about the centre holding every point")
    @field_validator("remove")
    @classmethod
    def _known(cls, v):
        for t in v:
            if isinstance(t, str) and t not in zk.TERM_NAMES:
                raise ValueError(f"unknown term name {t!r}; use one of {', '.join(zk.TERM_NAMES)} "
                                 "or an index")
        return v

    @model_validator(mode="after")
    def _indices_fitted(self):
        """An index in ``remove`` names one of the fitted terms: ANSI counts from 0, Fringe and Noll
        from 1, up to ``terms`` of them (a review: -4 and 400 were taken in the window's form and
        failed only when the step ran)."""
        first = 0 if self.ordering == "ansi" else 1
        for t in self.remove:
            if isinstance(t, int) and not first <= t < first + self.terms:
                raise ValueError(f"remove: index {t} is not among the {self.terms} fitted {self.ordering} terms "
                                 f"({first} … {first + self.terms - 1})")
        return self


#: the terms an evenly sampled area's best-fit plane and sphere are made of (piston, tilt, power)
_BEST_FIT_TERMS = frozenset({(0, 0), (1, 1), (1, -1), (2, 0)})


def removed_pairs(remove, ordering, pairs, named_strictly: bool = True) -> list[tuple[int, int]]:
    """The fitted (n, m) pairs ``remove`` names. A name none of whose terms was fitted is refused when
    the recipe gave it (``named_strictly``); the default list (piston, tilt, power) takes what a fit
    of fewer terms has."""
    out = []
    for t in remove:
        if isinstance(t, str):
            got = [p for p in zk.TERM_NAMES[t] if p in pairs]
            if not got and named_strictly:  # a review: `terms: 4` with `remove: [spherical]` removed nothing, silently
                n = max(p[0] for p in zk.TERM_NAMES[t])
                raise StepError(f"remove: {t} is not among the {len(pairs)} fitted {ordering} terms (its "
                                f"radial order is {n}): fit more terms, or leave it out of remove")
            out += got
        else:
            try:
                p = zk.nm_of(int(t), ordering)
            except ValueError as e:
                raise StepError(f"remove: {e}") from None
            if p not in pairs:
                raise StepError(f"remove: term {t} is not among the {len(pairs)} fitted {ordering} terms")
            out.append(p)
    return list(dict.fromkeys(out))


class ZernikeStep(Step):
    id = "zernike"
    title = "Zernike decomposition"
    reads_residual = True
    summary = "Fit Zernike terms over the aperture; remove piston, tilt, power… from the residual."
    Params = ZernikeParams

    @classmethod
    def example_cloud(cls, cloud):
        from pointspro.core.step import with_example_residual

        return with_example_residual(cloud)

    def run(self, cloud, params: ZernikeParams, ctx: Context) -> StepResult:
        from pointspro.core.figures import before_after, png_artifact, zernike_bars

        channel = "residual" if "residual" in cloud.channels else "z"
        from pointspro.core.metrics.pupil import heights_are_sag

        if channel == "z" and heights_are_sag(ctx.surface, cloud.x, cloud.y, cloud.z):
            # a curved part's heights are its sag: fitted, they were reported as a 13.9 µm RMS "form
            # error" of the example with exit 0 (a review); correction and bspline_map refuse alike
            raise StepError("the cloud has no residual, and its heights z are the part's sag, not its form "
                            "error: run misalignment (or register) before zernike")
        v = cloud[channel] if channel == "residual" else cloud.z
        x, y = cloud.x, cloud.y
        pupil = pupil_of(x, y, ctx.surface, params.given_centre, params.norm_radius)
        c, R = pupil.center, pupil.radius
        if not R > 0:
            raise StepError("the points have no extent to normalise the Zernike disk by")
        if not np.isfinite(R):  # a centre ~1e154 mm or more from the points: the radius overflows
            raise StepError(f"the pupil centre ({c[0]:g}, {c[1]:g}) mm lies so far from the points that "
                            "the normalisation radius is not a finite number; give a centre near the "
                            "measured region (or none: docs/conventions.md, Pupil)")
        warnings = []
        # beyond 0.1 % of the radius: a scan that ends at the clear aperture leaves a few points some
        # µm beyond it once the pose is removed (6.9 µm at 30 mm), where the polynomials are as good as
        # inside; the warning fired on 10 of 17 ordinary parts in a review
        outside = _count_outside(x, y, c, R * (1 + OUTSIDE_TOLERANCE))
        if outside:
            warnings.append(f"{outside} points lie outside the normalisation radius {R:g} mm "
                            "(polynomials are extrapolated there); use aperture first")
        pairs = zk.terms(params.terms, params.ordering)
        if cloud.n <= len(pairs):
            raise StepError(f"{cloud.n} points cannot determine {len(pairs)} Zernike terms")
        ctx.progress.update(0.2, "fitting")
        coef, sd, resid, cond = zk.fit(x, y, v, R, pairs, params.normalization, c)
        fit_rms = float(np.sqrt(resid @ resid / len(resid)))
        # PVr's parts for the run's summary when these 36 Fringe terms are its fit (core.pipeline.
        # _reusable): the summary then needs no second 36-term fit of the same residual
        pvr_reusable = params.ordering == "fringe" and len(pairs) == PVR_TERMS and cloud.n > 2 * PVR_TERMS
        if not pvr_reusable:
            del resid  # one full-length column less while the removal is evaluated (issue 26)
        ctx.progress.check()
        gone = removed_pairs(params.remove, params.ordering, pairs, "remove" in params.model_fields_set)
        cols = [pairs.index(p) for p in gone]
        removed_coef, how = coef[cols], "the joint fit's coefficients of the removed terms"
        if gone and set(gone) <= _BEST_FIT_TERMS and plain_best_fits(x, y, c, R):
            # piston, tilt (and power) of an evenly sampled area that is not the disk — a rectangular
            # map — are taken away as its best-fit plane (sphere): those terms fitted alone, the
            # area-weighted least squares of ISO 14999-4 (core.metrics.sampling.plain_best_fits). The joint fit's coefficients equal
            # them only over a full disk: on a rectangular map (its circumscribed disk has corners
            # without points) the higher terms trade with them, and removing them raised the RMS of
            # two real maps of six (35.2 → 67.4 nm; refused) and left 13.55 nm on MetroPro's for the
            # plane's 13.33 nm (a review). The coefficients reported stay the joint fit's.
            # the best fit is of the whole plane (sphere) — piston and both tilts, and power when it
            # goes — even where only some of them are removed: tilt alone, fitted without piston,
            # would take part of the mean wherever the points are not centred on the pupil
            block = [(0, 0), (1, 1), (1, -1)] + ([(2, 0)] if (2, 0) in gone else [])
            fitted = zk.fit(x, y, v, R, block, params.normalization, c).coef
            removed_coef = np.array([fitted[block.index(p)] for p in gone])
            how = ("the removed terms fitted alone (best-fit plane or sphere of the evenly sampled area, "
                   "which is not the Zernike disk)")
        # only the removed terms are evaluated again (in chunks: never the N × p design matrix)
        after = zk.evaluate(x, y, removed_coef, R, gone, params.normalization, c)
        np.subtract(v, after, out=after)  # v − removed terms, in place
        reuse = {}
        if pvr_reusable:  # the kept terms' fit = after − resid; PV in chunks, no full-length temporary
            reuse["pvr"] = {"xyz": cloud.xyz, "center": c, "fit_pv": _ptp_of_difference(after, resid),
                            "rest_rms": float(np.sqrt(np.mean(resid ** 2)))}
            del resid
        rms_before, rms_after = _std(v), _std(after)  # the guard's: the points' RMS, as the fit's
        if gone and rms_after > 1.05 * rms_before:
            # Removing least-squares terms cannot raise the RMS unless the kept and the removed terms
            # trade against each other (nearly dependent on this sampling): the "form" left is then
            # an artefact of the fit, not of the part (issue 15: 155.6 µm from 0.0133 µm of data).
            raise StepError(
                f"removing {', '.join(map(str, params.remove))} raises the RMS from "
                f"{_um(rms_before)} to {_um(rms_after)} (condition number {cond:.3g}): the {len(pairs)} "
                f"terms trade against each other on these points — fit fewer terms, or check the "
                f"pupil (centre ({c[0]:.6g}, {c[1]:.6g}) mm, radius {R:.6g} mm, {pupil.how})")
        if cond > 1e6:
            # a patch off the axis of a nominal with an aperture: the pupil is the whole aperture and
            # the coefficients its wild extrapolation (a review: Z(2,2) −5.9·10⁸ nm) — the pupil named
            warnings.append(f"the terms are nearly dependent on these points (condition {cond:.3g}): "
                            f"fewer terms, a fuller sampling of the pupil, or a pupil the points fill — "
                            f"`centre` and `norm_radius` (now centre ({c[0]:.6g}, {c[1]:.6g}) mm, radius "
                            f"{R:.6g} mm, {pupil.how})")
        # the report's RMS is over the area (docs/conventions.md, Summary figures): a star scan crowds
        # its centre, and its points' RMS read astigmatism ~20 % low (tests/test_area_rms_reports.py);
        # an even sampling: the points' RMS, as before
        from pointspro.core.pipeline import area_weights_of

        w = area_weights_of(cloud)
        if w is not None:
            rms_before, rms_after = _std(v, w), _std(after, w)
        j0 = zk.first_index(params.ordering)
        rows = [{"j": j0 + i, "n": n, "m": m, "name": zk.name_of(n, m),
                 "coefficient_nm": float(coef[i] * 1e6), "uncertainty_nm": float(sd[i] * 1e6),
                 "removed": (n, m) in gone} for i, (n, m) in enumerate(pairs)]
        report = {
            "ordering": params.ordering, "normalization": params.normalization, "norm_radius": R,
            **pupil.report(),
            "channel": channel, "terms": len(pairs),
            "removed_terms": [zk.index_of(n, m, params.ordering) for n, m in gone], "removal": how,
            "coefficients": rows, "condition_number": cond,
            "fit_residual_rms_um": fit_rms * 1e3,
            "rms_before_um": rms_before * 1e3, "rms_after_um": rms_after * 1e3,
            "pv_after_um": float(np.ptp(after) * 1e3), "warnings": warnings,
        }
        csv = "j,n,m,name,coefficient_nm,uncertainty_nm,removed\n" + "".join(
            f"{r['j']},{r['n']},{r['m']},{_csv_field(r['name'])},{r['coefficient_nm']!r},{r['uncertainty_nm']!r},"
            f"{int(r['removed'])}\n" for r in rows)
        labels = [f"{params.ordering[0].upper()}{r['j']}" for r in rows]
        arts = {
            "zernike.csv": csv,
            "zernike.png": png_artifact(zernike_bars, labels, coef * 1e6,
                                        removed=[lab for lab, r in zip(labels, rows) if r["removed"]],
                                        title=f"Zernike coefficients ({params.ordering}, "
                                              f"{params.normalization})",
                                        normalization=params.normalization),
            "zernike_removed.png": png_artifact(before_after, x, y, v, after,
                                                what="removing " + (", ".join(map(str, params.remove))
                                                                    or "nothing"), weights=w),
        }
        ctx.log.info("%d terms fitted (condition %.3g), %d removed; RMS %.4g → %.4g µm", len(pairs), cond,
                     len(gone), rms_before * 1e3, rms_after * 1e3)
        out = cloud.replace(channels={"residual": after})
        if reuse:
            reuse["pvr"]["residual"] = out["residual"]
        return StepResult(out, report, arts, reuse)


#: points per chunk of the step's own full-length reductions
_CHUNK = 1 << 18


def _ptp_of_difference(a, b) -> float:
    """max(a − b) − min(a − b), in chunks."""
    lo, hi = np.inf, -np.inf
    for s in range(0, len(a), _CHUNK):
        d = a[s:s + _CHUNK] - b[s:s + _CHUNK]
        lo, hi = min(lo, float(d.min())), max(hi, float(d.max()))
    return hi - lo


#: relative reach beyond the normalisation radius a point may have before the fit warns of extrapolation
OUTSIDE_TOLERANCE = 1e-3


def _count_outside(x, y, c, r: float) -> int:
    """Points farther than r from c, in chunks (no full-length radius column)."""
    out = 0
    for s in range(0, len(x), _CHUNK):
        dx = x[s:s + _CHUNK] - c[0]
        dy = y[s:s + _CHUNK] - c[1]
        out += int(np.count_nonzero(dx * dx + dy * dy > r * r))
    return out


def _std(v, w=None) -> float:
    """np.std(v) (about the mean, two passes) in chunks: no full-length temporary. ``w``: the points'
    areas (core.metrics.area_weights), then over the area: √(Σ w (v − v̄_w)² / Σ w), v̄_w = Σ w v / Σ w
    (core.metrics.area_weights.weighted_rms)."""
    n = len(v)
    if not n:
        return float("nan")
    total = n if w is None else float(np.sum(w))
    m = (float(np.sum(v)) if w is None else float(np.dot(w, v))) / total
    acc = 0.0
    for s in range(0, n, _CHUNK):
        d = v[s:s + _CHUNK] - m
        acc += float(d @ d) if w is None else float(np.dot(w[s:s + _CHUNK], d * d))
    return float(np.sqrt(acc / total))


def _um(v_mm: float) -> str:
    from pointspro.core.units import format_length

    return format_length(v_mm)


def _csv_field(text: str) -> str:
    """A CSV field (RFC 4180): quoted when it holds a comma, a quote or a line end — the unnamed
    terms' names "Z(4,2)" made 8 fields of a 7-column row, and a reader shifted the coefficients
    into the next column (issue 16's review)."""
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text
