"""The runner: applies a recipe's steps to a cloud with progress, cancellation and timing.

The same runner serves `pointspro --batch`, the window's worker thread and the tests.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from .cloud import PointCloud
from .errors import Cancelled, InternalError, PointsProError, StepError
from .progress import Progress
from .recipe import Recipe, check_step_order
from .step import Context, StepResult


@dataclass
class StepRecord:
    id: str
    title: str
    seconds: float
    report: dict
    artifacts: dict
    points_in: int
    points_out: int
    #: "" for a step id that runs once; "4_" (its 1-based position among the run steps) for one that
    #: runs more than once, so the second `knn_denoise`'s omega_map.png never replaces the first's
    file_prefix: str = ""

    def file_name(self, artifact: str) -> str:
        return self.file_prefix + artifact

    #: the step's StepResult.reuse (full-length arrays of this run; never written)
    reuse: dict = field(default_factory=dict, repr=False, compare=False)

    def to_json(self) -> dict:
        return {"id": self.id, "title": self.title, "seconds": round(self.seconds, 6),
                "points_in": self.points_in, "points_out": self.points_out, "report": self.report,
                "artifacts": sorted(self.file_name(a) for a in self.artifacts)}


@dataclass
class PipelineResult:
    input_cloud: PointCloud
    cloud: PointCloud
    steps: list[StepRecord] = field(default_factory=list)
    #: the recipe's nominal (None: a map with no nominal) — decides the pupil of PVr
    surface: object | None = None
    #: core.uncertainty's result (Monte Carlo through the steps) when the recipe has ``uncertainty:``
    uncertainty: object | None = None
    #: core.tolerance's verdict block when the recipe has ``tolerance:`` (core/assessment.py)
    tolerance: dict | None = None
    #: the pupil centre the recipe gives (core.metrics.pupil.recipe_centre; None: by the rules)
    pupil_centre: tuple[float, float] | None = None

    @property
    def artifacts(self) -> dict:
        """Every step's artifacts by the file name they are written under (StepRecord.file_name)."""
        arts = {rec.file_name(name): art for rec in self.steps for name, art in rec.artifacts.items()}
        if self.uncertainty is not None:  # uncertainty.png, uncertainty_samples.csv (core.uncertainty)
            arts.update(self.uncertainty.artifacts())
        return arts

    _summary: dict | None = field(default=None, init=False, repr=False)

    def summary(self) -> dict:
        """summarize() of input and output, computed once (PVr and slope RMS fit a map)."""
        if self._summary is None:
            from .parallel import single_threaded_blas

            with single_threaded_blas():  # the slope RMS's banded B-spline solve (run_pipeline's doc)
                self._summary = summarize(self.input_cloud, self.cloud, self.surface,
                                          reuse=[rec.reuse for rec in self.steps], centre=self.pupil_centre)
        s = dict(self._summary)
        if self.uncertainty is not None:
            s["uncertainty"] = self.uncertainty.block()
        if self.tolerance is not None:
            s["tolerance"] = self.tolerance
        return s


def summarize(cloud_in: PointCloud, cloud_out: PointCloud, surface=None, reuse=(), centre=None) -> dict:
    """points in/out and the optician's metrics over the kept points: RMS, PV, PVr (µm) and slope
    RMS (µrad) — core.metrics.form — of the residual; for a height map with no residual and no
    nominal (or a flat), of the heights after piston and tilt removal, said in ``figures_of``.
    PVr's 36-term fit uses the pupil of core.metrics.pupil (centre and radius reported) about
    ``centre`` when the recipe gives one (core.metrics.pupil.recipe_centre).

    ``reuse``: the steps' StepResult.reuse, in order. PVr's fit and the slope spline are taken from
    a step instead of fitted again when that step fitted exactly them on exactly these data (see
    ``_reusable``): the same numbers to rounding, the time of a whole Zernike fit and a whole
    B-spline fit saved (a third of a 12.6 M-point map's run; issues 17, 26)."""
    from .metrics import form_metrics
    from .metrics.area_weights import area_weights, weighting_words
    from .metrics.pupil import is_flat, pupil_of

    s = {"points_in": cloud_in.n, "points_out": cloud_out.n, "rms_um": None, "pv_um": None,
         "pvr_um": None, "slope_rms_urad": None, "figures_of": None}
    if not cloud_out.n:
        return s
    x, y = cloud_out.x, cloud_out.y
    if "residual" in cloud_out.channels:
        v = cloud_out["residual"]
        s["figures_of"] = "residual"
    elif is_flat(surface) and cloud_out.n >= 3:
        v = remove_piston_tilt(x, y, cloud_out.z)
        s["figures_of"] = "heights, piston and tilt removed (no residual)"
    else:
        return s
    if _is_stylus_profile(cloud_out):
        # a profile has no area: PVr's Zernike fit and the map's slope RMS mean nothing there; its
        # PV/RMS stand, and each profile's slope error is in the step's report (core.profiles)
        d = v - v.mean()
        s.update({"rms_um": float(np.sqrt(np.mean(d * d))) * 1e3, "pv_um": float(np.ptp(v)) * 1e3,
                  "figures_of": f"{s['figures_of']} of stylus profiles (no PVr or map slope on lines)"})
        return s
    pupil = pupil_of(x, y, surface, centre)
    pvr_parts, spline = _reusable(cloud_out, v, pupil, reuse) if s["figures_of"] == "residual" \
        else (None, None)
    weights = area_weights(x, y)
    s.update(form_metrics(x, y, v, pupil.radius, center=pupil.center, pvr_parts=pvr_parts,
                          spline=spline, weights=weights))
    s["rms_over"] = weighting_words(weights)
    s["pupil"] = pupil.report()
    return s


