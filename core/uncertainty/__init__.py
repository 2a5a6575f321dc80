"""The uncertainty of every figure by Monte Carlo through the recipe's steps (JCGM 101; issue 23;
docs/uncertainty.md is the reference the code cites).

``parse_uncertainty`` validates the recipe's ``uncertainty:`` block (core.uncertainty.spec);
``propagate(recipe, result)`` runs the samples (core.uncertainty.montecarlo) and turns them into each
figure's bias-corrected value, u, U95 and 95 % interval (core.uncertainty.estimate); the result's
``block()`` is ``summary.uncertainty`` and its ``artifacts()`` are uncertainty.png and
uncertainty_samples.csv.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import PointsProError, RecipeError
from ..progress import Progress
from .spec import COVERAGE, MIN_SAMPLES, Source, UncertaintySpec, parse_uncertainty

__all__ = ["parse_uncertainty", "propagate", "UncertaintySpec", "UncertaintyResult", "Source",
           "MIN_SAMPLES", "COVERAGE"]

#: more failed samples than this fraction fail the input (a fit that diverges on noise this size)
MAX_FAILED = 0.05
SUMMARY_ORDER = ("rms_um", "pv_um", "pvr_um", "slope_rms_urad", "pvr_fit_pv_um", "pvr_rest_rms_um")

NOT_INCLUDED = ("the outlier and aperture decisions (kept as in the nominal run: the interval is conditional "
                "on them); form errors of the nominal surface itself; systematic effects not named as "
                "sources (probe lobing, thermal drift during the scan, a CMM's uncorrected geometry, the "
                "volumetric model's own uncertainty); noise correlated between points")


class UncertaintyResult:
    """The Monte Carlo's outcome: ``block()`` for the summary, ``artifacts()`` for the output folder."""

    def __init__(self, names, f0, samples, draws, entries, meta, sources, budgets):
        self.names = list(names)
        self.nominal = dict(f0)
        self.samples = samples  # (M, K) figure values, NaN where a sample failed
        self.draws = draws  # (M, J) standard-normal type-B draws
        self.entries = entries
        self.meta = meta
        self.sources = tuple(sources)
        self.budgets = budgets

    def block(self) -> dict:
        out = {}
        for name in self.names:
            e = {k: _plain(v) for k, v in self.entries[name].items() if not k.startswith("_")}
            if name in self.budgets:
                e["budget"] = {k: _plain(v) for k, v in self.budgets[name].items()}
            out[name] = e
        out["_meta"] = self.meta
        return out

    def artifacts(self) -> dict:
        from .artifacts import histogram_writer, samples_csv

        return {"uncertainty.png": histogram_writer(self), "uncertainty_samples.csv": samples_csv(self)}


def _plain(v):
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def _ordered(names) -> list[str]:
    first = [n for n in SUMMARY_ORDER if n in names]
    zern = sorted((n for n in names if "zernike." in n), key=lambda n: (n.split(".Z")[0],
                                                                    int(n.split(".Z")[1].split("_")[0])))
    pose = [n for n in names if "pose." in n]
    rest = sorted(n for n in names if n not in first and n not in zern and n not in pose)
    return first + rest + zern + pose


