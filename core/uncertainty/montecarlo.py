"""The Monte Carlo trials through the recipe's steps (JCGM 101 §7; docs/uncertainty.md, Samples).

A *plan* is made once from the nominal input: each enabled step is run and classified by what it did
to the cloud —

- ``skip``: the cloud came out as it went in (bspline_map, fiducials: artifacts only). Not run again.
- ``select``: the cloud came out as a subset of its rows, coordinates and channels untouched
  (manual_edit, knn_denoise, aperture — whether or not it removed anything) and its report carries no
  figure (a zernike step whose removal changed nothing is still run: its coefficients are figures). Each sample keeps the
  *same rows* (the nominal run's decision; the interval is conditional on it). Channels the step added
  (knn_denoise's ω) are the nominal's.
- ``run``: anything else (probe_radius, misalignment, zernike, …): run again on every sample; if it
  dropped points in the nominal run, a sample keeps only the rows the nominal kept.

A sample is the input with fresh draws — noise N(0, σ²) on z (the measuring axis), the scale sources'
factors on x, y, z, the probe radius on its step's parameter — run through the plan; its figures are
those of core.pipeline.summarize (PVr also in its two parts), each Zernike coefficient, each pose
parameter and the tolerance's quantities. Sample i's random numbers come from SeedSequence(seed,
spawn_key=(i,)): the same whatever the number of worker processes.
"""
from __future__ import annotations

import logging
import os
import signal
from dataclasses import dataclass, field

import numpy as np

from ..cloud import PointCloud
from ..errors import Cancelled, PointsProError, StepError
from ..step import Context

_QUIET = logging.getLogger("pointspro.uncertainty.samples")
_QUIET.setLevel(logging.ERROR)
_QUIET.propagate = False
_QUIET.addHandler(logging.NullHandler())

POSE_KEYS = (("alpha_deg", "alpha_deg"), ("beta_deg", "beta_deg"), ("gamma_deg", "gamma_deg"),
             ("dx", "dx_mm"), ("dy", "dy_mm"), ("dz", "dz_mm"))


@dataclass
class PlannedStep:
    kind: str  # "run", "select", "skip"
    rs: object  # the RecipeStep
    position: int  # 1-based in the recipe
    rows: np.ndarray | None = None  # select / run-with-removal: rows of the step's input kept
    added: dict = field(default_factory=dict)  # select: channels the step added (nominal values)
    index_out: np.ndarray | None = None


@dataclass
class Plan:
    steps: list[PlannedStep]
    surface: object
    inputs: dict
    base_dir: object
    allowed_dirs: object
    #: figure name → (step position, how to read it from the report) for Zernike and pose
    report_keys: dict = field(default_factory=dict)

    def reuse_text(self) -> str:
        sel = [f"{p.rs.id}" for p in self.steps if p.kind == "select"]
        skip = [f"{p.rs.id}" for p in self.steps if p.kind == "skip"]
        run = [f"{p.rs.id}" for p in self.steps if p.kind == "run"]
        parts = []
        if sel:
            parts.append("kept the nominal run's point selection of " + ", ".join(sel)
                         + " (the interval is conditional on those decisions)")
        if skip:
            parts.append("skipped " + ", ".join(skip) + " (its output cloud equals its input: artifacts only)")
        if run:
            parts.append("re-ran " + ", ".join(run) + " on every sample")
        return "; ".join(parts)


def _context(plan: Plan, progress=None):
    from ..progress import Progress

    return Context(progress=progress or Progress(), log=_QUIET, surface=plan.surface, inputs=plan.inputs,
                   base_dir=plan.base_dir, allowed_dirs=plan.allowed_dirs)


def _run_step(plan: Plan, rs, cloud: PointCloud, params=None, progress=None):
    where = f"step {rs_position(plan, rs)} '{rs.id}'"
    try:
        return rs.step_cls().run(cloud, params if params is not None else rs.params, _context(plan, progress))
    except (PointsProError, Cancelled):
        raise
    except Exception as e:  # noqa: BLE001 — a sample's failure is counted, the message kept
        raise StepError(f"{where}: {type(e).__name__}: {e}") from e


