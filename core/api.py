"""PointsPro from Python: read a file, run a recipe or one step, look at and write the result.

    import pointspro.core as pp
    cloud = pp.read("resources/example/asphere_cmm.csv")
    result = pp.run("resources/example/recipe.yaml", cloud)
    result.summary["rms_um"]; result.cloud.to_pandas(); result.write("out/example")

The same reader, recipe validation, runner, report and writers as `pointspro --batch` (docs/api.md,
README "From Python"): the numbers are the batch's to the last bit. Errors are the CLI's one-line
`PointsProError`s (a file, line, step or key named); nothing is printed — library warnings met while
running are kept in ``Result.warnings`` and the ``pointspro`` logger has a NullHandler (logging.md's
rule for libraries), so a script decides what to show. No global state: every call builds what it
needs (the step registry is a cheap read of the installed entry points).
"""
from __future__ import annotations

import json
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from .cloud import PointCloud
from .errors import PointsProError, RecipeError
from .progress import CancelToken, Progress
from .recipe import RECIPE_VERSION, Recipe

__all__ = ["read", "write", "run", "step", "steps", "load", "Result", "StepRunner", "StepInfo", "StepCatalog"]

# -- reading and writing a cloud ----------------------------------------------------------------
def read(path, **options) -> PointCloud:
    """The point cloud in ``path``, any supported format, chosen by the file's content (docs/formats.md):
    x, y, z in mm plus every channel. ``options`` are the recipe's ``input:`` reader options
    (``pixel_size_um=``, ``wavelength_nm=``, ``height_unit=``, ``invalid=``…)."""
    from .io import read_cloud

    return read_cloud(path, **options)


def write(cloud: PointCloud, path) -> Path:
    """Write ``cloud`` to ``path`` (.csv: every channel, shortest round-trip decimals, bit-exact when
    read back — but a row with a NaN in any column is dropped on reading, as in any input file: a
    cloud with NaN in a channel keeps every row in .ply; .ply: binary, float64 coordinates, integer
    channels as int/uint or double by range), atomically. Returns the path."""
    from .errors import InputError
    from .io import write_cloud

    path = Path(path)
    if not path.parent.is_dir():  # not a traceback naming the writer's temporary file (a review)
        raise InputError(f"{path}: the folder {path.parent} does not exist")
    write_cloud(_as_cloud(cloud), path)
    return path


# -- running ------------------------------------------------------------------------------------
def load(recipe) -> Recipe:
    """A validated Recipe from a path, a Recipe or a plain mapping (the YAML's content; the format
    version ``pointspro: 1`` may be left out of a mapping written in code)."""
    if isinstance(recipe, Recipe):
        return recipe
    from .recipe import load_recipe, parse_recipe

    if isinstance(recipe, (str, Path)):
        return load_recipe(recipe)
    if isinstance(recipe, Mapping):
        data = {"pointspro": RECIPE_VERSION, **dict(recipe)}
        return parse_recipe(data, "recipe (mapping)")
    raise RecipeError(f"recipe: expected a path, a Recipe or a mapping, got {type(recipe).__name__}")


def run(recipe, cloud, *, progress: bool | Callable[[float, str], None] | None = None,
        cancel=None, allowed_dirs=None) -> "Result":
    """Run ``recipe`` (a path, a Recipe or a mapping) on ``cloud`` (a PointCloud, a Result whose
    cloud goes on, or a file path read with the recipe's ``input:`` options).

    ``progress``: a callable ``(fraction, message)``, or True for a bar (tqdm; a widget in Jupyter).
    ``cancel``: a `CancelToken`, a `threading.Event`, or a callable returning True to stop; the run
    then raises `Cancelled`. ``allowed_dirs``: folders parameter files may lie in besides the
    recipe's (None: any — a script chose its own files). The steps run with one BLAS thread (their
    calls are narrow; spinning BLAS threads beside another busy process made a run 3–4× slower); the
    caller's setting is given back after."""
    from .pipeline import run_pipeline

    rec = load(recipe)
    input_path = digest = None
    if isinstance(cloud, (str, Path)):
        from .batch import input_digest

        input_path = str(cloud)
        read_cloud = read(cloud, **rec.input)
        digest = input_digest(cloud)  # as the batch records it (report.json, --resume)
        cloud = read_cloud
    cloud = _as_cloud(cloud)
    if input_path is None:
        input_path = str(cloud.meta.get("source") or "(in memory)")
    token = _token(cancel)
    with _progress_sink(progress) as sink, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = run_pipeline(cloud, rec, progress=Progress(sink, token), allowed_dirs=allowed_dirs)
    seen: list[str] = []
    for w in caught:
        text = f"{w.category.__name__}: {w.message}"
        if text not in seen:
            seen.append(text)
    return Result(rec, res, input_path, seen, digest)


