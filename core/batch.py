"""`pointspro --batch RECIPE INPUT… --out DIR`: the recipe on each input, one output folder each.

For each input: ``DIR/<stem>/cloud.csv`` (with the `index` column), ``report.json``, ``report.html``
and the steps' artifacts, written into a temporary folder that replaces ``DIR/<stem>`` only when
complete. Inputs are never modified. Never starts Qt.
"""
from __future__ import annotations

import functools
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .errors import Cancelled, PointsProError, RecipeError
from .io import atomic_dir, read_cloud, write_csv
from .io.background import BackgroundWrite
from .pipeline import run_pipeline
from .progress import CancelToken, Progress
from .recipe import Recipe
from .report import build_report, dumps, render_html


@dataclass
class InputOutcome:
    input: str
    ok: bool
    error: str | None = None
    seconds: float = 0.0
    out_dir: str | None = None
    summary: dict | None = None
    traceback: str | None = field(default=None, repr=False)


def check_output_folder(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise RecipeError(f"{out}: the output path exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RecipeError(f"{out}: cannot create the output folder ({e.strerror or e})") from None
    if not out.is_dir():
        raise RecipeError(f"{out}: the output path exists and is not a folder")
    if not os.access(out, os.W_OK | os.X_OK):
        raise RecipeError(f"{out}: output folder is not writable")


def output_stems(inputs: list[Path]) -> list[str]:
    stems = [p.stem for p in inputs]
    seen: dict[str, Path] = {}
    for p, s in zip(inputs, stems):
        if s in seen:
            raise RecipeError(f"{seen[s]} and {p} would both write {s}/ in the output folder; "
                              "rename one or run them separately")
        seen[s] = p
    return stems


def write_artifact(folder: Path, name: str, art) -> None:
    target = folder / name
    if Path(name).name != name:
        raise ValueError(f"artifact name {name!r} must be a plain file name")
    if callable(art):
        art(target)
    elif isinstance(art, bytes):
        target.write_bytes(art)
    else:
        target.write_text(str(art), encoding="utf-8")


def write_outputs(folder: Path, input_path: str, recipe: Recipe, result, *, figures: str = "all",
                  timings: dict | None = None, fork_csv: bool = False) -> dict:
    """Write one input's outputs into ``folder`` atomically (all or nothing): cloud.csv, the steps'
    artifacts, form_error.png, report.json and report.html. Returns the report. Shared by the batch
    and the window's File → Export report. ``figures``: "all", "summary" (form_error.png only) or
    "none" — the report says which were not drawn. ``timings``, when given, receives the seconds
    spent on each file (benchmarks/bench_input.py's stage table). ``fork_csv``: cloud.csv may be
    written by a forked process while the figures are drawn (core/io/background.py) — only the
    batch's own single-threaded process asks for it."""
    from .report import SUMMARY_FIGURE, skipped_figures

    timings = {} if timings is None else timings
    has_map = "residual" in result.cloud.channels and result.cloud.n
    skipped = skipped_figures([*result.artifacts, *([SUMMARY_FIGURE] if has_map else [])], figures)

    def timed(name, write):
        t0 = time.perf_counter()
        write()
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0

    t0 = time.perf_counter()
    report = build_report(input_path, recipe, result, figures, skipped)
    timings["report (summary)"] = time.perf_counter() - t0
    with atomic_dir(folder) as tmp:
        # cloud.csv is formatted in a forked process while the figures are drawn, where a core is
        # free (core/io/background.py); else here. Either way it is complete before the rename.
        t1 = time.perf_counter()
        csv = BackgroundWrite(write_csv, result.cloud, tmp / "cloud.csv", what=f"{folder.name}/cloud.csv",
                              fork=fork_csv)
        timings["cloud.csv" + (" (started in a forked process)" if csv.forked else "")] = \
            time.perf_counter() - t1
        try:
            for name, art in result.artifacts.items():
                if name not in skipped:
                    timed(name, lambda: write_artifact(tmp, name, art))
            if has_map and SUMMARY_FIGURE not in skipped:
                from .figures import save_png, scattered_map

                c = result.cloud
                timed("form_error.png", lambda: save_png(scattered_map(
                    c.x, c.y, c["residual"], title="Form error (residual) after all steps"),
                    tmp / SUMMARY_FIGURE))
            timed("report.json", lambda: (tmp / "report.json").write_text(dumps(report),
                                                                           encoding="utf-8"))
            timed("report.html", lambda: (tmp / "report.html").write_text(render_html(report, tmp),
                                                                           encoding="utf-8"))
            if csv.forked:
                timed("cloud.csv (waiting for the forked writer)", csv.wait)
        finally:
            csv.cancel()  # only if still running: an error above; the folder is then removed
    return report


def process_input(path: Path, recipe: Recipe, out_dir: Path, stem: str, *,
                  sink: Callable[[float, str], None] | None = None, token: CancelToken | None = None,
                  surface=None, log: logging.Logger | None = None,
                  allowed_dirs=None, figures: str = "all", fork_csv: bool = False) -> InputOutcome:
    """Read, run, write one input. Any exception but Cancelled → a failed outcome for this input
    alone (one line naming the input and the step or stage; the traceback kept for summary.json and
    --debug); Cancelled propagates."""
    t0 = time.perf_counter()
    stage = "reading"
    try:
        progress = Progress(sink, token)
        cloud = read_cloud(path, **recipe.input)  # the recipe's `input:` reader options
        progress.update(0.05, "read")
        stage = "running the steps"
        result = run_pipeline(cloud, recipe, progress=progress.sub(0.05, 0.9), surface=surface,
                              log=log, allowed_dirs=allowed_dirs)
        stage = "writing the outputs"
        report = write_outputs(out_dir / stem, str(path), recipe, result, figures=figures,
                               fork_csv=fork_csv)
        progress.update(1.0, "written")
        return InputOutcome(str(path), True, None, time.perf_counter() - t0, str(out_dir / stem),
                            report["summary"])
    except Cancelled:
        raise
    except Exception as e:  # noqa: BLE001 — isolation is the point: one bug must not sink the night
        return failed_outcome(str(path), stage, e, time.perf_counter() - t0)


def failed_outcome(path: str, stage: str, e: BaseException, seconds: float = 0.0) -> InputOutcome:
    """The outcome of an input that failed with ``e`` while ``stage``: a PointsProError's own line, or
    "internal error … — please report" for a bug; prefixed with the input; traceback kept."""
    import traceback

    from .pipeline import internal_message

    if isinstance(e, PointsProError):
        msg = str(e)
    elif isinstance(e, OSError):  # the machine, not a bug: disk full, permissions, a lost share
        where = f" {e.filename}" if getattr(e, "filename", None) else ""
        msg = f"{stage}:{where} {e.strerror or e}"
    else:
        msg = internal_message(stage, e)
    if not msg.startswith(path):
        msg = f"{path}: {msg}"
    return InputOutcome(path, False, msg, seconds, traceback="".join(traceback.format_exception(e)))


def process_job(recipe_path: str, path: str, out_dir: str, stem: str,
                allowed_dirs: list[str] | None = None, figures: str = "all") -> InputOutcome:
    """One input in a worker (process pool or Dask): the recipe is read there from its file, so
    only plain strings cross process and machine boundaries — once per worker and recipe version
    (``worker_recipe``), not once per input."""
    try:
        st = os.stat(recipe_path)
        recipe, surface = worker_recipe(recipe_path, st.st_mtime_ns, st.st_size)
    except Exception as e:  # noqa: BLE001 — e.g. the recipe changed or vanished since the start
        return failed_outcome(path, "reading the recipe in the worker", e)
    return process_input(Path(path), recipe, Path(out_dir), stem, surface=surface, figures=figures,
                         allowed_dirs=None if allowed_dirs is None else [Path(d) for d in allowed_dirs])


@functools.lru_cache(maxsize=4)
def worker_recipe(recipe_path: str, mtime_ns: int, size: int):
    """(Recipe, nominal surface) of a recipe file, parsed and built once per worker process for a
    given version of the file (its modification time and size are part of the key, so an edited
    recipe is read again). A cache, not state: the same key always gives the same recipe, and the
    steps never modify either (a step's Params are frozen; surfaces are immutable)."""
    from .recipe import load_recipe

    recipe = load_recipe(recipe_path)
    return recipe, (recipe.build_surface() if recipe.surface_spec is not None else None)


def cleanup_partials(out_dir: Path) -> list[str]:
    """Remove what an interrupted run leaves: temporary output folders and files (``.*.partial``) and
    folders set aside while being replaced (``.*.old``). Returns what was removed."""
    import shutil

    gone = []
    for p in sorted(Path(out_dir).glob(".*")):
        if p.name.endswith((".partial", ".old")):
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            gone.append(p.name)
    return gone


def is_complete(out_dir: Path, stem: str, path: Path, recipe: Recipe) -> dict | None:
    """The report of a complete earlier output of this input with this recipe, else None.

    Output folders appear only when complete (atomic rename); the report must also name the same
    input and the same recipe (every parameter), so a changed recipe is run again."""
    import json

    folder = Path(out_dir) / stem
    rep = folder / "report.json"
    if not (rep.is_file() and (folder / "cloud.csv").is_file()):
        return None
    try:
        data = json.loads(rep.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    from .report import jsonable

    if data.get("input") != str(path) or data.get("recipe") != jsonable(recipe.to_dict(full=True)):
        return None
    return data