def _reusable(cloud_out: PointCloud, r: np.ndarray, pupil, reuse):
    """(PVr's (fit PV, rest RMS) in mm, the slope spline) a step left for these very data, or None.

    PVr: the zernike step fitted its input v over Fringe Z1…Z36 about the same centre and removed
    some of those terms, r = v − removed. The span of Fringe Z1…Z36 (all n + |m| ≤ 10) is the same
    for any normalisation radius about a centre (R_n^m(sρ) is a sum of R_k^m, k ≤ n), so the
    summary's 36-term fit of r is the step's fit less the removed terms and its rest is the step's
    fit residual e (orthogonal to the span): PVr = PV(r − e) + 3·RMS(e), both computed by the step.
    Valid only while the points and the residual are the step's own arrays (identity: any later
    step that moves, removes or changes them makes new arrays) and the centre is the summary's.

    Slope spline: bspline_map's spline when it was fitted with fit_bspline's defaults (automatic
    knots, default smoothing, the points' own box: no diameter) on these arrays."""
    pvr_parts = spline = None
    for entry in reuse:
        p = entry.get("pvr")
        if p is not None:
            same = (p["xyz"] is cloud_out.xyz and p["residual"] is r
                    and tuple(map(float, p["center"])) == tuple(map(float, pupil.center)))
            pvr_parts = (p["fit_pv"], p["rest_rms"]) if same else None
        b = entry.get("slope_spline")
        if b is not None:
            spline = b["spline"] if b["xyz"] is cloud_out.xyz and b["values"] is r else None
    return pvr_parts, spline


def _is_stylus_profile(cloud) -> bool:
    from .errors import PointsProError
    from .profiles import profiles_of

    try:
        return profiles_of(cloud) is not None
    except PointsProError:
        return False


def area_weights_of(cloud):
    """The points' areas for an RMS over the area (core.metrics.area_weights), as the summary takes
    them: None on an even sampling (the plain mean stands) and for stylus profiles (no area)."""
    from .metrics.area_weights import area_weights

    return None if _is_stylus_profile(cloud) else area_weights(cloud.x, cloud.y)


def remove_piston_tilt(x, y, z):
    """z − (a + b·x + c·y), the least-squares plane about the points' bounding-box centre (mm)."""
    x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    A = np.column_stack([np.ones_like(x), x - cx, y - cy])
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    return z - A @ coef


def check_sanity(cloud_in: PointCloud, cloud_out: PointCloud) -> None:
    """A residual whose RMS exceeds the input's whole height range is a fit that diverged (a km of
    "form error" on a 150 mm part), never a result: StepError naming both figures.

    The rule on the mean: the RMS is taken about the residual's mean, since a residual's piston may be
    an arbitrary offset (a height map's zero, a misalignment without dz in its dof) — except when the
    residual was last made by a step that fits every rigid motion (``mean_fitted``: register), whose
    residual has no free piston: there its mean is kept, so a fit that pushed the cloud off the
    nominal (a review: register's residual a constant 0.4 m on a 40 mm part, its scatter small)
    counts at its full size."""
    from .units import format_length

    if "residual" not in cloud_out.channels or not cloud_out.n or not cloud_in.n:
        return
    r = cloud_out["residual"]
    if not np.all(np.isfinite(r)):
        bad = int((~np.isfinite(r)).sum())
        raise StepError(f"sanity check: {bad} residuals are NaN/inf after the steps")
    # the step that last made the residual (its provenance); register fits all six rigid motions, the
    # slide along the nominal's normal included, so a mean left in its residual is the fit's own miss
    mean_fitted = {"register"}
    made_by = next((e.get("id") for e in reversed(cloud_out.provenance)
                    if isinstance(e, dict) and e.get("id") in mean_fitted | {"misalignment"}), None)
    centre = 0.0 if made_by in mean_fitted else float(r.mean())
    rms = float(np.sqrt(np.mean((r - centre) ** 2)))
    span = float(np.ptp(cloud_in.z))
    if rms > max(span, 1e-6):
        if made_by is None:  # no step made it: the input carried it (a cloud.csv, the Python API)
            raise StepError(f"sanity check: the residual's RMS ({format_length(rms)}) exceeds the input's "
                            f"whole height range ({format_length(span)}), and no step of this run made "
                            "that residual: the input carries it — are its heights z the points' "
                            "heights? (the residual is z − sag; a map of form error alone belongs in z, "
                            "with no residual column)")
        raise StepError(f"sanity check: the residual's RMS ({format_length(rms)}) exceeds the input's "
                        f"whole height range ({format_length(span)}) — a fit diverged; check the "
                        "surface, the pose's DOF and the Zernike pupil in report.json")