def _as_cloud(obj) -> PointCloud:
    if isinstance(obj, PointCloud):
        return obj
    if isinstance(obj, Result):
        return obj.cloud
    raise PointsProError(f"expected a PointCloud, a Result or a file path, got {type(obj).__name__} "
                         "(PointCloud.from_numpy / from_pandas make one from arrays)")


class _CallableToken(CancelToken):
    """A CancelToken that also asks ``stop()`` (an Event's is_set, or any callable)."""

    def __init__(self, stop: Callable[[], bool]):
        super().__init__()
        self._stop = stop

    @property
    def cancelled(self) -> bool:
        return super().cancelled or bool(self._stop())


def _token(cancel) -> CancelToken:
    if cancel is None:
        return CancelToken()
    if isinstance(cancel, CancelToken):
        return cancel
    if isinstance(cancel, threading.Event):
        return _CallableToken(cancel.is_set)
    if callable(cancel):
        return _CallableToken(cancel)
    raise PointsProError("cancel: expected a CancelToken, a threading.Event or a callable, got "
                         f"{type(cancel).__name__}")


class _progress_sink:
    """Context manager giving the Progress sink for ``progress=`` (None, a callable or True: a tqdm
    bar in percent, closed at the end whatever happens)."""

    def __init__(self, progress):
        self.progress, self.bar = progress, None

    def __enter__(self):
        if self.progress is True:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=100, unit="%", bar_format="{l_bar}{bar}| {n:.0f}% [{elapsed}<{remaining}]")
            bar = self.bar

            def sink(fraction: float, message: str) -> None:
                bar.n = round(100.0 * fraction, 1)
                if message:
                    bar.set_description_str(message, refresh=False)
                bar.refresh()
            return sink
        if self.progress is None or self.progress is False:
            return None
        if callable(self.progress):
            return self.progress
        raise PointsProError(f"progress: expected True, False, None or a callable, got "
                             f"{type(self.progress).__name__}")

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()
        return False


# -- the result ---------------------------------------------------------------------------------
@dataclass
class Result:
    """What a run gives back: the processed cloud, each step's record, the summary and the report.

    ``summary`` and ``report`` are the dicts `--batch` writes (report.json's content); ``write(out)``
    writes ``out/<stem>/`` exactly as ``pointspro --batch … --out out`` does for this input.

    Attributes besides the properties below: ``recipe`` (the Recipe run), ``input`` (the input's name,
    "(in memory)" for a cloud given in code), ``warnings`` (Python warnings the libraries raised during
    the run, deduplicated; each step's own warnings are in its report) and ``input_sha256`` (the input
    file's SHA-256 as read, report.json's ``input_sha256``; None for a cloud in memory)."""

    recipe: Recipe
    _run: Any = field(repr=False)  # core.pipeline.PipelineResult
    input: str = "(in memory)"
    #: Python warnings raised by the libraries during the run (deduplicated; steps' own warnings are
    #: in each step's report)
    warnings: list = field(default_factory=list)
    #: SHA-256 of the input file as read (None for a cloud given in memory): report.json's input_sha256
    input_sha256: str | None = field(default=None, repr=False)
    _report: dict | None = field(default=None, init=False, repr=False)

    @property
    def cloud(self) -> PointCloud:
        """The cloud after the steps (``residual`` in mm when a step formed one)."""
        return self._run.cloud

    @property
    def input_cloud(self) -> PointCloud:
        """The cloud the steps started from (as read, before any step)."""
        return self._run.input_cloud

    @property
    def steps(self) -> list:
        """Each step's record: id, title, seconds, report (dict), artifacts, points in/out."""
        return self._run.steps

    @property
    def artifacts(self) -> dict:
        """File name → artifact (bytes, text or a writer) of every step, as written by ``write``."""
        return self._run.artifacts

    @property
    def summary(self) -> dict:
        """points in/out, RMS, PV, PVr (µm) and slope RMS (µrad) of the residual, and the pupil —
        report.json's ``summary``."""
        return self.report["summary"]

    @property
    def report(self) -> dict:
        """report.json's content as a dict (built once; plain JSON types)."""
        if self._report is None:
            from .report import build_report, dumps

            self._report = json.loads(dumps(build_report(self.input, self.recipe, self._run)))
        return self._report

    def write(self, out, *, stem: str | None = None, figures: str = "all") -> Path:
        """Write this input's outputs into ``out/<stem>/`` (stem: the input file's name without its
        suffix, else "cloud") as the batch does: cloud.csv, the steps' files, form_error.png,
        report.json, report.html; all or nothing (a temporary folder renamed when complete).
        ``figures``: "all", "summary" or "none". Returns the folder."""
        from .batch import check_output_folder, check_replaceable, write_outputs
        from .report import FIGURE_MODES

        if figures not in FIGURE_MODES:
            raise PointsProError(f"figures: {figures!r} is not one of {', '.join(FIGURE_MODES)}")
        out = Path(out)
        check_output_folder(out)
        if stem is None:
            stem = Path(self.input).stem if self.input != "(in memory)" else "cloud"
        if not stem or Path(stem).name != stem:
            raise PointsProError(f"stem {stem!r} must be a plain folder name")
        folder = out / stem
        own = [Path(self.input)] if self.input != "(in memory)" else []
        check_replaceable(folder, own, self.input)  # never the input, a user's folder or their notes
        write_outputs(folder, self.input, self.recipe, self._run, figures=figures,
                      input_sha256=self.input_sha256)
        return folder

    def __repr__(self) -> str:
        s = self.summary
        ids = [r.id for r in self.steps]
        rms = "" if s.get("rms_um") is None else f", rms_um={s['rms_um']:.6g}, pv_um={s['pv_um']:.6g}"
        return f"Result(input={self.input!r}, steps={ids}, points {s['points_in']} → {s['points_out']}{rms})"

    def _repr_html_(self) -> str:
        from .notebook import result_html

        return result_html(self)