def rs_position(plan: Plan, rs) -> int:
    for p in plan.steps:
        if p.rs is rs:
            return p.position
    return 0


def _rows_of(before: PointCloud, after: PointCloud) -> np.ndarray | None:
    """Positions in ``before`` of ``after``'s rows when ``after`` is a subset of ``before``'s rows with
    coordinates and shared channels untouched; None otherwise."""
    if after.n > before.n:
        return None
    ib, ia = before["index"], after["index"]
    order = np.argsort(ib, kind="stable")
    pos = np.searchsorted(ib[order], ia)
    if np.any(pos >= ib.size):
        return None
    rows = order[pos]
    if not np.array_equal(ib[rows], ia) or np.unique(ia).size != ia.size:
        return None
    if not np.array_equal(before.xyz[rows], after.xyz, equal_nan=True):
        return None
    for name in set(before.channels) & set(after.channels):
        a, b = before[name][rows], after[name]
        if not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
            return None
    return rows


def make_plan(recipe, cloud: PointCloud, surface, allowed_dirs=None, progress=None):
    """Run the recipe's enabled steps once on the input, classify each (module doc); returns the plan
    the nominal run's output cloud and its run steps' reports by position."""
    steps = [(i, rs) for i, rs in enumerate(recipe.steps, 1) if rs.enabled]
    plan = Plan([], surface, dict(recipe.inputs), recipe.base_dir,
                None if allowed_dirs is None else tuple(allowed_dirs))
    reports = {}
    current = cloud
    n = max(len(steps), 1)
    for k, (pos, rs) in enumerate(steps):
        sub = progress.sub(k / n, (k + 1) / n) if progress is not None else None
        ps = PlannedStep("run", rs, pos)
        plan.steps.append(ps)
        res = _run_step(plan, rs, current, progress=sub)
        out = res.cloud
        # a step whose report carries figures (Zernike coefficients, a pose) is always run again, even
        # where its cloud came out unchanged (a piston and tilt already zero after the pose fit)
        rows = None if report_figures({pos: res.report}, plan) else _rows_of(current, out)
        if rows is not None and rows.size == current.n and np.array_equal(rows, np.arange(current.n)) \
                and set(out.channels) == set(current.channels):
            ps.kind = "skip"
            out = current
        elif rows is not None:
            ps.kind = "select"
            ps.rows = rows
            ps.added = {c: out[c] for c in out.channels if c not in current.channels}
        elif out.n < current.n:
            keep = np.isin(current["index"], out["index"])
            ps.rows = np.flatnonzero(keep)
        ps.index_out = out["index"]
        if ps.kind == "run":
            reports[pos] = res.report
        current = out
    return plan, current, reports


def run_plan(plan: Plan, cloud: PointCloud, params_of=None):
    """The plan applied to ``cloud`` (rows in the nominal input's order); returns the output cloud and
    each run step's report by position. ``params_of(rs)`` may give perturbed parameters."""
    current = cloud
    reports = {}
    for ps in plan.steps:
        if ps.kind == "skip":
            continue
        if ps.kind == "select":
            ch = {name: current[name][ps.rows] for name in current.channels}
            ch.update(ps.added)
            current = PointCloud(current.xyz[ps.rows], ch, current.meta, current.provenance)
            continue
        params = params_of(ps.rs) if params_of is not None else None
        res = _run_step(plan, ps.rs, current, params)
        out = res.cloud
        reports[ps.position] = res.report
        if ps.rows is not None:  # the nominal run dropped points here: keep the nominal's rows
            keep = np.isin(out["index"], ps.index_out)
            if not keep.all():
                out = out.select(keep)
        current = out
    return current, reports


# -- the figures of one run ---------------------------------------------------------------------------

