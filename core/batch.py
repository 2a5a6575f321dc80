"""`pointspro --batch RECIPE INPUT… --out DIR`: the recipe on each input, one output folder each.

For each input: ``DIR/<stem>/cloud.csv`` (with the `index` column), ``report.json``, ``report.html``
and the steps' artifacts, written into a temporary folder that replaces ``DIR/<stem>`` only when
complete. Inputs are never modified. Never starts Qt.
"""
from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .errors import PointsProError, RecipeError
from .io import atomic_dir, read_cloud, write_csv
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


def write_outputs(folder: Path, input_path: str, recipe: Recipe, result) -> dict:
    """Write one input's outputs into ``folder`` atomically (all or nothing): cloud.csv, the steps'
    artifacts, form_error.png, report.json and report.html. Returns the report. Shared by the batch
    and the window's File → Export report."""
    report = build_report(input_path, recipe, result)
    with atomic_dir(folder) as tmp:
        write_csv(result.cloud, tmp / "cloud.csv")
        for name, art in result.artifacts.items():
            write_artifact(tmp, name, art)
        if "residual" in result.cloud.channels and result.cloud.n:
            from .figures import save_png, scattered_map

            c = result.cloud
            save_png(scattered_map(c.x, c.y, c["residual"], title="Form error (residual) after "
                                   "all steps"), tmp / "form_error.png")
        (tmp / "report.json").write_text(dumps(report), encoding="utf-8")
        (tmp / "report.html").write_text(render_html(report, tmp), encoding="utf-8")
    return report


def process_input(path: Path, recipe: Recipe, out_dir: Path, stem: str, *,
                  sink: Callable[[float, str], None] | None = None, token: CancelToken | None = None,
                  surface=None, log: logging.Logger | None = None) -> InputOutcome:
    """Read, run, write one input. PointsProError → a failed outcome; Cancelled propagates."""
    t0 = time.perf_counter()
    try:
        progress = Progress(sink, token)
        cloud = read_cloud(path)
        progress.update(0.05, "read")
        result = run_pipeline(cloud, recipe, progress=progress.sub(0.05, 0.9), surface=surface,
                              log=log)
        report = write_outputs(out_dir / stem, str(path), recipe, result)
        progress.update(1.0, "written")
        return InputOutcome(str(path), True, None, time.perf_counter() - t0, str(out_dir / stem),
                            report["summary"])
    except PointsProError as e:
        msg = str(e)
        if not msg.startswith(str(path)):
            msg = f"{path}: {msg}"
        import traceback

        return InputOutcome(str(path), False, msg, time.perf_counter() - t0,
                            traceback="".join(traceback.format_exception(e)))


def process_job(recipe_path: str, path: str, out_dir: str, stem: str) -> InputOutcome:
    """One input in a worker (process pool or Dask): the recipe is re-read there from its file, so
    only plain strings cross process and machine boundaries."""
    from .recipe import load_recipe

    recipe = load_recipe(recipe_path)
    return process_input(Path(path), recipe, Path(out_dir), stem)


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