def propagate(recipe, result, *, extra_figures=None, progress: Progress | None = None,
              workers: int | None = None) -> UncertaintyResult:
    """Monte Carlo through the recipe's steps (module doc, docs/uncertainty.md) for ``result`` — the
    pipeline's run of ``recipe`` on ``result.input_cloud``. ``extra_figures(cloud, surface)`` gives
    more figures (the tolerance's quantities) computed on every sample too; it may carry ``kinds``
    (figure → quadratic, extreme, smooth or linear) to say how each is bias-corrected."""
    from . import estimate as est
    from . import montecarlo as mc
    from .noise import MIN_POINTS, estimate_sigma, method_text, sigma_with_uncertainty

    spec: UncertaintySpec = recipe.uncertainty
    if spec is None:
        raise RecipeError("uncertainty: the recipe has no uncertainty: block")
    spec.check_steps(recipe.steps, str(recipe.path or "recipe"))
    progress = progress or Progress()
    t0 = time.perf_counter()
    progress.update(0.0, "uncertainty: the nominal run's plan")
    plan, nominal, reports = mc.make_plan(recipe, result.input_cloud, result.surface,
                                          progress=progress.sub(0.0, 0.08))
    f0 = mc.all_figures(nominal, reports, plan, extra_figures)
    knots = f0.pop("_knot_spacing", None)
    summary = result.summary() if hasattr(result, "summary") else {}
    warnings = []
    for key in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad"):
        a, b = summary.get(key), f0.get(key)
        if a is not None and b is not None and abs(a - b) > 1e-9 * max(abs(a), 1e-12):
            warnings.append(f"the re-run's {key} ({b:.6g}) differs from the pipeline's ({a:.6g}): a step is "
                            "not deterministic; the samples are about the re-run")
    if not f0:
        raise PointsProError("uncertainty: the steps leave no figure to give an uncertainty for (no residual "
                             "and no nominal; nothing in the summary)")
    if spec.noise is None:
        v, of = mc.residual_values(nominal, plan.surface)
        sigma, u_rel = sigma_with_uncertainty(nominal.x, nominal.y, v)
        noise_from = f"auto: {method_text()} ({of}); relative standard uncertainty {100 * u_rel:.2g} %"
    else:
        sigma, u_rel = spec.noise, 0.0
        noise_from = f"given in the recipe ({spec.noise_text}), taken as exact"
        v, of = mc.residual_values(nominal, plan.surface)
        spread = float(np.std(v)) if v.size > 1 else float("nan")
        if sigma > 1.5 * spread:  # the residual holds its noise: RMS² ≈ form² + σ² ≥ σ²
            from ..units import format_length

            warnings.append(f"the given noise σ {format_length(sigma)} exceeds the spread of {of} "
                            f"({format_length(spread)}), which holds that noise: check its unit — the "
                            "figures are then mostly noise bias")
        # the data's own σ for the check below, where there are points enough to estimate it (a
        # review: a given noise with 9–29 points failed on estimate_sigma's own minimum)
        seen = estimate_sigma(nominal.x, nominal.y, v) if v.size >= MIN_POINTS else 0.0
        if seen > 0 and sigma < 0.1 * seen:
            # a review: "1e-9 nm" gave U95 7e-13 µm and "conforms", no bias removed, with ~0.3 µm of
            # noise in the data (as estimated for noise: auto, which reads form at the neighbours'
            # scale as noise too — so a warning, not a refusal)
            from ..units import format_length

            warnings.append(f"the given noise σ {format_length(sigma)} is below a tenth of what {of} shows "
                            f"between neighbouring points ({format_length(seen)}, as noise: auto would "
                            "take it): check its unit — U95 and the bias correction are then too small")
    names = _ordered(list(f0))
    kinds = getattr(extra_figures, "kinds", None)
    extreme = [n for n in names if est.kind_of(n, kinds) == "extreme"]
    levels = [f"{n}@{lam:g}" for n in extreme for lam in mc.LEVELS]
    v0 = mc.residual_values(nominal, plan.surface)[0] if levels else None
    job = mc.Job(plan, result.input_cloud, sigma, spec.sources, spec.seed, names + levels, extra_figures,
                 knots, v0, nominal["index"], tuple(n for n in extreme if n != "pv_um"))
    w = workers or spec.workers or mc.default_workers()
    used, results = mc.run_samples(job, spec.samples, w, progress.sub(0.08, 0.97))
    S = np.array([r[1] for r in results])
    Z = np.array([r[2] for r in results]).reshape(len(results), len(spec.sources))
    failed = [r[3] for r in results if r[3] is not None]
    if len(failed) > MAX_FAILED * spec.samples:
        raise PointsProError(f"uncertainty: {len(failed)} of {spec.samples} Monte Carlo samples failed (first: "
                             f"{failed[0]}); the steps are not stable under noise of σ = {sigma * 1e6:.3g} nm")
    entries, budgets = {}, {}
    src_names = [s.name for s in spec.sources]
    for name in sorted(names, key=lambda n: n == "pvr_um"):  # PVr after its two parts
        j = names.index(name)
        kind = est.kind_of(name, kinds)
        parts = None
        if kind == "pvr":
            if "pvr_fit_pv_um" in entries and "pvr_rest_rms_um" in entries:
                parts = {"fit": entries["pvr_fit_pv_um"], "rest": entries["pvr_rest_rms_um"]}
            else:
                kind = "extreme"
        if kind == "extreme":
            cols = {lam: job.names.index(f"{name}@{lam:g}") for lam in mc.LEVELS}
            parts = {lam: S[:, c] for lam, c in cols.items()}
            if not all(np.isfinite(v).any() for v in parts.values()):
                parts = None  # no levels (the rows changed): the fixed extrapolant
        entries[name] = est.estimate(name, kind, f0[name], S[:, j], Z, parts, u_rel)
        if src_names or name in SUMMARY_ORDER or kinds and name in kinds:  # each source's share
            e = entries[name]  # the shares of its u: of the samples placed about the value
            budgets[name] = est.budget(e["_placed"], Z[np.isfinite(S[:, j])], src_names, e["_se"])
    for key in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad"):
        if key in entries and summary.get(key) is not None:
            entries[key]["measured"] = summary[key]
    seconds = time.perf_counter() - t0
    meta = {
        "method": "Monte Carlo through the recipe's steps (JCGM 101), parametric bootstrap; noise bias "
                  "removed per figure (docs/uncertainty.md)",
        "samples": spec.samples, "samples_failed": len(failed), "seed": spec.seed, "workers": used,
        "same_for_any_workers": True, "coverage_probability": COVERAGE,
        "noise_sigma_um": sigma * 1e3, "noise_sigma_u_rel": u_rel, "noise_from": noise_from,
        "noise_axis": "z of the input (the instrument's measuring axis), independent N(0, σ²) per point",
        "sources": {s.name: _source_meta(s) for s in spec.sources},
        "reuse": plan.reuse_text(),
        "not_included": NOT_INCLUDED,
        "seconds": round(seconds, 3),
    }
    if failed:
        meta["first_failure"] = failed[0]
    if warnings:
        meta["warnings"] = warnings
    progress.update(1.0, f"uncertainty: {spec.samples} samples in {seconds:.1f} s")
    return UncertaintyResult(names, f0, S, Z, entries, meta, spec.sources, budgets)


def _source_meta(s: Source) -> dict:
    if s.name == "probe_radius":
        return {"u": s.text, "acts_on": "the probe_radius step's ball radius"}
    if s.name == "z_scale":
        return {"u": s.text, "acts_on": "z·(1 + ε) of the input (about the machine's z = 0)"}
    if s.name == "length_scale":
        return {"u": s.text, "acts_on": "x, y, z·(1 + ε) of the input"}
    return {"u": s.text, "cte": s.cte_text, "acts_on": "x, y, z·(1 + α·ΔT) of the input",
            "relative_u_ppm": s.relative * 1e6}