_PAIRS = {}


def summary_figures(cloud: PointCloud, surface, knot_spacing: float | None = None, centre=None) -> dict:
    """rms_um, pv_um, pvr_um, slope_rms_urad as core.pipeline.summarize computes them, plus PVr's two
    parts (``pvr_fit_pv_um``: PV of the 36-term fit; ``pvr_rest_rms_um``: RMS of what it leaves).
    ``knot_spacing``: the slope spline's (the nominal run's, reused by the samples; None: its default);
    ``centre``: the pupil centre the recipe gives (core.metrics.pupil.recipe_centre)."""
    from ..maps.bspline import default_knot_spacing, fit_bspline
    from ..metrics import zernike as zk
    from ..metrics.area_weights import area_weights, weighted_rms
    from ..metrics.form import PVR_TERMS, slope_rms_urad
    from ..metrics.pupil import is_flat, pupil_of
    from ..pipeline import _is_stylus_profile, remove_piston_tilt

    out = {}
    if not cloud.n:
        return out
    x, y = cloud.x, cloud.y
    if "residual" in cloud.channels:
        v = cloud["residual"]
    elif is_flat(surface) and cloud.n >= 3:
        v = remove_piston_tilt(x, y, cloud.z)
    else:
        return out
    v = np.asarray(v, dtype=np.float64)
    profile = _is_stylus_profile(cloud)
    weights = None if profile else area_weights(x, y)  # as summarize: RMS over the area
    out["rms_um"] = weighted_rms(v, weights) * 1e3
    out["pv_um"] = float(np.ptp(v)) * 1e3
    if profile:
        return out
    pupil = pupil_of(x, y, surface, centre)
    pairs = _PAIRS.get(PVR_TERMS) or _PAIRS.setdefault(PVR_TERMS, zk.terms(PVR_TERMS, "fringe"))
    R = pupil.radius if pupil.radius > 0 else 1.0
    if len(v) > 2 * len(pairs):
        resid = zk.fit(x, y, v, R, pairs, center=pupil.center).residual
        fit_pv = float(np.ptp(v - resid))
        rest = float(np.sqrt(np.mean(resid ** 2)))
        out["pvr_fit_pv_um"] = fit_pv * 1e3
        out["pvr_rest_rms_um"] = rest * 1e3
        out["pvr_um"] = (fit_pv + 3.0 * rest) * 1e3
    # else no PVr: 72 points or fewer cannot carry its 36-term fit (core.metrics.form.pvr)
    spline = None
    if len(v) >= 50:
        try:
            h = knot_spacing if knot_spacing is not None else default_knot_spacing(x, y)
            spline = fit_bspline(x, y, v, knot_spacing=h)
            out["_knot_spacing"] = h
        except ValueError:
            spline = None
    s = slope_rms_urad(x, y, v, spline, weights) if spline is not None else None
    if s is not None:
        out["slope_rms_urad"] = s
    return out


def report_figures(reports: dict, plan: Plan) -> dict:
    """Zernike coefficients (``zernike.Z4_nm``) and pose parameters (``pose.alpha_deg``) of the run
    steps' reports; a second zernike or pose step's are prefixed with its position (``3.pose.dx_mm``)."""
    out = {}
    zern = [p for p in sorted(reports) if isinstance(reports[p].get("coefficients"), list)]
    pose = [p for p in sorted(reports) if all(isinstance(reports[p].get(k), (int, float))
                                             for k in ("alpha_deg", "beta_deg"))]
    for p in zern:
        prefix = "zernike" if p == zern[-1] else f"{p}.zernike"
        for c in reports[p]["coefficients"]:
            v = c.get("coefficient_nm")
            if isinstance(v, (int, float)) and "j" in c:
                out[f"{prefix}.Z{c['j']}_nm"] = float(v)
    for p in pose:
        prefix = "pose" if p == pose[-1] else f"{p}.pose"
        for key, name in POSE_KEYS:
            v = reports[p].get(key)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                out[f"{prefix}.{name}"] = float(v)
    return out