# -- one step on its own ------------------------------------------------------------------------
class StepRunner:
    """One step with validated parameters, callable on a cloud: ``pp.step("knn_denoise",
    window=15, remove="auto")(cloud)`` → a Result. A one-step recipe underneath, so its messages and
    numbers are those of the same step in a recipe."""

    def __init__(self, step_id: str, **params):
        from .recipe import make_step

        self._step = make_step(step_id, params, where=f"pp.step('{step_id}')")
        self.id = step_id

    @property
    def params(self):
        """The validated Params (pydantic model, frozen)."""
        return self._step.params

    def recipe(self, surface: Mapping | None = None) -> Recipe:
        """The one-step recipe this runs (with ``surface`` as its nominal when given)."""
        data: dict = {"pointspro": RECIPE_VERSION,
                      "steps": [{self.id: self.params.model_dump(mode="json", exclude_defaults=True)}]}
        if surface is not None:
            data["surface"] = dict(surface)
        return load(data)

    def __call__(self, cloud, *, surface: Mapping | None = None, progress=None, cancel=None) -> Result:
        """Run on ``cloud`` (PointCloud, Result or path); ``surface``: the nominal as in a recipe's
        ``surface:`` mapping, for the steps that need one."""
        return run(self.recipe(surface), cloud, progress=progress, cancel=cancel)

    def __repr__(self) -> str:
        changed = self.params.model_dump(mode="json", exclude_defaults=True)
        return f"step({self.id!r}" + "".join(f", {k}={v!r}" for k, v in changed.items()) + ")"


def step(step_id: str, **params) -> StepRunner:
    """``step_id`` with ``params`` validated now (RecipeError naming the key), run by calling it."""
    return StepRunner(step_id, **params)


# -- the installed steps ------------------------------------------------------------------------
@dataclass(frozen=True)
class StepInfo:
    """An installed step: id, title, one-line summary, long help, its ``Params`` class (pydantic)
    and the form fields (key, kind, default, unit, bounds, choices, help) read from it."""

    id: str
    title: str
    summary: str
    doc: str
    Params: type
    fields: tuple

    def defaults(self) -> dict:
        """The parameters' defaults (required ones absent)."""
        return {f.key: f.default for f in self.fields if not f.required}

    def __repr__(self) -> str:
        keys = ", ".join(f"{f.key}{' [' + f.unit + ']' if f.unit else ''}" for f in self.fields)
        return f"<step {self.id!r} — {self.title}: {keys}>"


class StepCatalog(dict):
    """id → StepInfo of every installed step, sorted by id; shown as a table in Jupyter."""

    def to_pandas(self):
        """One row per parameter: step, key, kind, default, unit, bounds, choices, help."""
        import pandas as pd

        rows = [{"step": s.id, "key": f.key, "kind": f.widget,
                 "default": "required" if f.required else f.default, "unit": f.unit or "",
                 "bounds": f.bounds_text(), "choices": f.choices, "help": f.help}
                for s in self.values() for f in s.fields]
        return pd.DataFrame(rows, columns=["step", "key", "kind", "default", "unit", "bounds",
                                           "choices", "help"])

    def __repr__(self) -> str:
        return "\n".join(repr(s) for s in self.values())

    def _repr_html_(self) -> str:
        from .notebook import steps_html

        return steps_html(self)


def steps() -> StepCatalog:
    """The installed steps (built-in and third-party, through the ``pointspro.steps`` entry points)."""
    import inspect

    from .forms import form_fields
    from .registry import Registry

    reg = Registry()
    out = StepCatalog()
    for step_id in reg.ids():
        cls = reg.load(step_id)
        out[step_id] = StepInfo(step_id, cls.title, cls.summary or "", inspect.getdoc(cls) or "",
                                cls.Params, tuple(form_fields(cls.Params)))
    return out