def _one_form(report) -> dict:
    """A step's report with ``warnings`` always present as a list of strings (a third-party step may
    give none, one string, or objects), so the report, the window and scripts read one form."""
    report = dict(report or {})
    w = report.get("warnings") or []
    report["warnings"] = [w] if isinstance(w, str) else [str(x) for x in w]
    return report


def internal_message(where: str, e: BaseException) -> str:
    """One line for a bug met at ``where``: "step 2 'buggy': internal error ZeroDivisionError:
    division by zero — please report" (the traceback goes to summary.json and --debug)."""
    text = str(e).strip().splitlines()[0] if str(e).strip() else ""
    return f"{where}: internal error {type(e).__name__}" + (f": {text}" if text else "") + \
        " — please report"


def _stale_residual(before: PointCloud, after: PointCloud) -> bool:
    """True when a step moved the points (new coordinates, the same points) but handed the residual
    on untouched: the residual of the points before the move (a review: probe_radius after
    misalignment kept z − sag of the probe centres, summary RMS 27.8 µm for a true 0.99 µm). Steps
    that move points and keep the residual true (kinematic, z_scale) write a new residual array;
    transform drops it."""
    if "residual" not in before.channels or after.n != before.n:
        return False
    kept = np.may_share_memory(after.channels["residual"], before.channels["residual"])
    moved = not np.may_share_memory(after.xyz, before.xyz) and not np.array_equal(after.xyz, before.xyz)
    return kept and moved


def stale_message(stale, reader: str | None) -> str:
    """The error of a residual left stale by a move (``_stale_residual``): the step after it uses
    it (``reader``), or it would reach the outputs (None)."""
    mover, mover_id, made_by = stale
    fix = (f"move '{mover_id}' before {made_by}" if made_by else "the input's residual column is of the "
           "points as read: leave it out of the input")
    use = f"{reader} would use it" if reader else "it would be written as the form error"
    return (f"{mover}: this step moves the points, but their residual (the form error) was made before "
            f"the move and would no longer match them, and {use} — {fix}, or make the residual again "
            "right after it (misalignment, register)")


def _check_finite(cloud: PointCloud) -> None:
    """A cloud with a NaN or infinite x, y or z is refused naming the first row: the file readers drop
    such rows and count them, but a cloud built in memory (the Python API) reached the steps with
    them — a summary figure silently missing, "400 residuals are NaN/inf" for 3 NaN rows, and an
    uncertainty that failed with an internal error (a review)."""
    ok = np.isfinite(cloud.xyz).all(axis=1)
    if ok.all():
        return
    from .errors import InputError

    bad = np.flatnonzero(~ok)
    row = int(cloud["index"][bad[0]]) if "index" in cloud.channels else int(bad[0])
    raise InputError(f"{bad.size} of {cloud.n} points have a NaN or infinite x, y or z (the first: row "
                     f"{row}); drop them first, as the file readers do: "
                     "cloud.select(np.isfinite(cloud.xyz).all(axis=1))")


def run_pipeline(cloud: PointCloud, recipe: Recipe, *, progress: Progress | None = None,
                 log: logging.Logger | None = None, surface=None, upto: int | None = None,
                 allowed_dirs=None, assess: bool = True) -> PipelineResult:
    """Run the recipe's enabled steps (those before position ``upto`` when given).

    Step errors that are the input's fault come back as StepError naming the step, bugs as
    InternalError naming it; `Cancelled` propagates. ``allowed_dirs``: folders a parameter file may
    lie in besides the recipe's (the batch: the inputs' folders and --allow-path); None: any. The input cloud is never modified (its arrays are read-only).
    After the whole recipe (``upto`` None) and with ``assess``, the recipe's ``uncertainty:`` and
    ``tolerance:`` blocks are evaluated (core/assessment.py) into ``result.uncertainty`` and
    ``result.tolerance``.

    BLAS runs one thread meanwhile (core.parallel.single_threaded_blas: the steps' calls are narrow,
    and spinning BLAS threads beside another busy process made the window's run 3–4× slower).
    """
    from .parallel import single_threaded_blas

    with single_threaded_blas():
        return _run_pipeline(cloud, recipe, progress=progress, log=log, surface=surface, upto=upto,
                             allowed_dirs=allowed_dirs, assess=assess)