def all_figures(cloud, reports, plan, extra_figures=None, knot_spacing=None) -> dict:
    from ..metrics.pupil import recipe_centre

    f = summary_figures(cloud, plan.surface, knot_spacing, recipe_centre(p.rs for p in plan.steps))
    f.update(report_figures(reports, plan))
    if extra_figures is not None:
        for k, v in (extra_figures(cloud, plan.surface) or {}).items():
            if isinstance(v, (int, float)) and not isinstance(v, bool) and v is not None:
                f[str(k)] = float(v)
    return f


# -- one sample ----------------------------------------------------------------------------------------

@dataclass
class Job:
    plan: Plan
    cloud: PointCloud  # the nominal input
    sigma: float  # mm
    sources: tuple  # core.uncertainty.spec.Source
    seed: int
    names: list  # figure names, in the order of the returned vector
    extra_figures: object = None
    knot_spacing: float | None = None  # the slope spline's, from the nominal run
    v0: np.ndarray | None = None  # the nominal's residual values (for PV at other noise levels)
    index0: np.ndarray | None = None
    #: extra figures of the extreme kind (an irregularity): evaluated at the LEVELS too, on the
    #: sample's cloud with its residual's change scaled
    extreme_extras: tuple = ()


#: extra noise levels λ (variance λσ² on top of the data's) at which PV is evaluated by scaling each
#: sample's change of the residual by √λ (core.uncertainty.estimate: the extreme-value extrapolation)
LEVELS = (0.5, 2.0)


def residual_values(cloud, surface):
    from ..metrics.pupil import is_flat
    from ..pipeline import remove_piston_tilt

    if "residual" in cloud.channels:
        return np.asarray(cloud["residual"], dtype=np.float64), "the final residual"
    if is_flat(surface) and cloud.n >= 3:
        return remove_piston_tilt(cloud.x, cloud.y, cloud.z), "the heights, piston and tilt removed"
    return np.asarray(cloud.z, dtype=np.float64), "the heights"


def draws(job: Job, i: int):
    """Sample i's standard-normal draws: one per source (in the recipe's order), then one per point."""
    rng = np.random.default_rng(np.random.SeedSequence(job.seed, spawn_key=(i,)))
    zb = rng.standard_normal(len(job.sources))
    zn = rng.standard_normal(job.cloud.n)
    return zb, zn


def perturbed(job: Job, zb, zn):
    """The input cloud with sample draws applied, and the parameter function for run steps."""
    xyz = np.array(job.cloud.xyz)
    xyz[:, 2] += job.sigma * zn
    scale_xy = scale_z = 1.0
    radius_shift = 0.0
    for s, z in zip(job.sources, zb):
        if s.name == "z_scale":
            scale_z *= 1.0 + s.u * z
        elif s.name in ("length_scale", "temperature"):
            f = 1.0 + s.relative * z
            scale_xy *= f
            scale_z *= f
        elif s.name == "probe_radius":
            radius_shift += s.u * z
    if scale_xy != 1.0:
        xyz[:, :2] *= scale_xy
    if scale_z != 1.0:
        xyz[:, 2] *= scale_z
    cloud = PointCloud(xyz, job.cloud.channels, job.cloud.meta, job.cloud.provenance)

    def params_of(rs):
        if radius_shift and rs.id == "probe_radius":
            return rs.params.model_copy(update={"radius": float(rs.params.radius) + radius_shift})
        return None

    return cloud, params_of


