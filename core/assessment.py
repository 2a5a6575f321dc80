"""The shop's questions after the steps (docs/uncertainty.md): how sure is each figure — the
recipe's ``uncertainty:`` block, a Monte Carlo through the same steps (core.uncertainty) — and does
the part meet its drawing — the ``tolerance:`` block, ISO 10110-5 quantities decided by the rules of
ISO 14253-1 (core.tolerance). Both land in the summary (``summary.uncertainty``,
``summary.tolerance``) of report.json, report.html, the window and the batch's table.
"""
from __future__ import annotations

import functools

from .metrics.pupil import recipe_centre
from .progress import Progress


def assess(recipe, result, *, progress: Progress | None = None) -> None:
    """Fill ``result.uncertainty`` and ``result.tolerance`` when the recipe asks for them.

    The tolerance's quantities are computed on every Monte Carlo sample too, so each gets its own
    interval; the verdict uses the bias-corrected value and U95 when there is an uncertainty."""
    if recipe.uncertainty is None and recipe.tolerance is None:
        return
    progress = progress or Progress()
    tolerance = recipe.tolerance
    extra = None
    centre = recipe_centre(s for s in recipe.steps if s.enabled)
    if tolerance is not None:  # about the recipe's pupil centre, as the summary (the Monte Carlo's
        extra = functools.partial(tolerance.quantities, centre=centre)  # samples too)
        extra.kinds = tolerance.quantities.kinds
    block = None
    if recipe.uncertainty is not None:
        from .uncertainty import propagate

        result.uncertainty = propagate(recipe, result, extra_figures=extra, progress=progress)
        block = result.uncertainty.block()
    if tolerance is not None:
        values = tolerance.quantities(result.cloud, result.surface, centre)
        result.tolerance = tolerance.decide(values, block)
