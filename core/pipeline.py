"""The runner: applies a recipe's steps to a cloud with progress, cancellation and timing.

The same runner serves `pointspro --batch`, the window's worker thread and the tests.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from .cloud import PointCloud
from .errors import PointsProError, StepError
from .progress import Progress
from .recipe import Recipe
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

    def to_json(self) -> dict:
        return {"id": self.id, "title": self.title, "seconds": round(self.seconds, 6),
                "points_in": self.points_in, "points_out": self.points_out, "report": self.report,
                "artifacts": sorted(self.artifacts)}


@dataclass
class PipelineResult:
    input_cloud: PointCloud
    cloud: PointCloud
    steps: list[StepRecord] = field(default_factory=list)

    @property
    def artifacts(self) -> dict:
        out = {}
        for rec in self.steps:
            out.update(rec.artifacts)
        return out

    _summary: dict | None = field(default=None, init=False, repr=False)

    def summary(self) -> dict:
        """summarize() of input and output, computed once (PVr and slope RMS fit a map)."""
        if self._summary is None:
            self._summary = summarize(self.input_cloud, self.cloud)
        return dict(self._summary)


def summarize(cloud_in: PointCloud, cloud_out: PointCloud) -> dict:
    """points in/out and, where a residual exists, the optician's metrics over the kept points:
    RMS, PV, PVr (µm) and slope RMS (µrad) — core.metrics.form."""
    from .metrics import form_metrics

    s = {"points_in": cloud_in.n, "points_out": cloud_out.n, "rms_um": None, "pv_um": None,
         "pvr_um": None, "slope_rms_urad": None}
    if "residual" in cloud_out.channels and cloud_out.n:
        s.update(form_metrics(cloud_out.x, cloud_out.y, cloud_out["residual"]))
    return s


def run_pipeline(cloud: PointCloud, recipe: Recipe, *, progress: Progress | None = None,
                 log: logging.Logger | None = None, surface=None, upto: int | None = None,
                 ) -> PipelineResult:
    """Run the recipe's enabled steps (those before position ``upto`` when given).

    Step errors that are the input's fault come back as StepError naming the step; `Cancelled`
    propagates. The input cloud is never modified (its arrays are read-only).
    """
    progress = progress or Progress()
    log = log or logging.getLogger("pointspro")
    if surface is None and recipe.surface_spec is not None:
        surface = recipe.build_surface()
    steps = [s for s in recipe.steps[:upto] if s.enabled]
    result = PipelineResult(cloud, cloud)
    n = max(len(steps), 1)
    current = cloud
    for i, rs in enumerate(steps):
        progress.check()
        sub = progress.sub(i / n, (i + 1) / n)
        ctx = Context(progress=sub, log=log.getChild(rs.id), surface=surface, inputs=recipe.inputs,
                      base_dir=recipe.base_dir)
        sub.update(0.0, rs.step_cls.title)
        t0 = time.perf_counter()
        try:
            out = rs.step_cls().run(current, rs.params, ctx)
        except PointsProError as e:
            raise StepError(f"step {recipe.steps.index(rs) + 1} '{rs.id}': {e}") from e
        seconds = time.perf_counter() - t0
        if not isinstance(out, StepResult) or not isinstance(out.cloud, PointCloud):
            raise TypeError(f"step '{rs.id}' returned {type(out).__name__}, not a StepResult")
        new = out.cloud.with_provenance({"id": rs.id, "params": rs.params.model_dump(mode="json")})
        result.steps.append(StepRecord(rs.id, rs.step_cls.title, seconds, out.report,
                                       dict(out.artifacts), current.n, new.n))
        sub.update(1.0, f"{rs.step_cls.title}: done")
        current = new
    result.cloud = current
    return result