def one_sample(job: Job, i: int):
    """(i, figure vector with NaN where a figure is missing, type-B draws, failure message or None)."""
    zb, zn = draws(job, i)
    cloud, params_of = perturbed(job, zb, zn)
    try:
        out, reports = run_plan(job.plan, cloud, params_of)
        f = all_figures(out, reports, job.plan, job.extra_figures, job.knot_spacing)
        if job.v0 is not None and out.n == job.v0.size and np.array_equal(out["index"], job.index0):
            dv = residual_values(out, job.plan.surface)[0] - job.v0
            for lam in LEVELS:
                v = job.v0 + np.sqrt(lam) * dv
                f[f"pv_um@{lam:g}"] = float(np.ptp(v)) * 1e3
                if job.extreme_extras and "residual" in out.channels:
                    more = job.extra_figures(out.replace(channels={"residual": v}), job.plan.surface) or {}
                    for name in job.extreme_extras:
                        if isinstance(more.get(name), (int, float)):
                            f[f"{name}@{lam:g}"] = float(more[name])
    except PointsProError as e:
        return i, np.full(len(job.names), np.nan), zb, str(e).splitlines()[0] if str(e) else type(e).__name__
    return i, np.array([f.get(n, np.nan) for n in job.names], dtype=np.float64), zb, None


# -- many samples, in processes --------------------------------------------------------------------------

_JOB: Job | None = None


#: blocked while the pool forks its workers; each worker unblocks them once it handles them its way
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _worker_init():
    """A worker's own signal handling. It is forked from the batch, whose SIGTERM handler raises
    KeyboardInterrupt (core/cli.py _drain): on the pool's terminate() (which sends SIGTERM) each
    worker printed "Process ForkPoolWorker-1: Traceback … KeyboardInterrupt" before the batch's
    closing line (a review's finding). The parent stops the pool: Ctrl-C (SIGINT, sent to the whole
    process group) is ignored here, and SIGTERM ends the worker at once, silently, as by default.
    Both were blocked while the pool forked (run_samples), so that neither reaches a worker before
    this has run; they are unblocked last."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops the pool
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def _worker_chunk(indices):
    from ..parallel import single_threaded_blas

    # one BLAS thread, held across the chunk: each sample's run_pipeline then nests in it (~3 ms a
    # sample of threadpoolctl's library scan saved)
    with single_threaded_blas():
        return [one_sample(_JOB, i) for i in indices]


def default_workers() -> int:
    from ..parallel import thread_count

    return max(1, thread_count())


def can_fork() -> bool:
    import multiprocessing as mp

    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


def run_samples(job: Job, samples: int, workers: int, progress) -> tuple[int, list]:
    """All samples (ordered by i); returns (workers actually used, results)."""
    global _JOB
    from ..parallel import single_threaded_blas

    workers = max(1, min(workers, samples))
    if workers > 1 and not can_fork():
        workers = 1  # no fork (Windows, macOS' default) or inside a batch's worker: in this process
    results = []
    if workers == 1:
        with single_threaded_blas():
            for i in range(samples):
                progress.check()
                results.append(one_sample(job, i))
                progress.update((i + 1) / samples, f"Monte Carlo sample {i + 1}/{samples}")
        return 1, results
    import multiprocessing as mp

    chunk = max(1, min(8, samples // (workers * 6)))
    chunks = [list(range(a, min(a + chunk, samples))) for a in range(0, samples, chunk)]
    _JOB = job
    ctx = mp.get_context("fork")
    pool = None
    try:
        # the workers (and the pool's threads, which fork replacements) start with SIGINT and SIGTERM
        # blocked: one arriving between a fork and _worker_init waits for the worker's own handling;
        # one arriving here meanwhile is handled by this thread once Pool() has returned
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        try:
            pool = ctx.Pool(workers, initializer=_worker_init)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        for part in pool.imap(_worker_chunk, chunks):
            results.extend(part)
            progress.update(len(results) / samples, f"Monte Carlo sample {len(results)}/{samples}")
        pool.close()
    except BaseException:
        if pool is not None:
            pool.terminate()
        raise
    finally:
        if pool is not None:
            pool.join()
        _JOB = None
    results.sort(key=lambda r: r[0])
    return workers, results


def cpu_count_text() -> str:
    return str(os.cpu_count() or 1)