def _run_pipeline(cloud, recipe, *, progress, log, surface, upto, allowed_dirs, assess):
    progress = progress or Progress()
    log = log or logging.getLogger("pointspro")
    _check_finite(cloud)
    if surface is None and recipe.surface_spec is not None:
        surface = recipe.build_surface()
    steps = [s for s in recipe.steps[:upto] if s.enabled]
    # the window and the Python API edit recipes without parsing them again: the order rule here too
    check_step_order(recipe.steps[:upto], "recipe")
    assessing = assess and upto is None and (recipe.uncertainty is not None
                                             or recipe.tolerance is not None)
    whole, progress = progress, (progress.sub(0.0, 0.3) if assessing else progress)
    from .metrics.pupil import recipe_centre

    result = PipelineResult(cloud, cloud, surface=surface, pupil_centre=recipe_centre(steps))
    n = max(len(steps), 1)
    current = cloud
    residual_by = None  # the step that made the current residual ("step 3 'misalignment'"); None: the input
    stale = None  # (where, id, residual_by) of a step that moved the points after their residual was made
    previous = None  # the step run last ("step 1 'manual_edit'")
    for i, rs in enumerate(steps):
        progress.check()
        sub = progress.sub(i / n, (i + 1) / n)
        ctx = Context(progress=sub, log=log.getChild(rs.id), surface=surface, inputs=recipe.inputs,
                      base_dir=recipe.base_dir,
                      allowed_dirs=None if allowed_dirs is None else tuple(allowed_dirs))
        sub.update(0.0, rs.step_cls.title)
        t0 = time.perf_counter()
        where = f"step {recipe.steps.index(rs) + 1} '{rs.id}'"
        if current.n == 0:  # every point removed before it (a manual_edit of all rows, an aperture off the part)
            raise StepError(f"{where}: no point is left to process — "
                            + (f"{previous} removed them all" if previous else "the cloud is empty"))
        try:
            out = rs.step_cls().run(current, rs.params, ctx)
        except PointsProError as e:
            raise StepError(f"{where}: {e}") from e
        except Cancelled:
            raise
        except Exception as e:  # a bug in the step or under it: this input fails alone
            raise InternalError(internal_message(where, e)) from e
        except KeyboardInterrupt:  # Ctrl-C (a sequential batch, the window): the run stops
            raise
        except BaseException as e:  # noqa: BLE001 — sys.exit() or a bare BaseException in a step
            # (a third-party one): this input fails alone; a SystemExit reached the batch's own
            # handler and ended it with exit 0, no summary and a half-written folder (a review)
            what = f"called sys.exit({e.code!r})" if isinstance(e, SystemExit) else \
                f"raised {type(e).__name__}" + (f": {e}" if str(e) else "")
            raise InternalError(f"{where}: internal error: the step {what} — please report") from None
        seconds = time.perf_counter() - t0
        previous = where
        if not isinstance(out, StepResult) or not isinstance(out.cloud, PointCloud):
            raise InternalError(f"{where}: internal error: returned {type(out).__name__}, not a "
                                "StepResult — please report")
        new = out.cloud.with_provenance({"id": rs.id, "params": rs.params.model_dump(mode="json")})
        makes = getattr(rs.step_cls, "makes_residual", False)
        if stale is not None:
            if not makes:
                raise StepError(stale_message(stale, where))
            stale = None
        if "residual" in new.channels:
            if _stale_residual(current, new):
                # not yet an error: a residual-making step right after it makes the residual again
                stale = (where, rs.id, residual_by)
            elif makes or "residual" not in current.channels:
                residual_by = where
        result.steps.append(StepRecord(rs.id, rs.step_cls.title, seconds, _one_form(out.report),
                                       dict(out.artifacts), current.n, new.n,
                                       reuse=dict(getattr(out, "reuse", None) or {})))
        sub.update(1.0, f"{rs.step_cls.title}: done")
        current = new
    if stale is not None:
        raise StepError(stale_message(stale, None))
    check_sanity(cloud, current)
    ids = [rec.id for rec in result.steps]
    for k, rec in enumerate(result.steps, 1):
        if ids.count(rec.id) > 1:
            rec.file_prefix = f"{k}_"
    result.cloud = current
    if assessing:
        from .assessment import assess as assess_result

        try:
            assess_result(recipe, result, progress=whole.sub(0.3, 1.0))
        except (PointsProError, Cancelled):
            raise
        except Exception as e:  # a bug in the Monte Carlo or the tolerance: this input fails alone
            raise InternalError(internal_message("uncertainty/tolerance", e)) from e
    return result
