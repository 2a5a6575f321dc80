"""`pointspro --batch RECIPE INPUT… --out DIR`: the recipe on each input, one output folder each.

For each input: ``DIR/<stem>/cloud.csv`` (with the `index` column; ``cloud.ply`` or ``cloud.npz``
with ``--cloud-format``), ``report.json``, ``report.html`` and the steps' artifacts, written into a
temporary folder that replaces ``DIR/<stem>`` only when complete. Inputs are never modified. Never
starts Qt.

``--set STEP.KEY=VALUE`` overrides (``load_batch_recipe``) are applied to the recipe's YAML before
it is validated, in this process and in every worker, and listed in report.json's ``overrides``.
The steps' log records (``ctx.log``, loggers ``pointspro.<step id>``) carry the input's name
(``record.input``); a worker returns its records with its outcome for the parent to show.
"""
from __future__ import annotations

import contextvars
import functools
import logging
import os
import re
import time
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .errors import Cancelled, PointsProError, RecipeError
from .io import atomic_dir, read_cloud, write_csv
from .io.atomic import InputPlaces, naming_errors, why_not_replace
from .io.background import BackgroundWrite, share_out
from .io.formats import write_ply_cloud
from .io.npz import write_npz_cloud
from .parallel import single_threaded_blas, thread_count
from .pathnames import resolved
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
    #: the log records of a worker (plain dicts, ``logging.makeLogRecord``'s input), for the parent
    log: list = field(default_factory=list, repr=False)
    #: the steps' warnings ("'aperture': it removed 61 % of the points …"), which the command prints
    #: beside the input's line — in report.json alone nobody reads them (a review)
    warnings: list = field(default_factory=list)


#: what ``--cloud-format`` may name: the processed cloud is written as ``cloud.<format>``; "auto"
#: (the default): cloud.x3p when the input was a regular grid of pixels and the points still lie on
#: it (core.io.gridcloud: the map stays a map), else cloud.csv — the report says which and why
CLOUD_FORMATS = ("csv", "ply", "npz", "x3p")


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


#: the longest file name the usual file systems take (ext4, XFS, APFS, NTFS: 255 bytes or units)
NAME_MAX = 255
#: what an output folder's temporary name adds to the input's stem: "." + ".xxxxxxxx" + ".partial"
_LONGEST_STEM_EXTRA = len(".") + len(".0123abcd") + len(".partial")
_LONGEST_STEM = NAME_MAX - _LONGEST_STEM_EXTRA


def output_stems(inputs: list[Path]) -> list[str]:
    stems = [p.stem for p in inputs]
    seen: dict[str, Path] = {}
    for p, s in zip(inputs, stems):
        if s.strip(".") == "":
            # "..csv" has the stem ".": its outputs would replace the output folder itself (a review)
            raise RecipeError(f"{p}: its name gives no output folder name ('{s}/' is a path, not a "
                              "folder of its own); rename the input")
        if len(s.encode("utf-8", "surrogateescape")) > _LONGEST_STEM:
            # the folder is written as ".<name>.<8 hex>.partial" first (core/io/atomic.py): a 240-byte
            # name ran the whole pipeline and then failed "File name too long" (a review)
            raise RecipeError(f"{p}: its name is {len(s.encode('utf-8', 'surrogateescape'))} bytes long; "
                              f"its output folder is written under a temporary name {_LONGEST_STEM_EXTRA} "
                              f"bytes longer, beyond the {NAME_MAX}-byte limit of a file name — rename the "
                              f"input (at most {_LONGEST_STEM} bytes before the extension)")
        if s in seen:
            raise RecipeError(f"{seen[s]} and {p} would both write {s}/ in the output folder; "
                              "rename one or run them separately")
        seen[s] = p
    return stems


#: the files a batch writes at the top of its output folder, beside the inputs' folders
BATCH_FILES = ("summary.json",)


#: the file a batch holds locked (``fcntl.flock``) in its output folder while it writes there
LOCK_FILE = ".pointspro.lock"


class BatchLock:
    """The output folder held by one batch (``lock_output_folder``); ``release()`` (idempotent) gives
    it up and removes the lock file."""

    def __init__(self, path: Path, fd: int | None):
        self.path, self.fd = path, fd
        if fd is not None:
            _HELD.add(self)

    @property
    def held(self) -> bool:
        return self.fd is not None

    def release(self) -> None:
        fd, self.fd = self.fd, None
        _HELD.discard(self)
        if fd is None:
            return
        try:  # removed while still locked, and only if it is still ours (see lock_output_folder)
            if os.path.samestat(os.fstat(fd), os.stat(self.path)):
                os.unlink(self.path)
        except OSError:
            pass
        finally:
            os.close(fd)  # the lock goes with the last descriptor


#: the locks this process holds: a forked child (a writer, a Monte Carlo worker) closes its copies at
#: once — closing a copy never releases the parent's lock, and a child left behind by a batch killed
#: with SIGKILL would otherwise hold it on, refusing the next batch
_HELD: "weakref.WeakSet[BatchLock]" = weakref.WeakSet()


def _close_in_child() -> None:
    for lock in list(_HELD):
        fd, lock.fd = lock.fd, None
        try:
            os.close(fd)
        except OSError:
            pass
    _HELD.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_in_child)


def lock_output_folder(out: Path) -> BatchLock:
    """Hold the output folder ``out`` for this batch: an exclusive, non-blocking ``flock`` on
    ``out/.pointspro.lock`` (LOCK_FILE), with this process's id written in it. A second batch writing
    the same folder is refused — RecipeError naming the folder — before it removes or writes anything:
    two batches sharing one --out deleted each other's temporary folders (cleanup_partials, then of
    every name) and the last to end overwrote the other's summary.json (a review).

    Held by the batch's own process only, for the whole batch: its pool's workers are spawned and
    Dask's run elsewhere (neither inherits the descriptor, opened close-on-exec) and never ask for
    it; a forked child closes its copy at once (``_close_in_child``). The system releases the lock when
    the process ends, however it ends (SIGKILL too), so a lock file left behind blocks nothing; a
    batch that ends removes it (``BatchLock.release``). A file system without locks (ENOLCK: NFS
    without its lock daemon): the batch goes on unlocked."""
    import fcntl

    path = Path(out) / LOCK_FILE
    for _ in range(100):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        except PermissionError:  # left by another user's batch that was killed: locking reads it
            fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _lock_holder(fd)
            os.close(fd)
            raise RecipeError(f"{out}: another batch is writing this output folder{holder}; wait for it "
                              "to end or choose another --out") from None
        except OSError:
            os.close(fd)
            return BatchLock(path, None)
        # the file locked is still the one at the path: a batch that ended meanwhile removed its own
        # after this one opened it, and a third may have made a new one
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            try:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode("ascii"))
            except OSError:  # opened read-only: the lock holds all the same
                pass
            return BatchLock(path, fd)
        os.close(fd)
    raise RecipeError(f"{out}: cannot lock the output folder ({path} keeps being replaced)")


def batch_running(out: Path) -> str | None:
    """The line saying that another batch is writing the output folder ``out`` now (its lock is held),
    else None; creates nothing (for --check-only)."""
    import fcntl

    try:
        fd = os.open(Path(out) / LOCK_FILE, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # released at once, with the descriptor
    except BlockingIOError:
        return f"{out}: another batch is writing this output folder{_lock_holder(fd)}"
    except OSError:
        return None
    finally:
        os.close(fd)
    return None


def _lock_holder(fd: int) -> str:
    """" (process 1234)", the id a lock file's holder wrote in it, or ""."""
    try:
        text = os.pread(fd, 32, 0).decode("ascii").strip()
    except (OSError, UnicodeDecodeError):
        return ""
    return f" (process {text})" if text.isdigit() else ""


def check_output_targets(out: Path, inputs: list[Path], stems: list[str], resume: bool = False) -> None:
    """Refuse, before anything is written, a batch whose outputs would destroy what is not its own:
    an input's folder ``out/<stem>`` replaces a folder as a whole, so it must not hold an input, be
    a file, or be a folder that is not a PointsPro output (no report.json; an empty one is fine);
    no input may be named like the batch's own files (``summary.json``) or be one of them, and an
    existing summary.json must be a batch's. Measured before this check: an input o/part/part.csv
    with --out o was deleted with its folder, an input o/summary.json overwritten by the summary, a
    folder o/<stem> of the user's notes replaced — all with exit status 0. With ``resume`` a file added
    to an earlier output's folder is checked later, for the inputs --resume runs again
    (cli._plan_jobs): a skipped input's folder stays as it is, notes and all."""
    import json

    out_r = resolved(out)
    ins = [resolved(p) for p in inputs]
    for name in BATCH_FILES:
        target = out_r / name
        for p, pr in zip(inputs, ins):
            if pr == target:
                raise RecipeError(f"{p}: is the batch's own {out / name}, which the batch writes; "
                                  "copy the input elsewhere or choose another --out")
        if target.exists():
            try:
                ours = target.is_file() and "inputs" in json.loads(target.read_text(encoding="utf-8"))
            except (OSError, ValueError, TypeError):
                ours = False
            if not ours:
                raise RecipeError(f"{out / name}: exists and is not a PointsPro batch summary; the batch "
                                  "would replace it — move it or choose another --out")
    places = InputPlaces(inputs)  # resolved once, not once per output folder (N², issue 17)
    for p, stem in zip(inputs, stems):
        if stem in BATCH_FILES:
            raise RecipeError(f"{p}: its output folder would be the batch's own {out / stem}; rename "
                              "the input")
        check_replaceable(out / stem, places, p, extra=not resume)


def check_replaceable(folder: Path, inputs, of, extra: bool = True) -> None:
    """Refuse (RecipeError) writing the output of ``of`` into ``folder``, which write_outputs replaces
    as a whole, when that would destroy what is not an earlier output of ours: an input inside it, a
    file, a folder of other files, or an earlier output's folder holding a file it did not write
    (a user's notes). Shared by the batch, ``Result.write`` (which deleted such a folder, and the
    input inside it, with no word — a review) and the window's Export report."""
    why = why_not_replace(folder, "report.json", inputs)
    if why is None:
        return
    if why[0] == "input":
        raise RecipeError(f"{why[1]}: lies in {folder}, the output folder of {of}, which is replaced as a "
                          "whole; copy the input elsewhere or choose another output folder")
    if why[0] == "file":
        raise RecipeError(f"{folder}: exists and is not a folder; the output of {of} would go there — "
                          "move it or choose another output folder")
    if why[0] == "extra":
        if not extra:
            return  # --resume: checked again for the inputs it runs (a skipped one's folder stays as it is)
        raise RecipeError(f"{folder / why[1].name}: is not one of the files of the earlier output in "
                          f"{folder}, which is replaced as a whole with the output of {of} — move it or "
                          "choose another output folder")
    raise RecipeError(f"{folder}: exists and is not a PointsPro output folder (no report.json that PointsPro wrote); it would "
                      f"be replaced with the output of {of} — move it or choose another output folder")


def write_artifact(folder: Path, name: str, art) -> None:
    target = folder / name
    if Path(name).name != name:
        raise ValueError(f"artifact name {name!r} must be a plain file name")
    with naming_errors(target):  # a full disk names the file (a review)
        if callable(art):
            art(target)
        elif isinstance(art, bytes):
            target.write_bytes(art)
        else:
            target.write_text(str(art), encoding="utf-8")


def write_outputs(folder: Path, input_path: str, recipe: Recipe, result, *, figures: str = "all",
                  timings: dict | None = None, fork_csv: bool = False, cloud_format: str = "auto",
                  overrides=(), paths=None, input_sha256: str | None = None,
                  file_sha256: dict | None = None, input_abspath: str | None = None) -> dict:
    """Write one input's outputs into ``folder`` atomically (all or nothing): cloud.csv, the steps'
    artifacts, form_error.png, report.json and report.html. Returns the report. Shared by the batch
    and the window's File → Export report. ``figures``: "all", "summary" (form_error.png only) or
    "none" — the report says which were not drawn. ``timings``, when given, receives the seconds
    spent on each file (benchmarks/bench_input.py's stage table). ``fork_csv``: cloud.csv may be
    written by a forked process while the figures are drawn (core/io/background.py) — only the
    batch's own single-threaded process asks for it. ``cloud_format``: csv, ply (binary float64)
    or npz — the cloud is ``cloud.<format>``, named in report.json's ``cloud_file``. ``overrides``:
    the ``--set`` texts the recipe was run with, listed in report.json's ``overrides``. ``paths``: a
    ``cluster.PathMap`` that names a worker's private files as the client does, in the report.
    ``input_sha256``: the input file's digest (``input_digest``), ``file_sha256`` those of the files the
    recipe names (``parameter_file_digests``), recorded for ``--resume``, as is ``input_abspath``, the
    input's absolute path on the machine that ran the batch where ``input_path`` (as the user typed
    it, report.json's ``input``) is not that already. BLAS
    runs one thread meanwhile (core.parallel.single_threaded_blas), as in the batch."""
    with single_threaded_blas():
        return _write_outputs(folder, input_path, recipe, result, figures=figures, timings=timings,
                              fork_csv=fork_csv, cloud_format=cloud_format, overrides=overrides,
                              paths=paths, input_sha256=input_sha256, file_sha256=file_sha256,
                              input_abspath=input_abspath)


def _write_outputs(folder, input_path, recipe, result, *, figures, timings, fork_csv, cloud_format,
                   overrides, paths, input_sha256, file_sha256, input_abspath) -> dict:
    from .io.gridcloud import grid_channel, grid_of, write_x3p_cloud
    from .report import SUMMARY_FIGURE, skipped_figures

    if cloud_format not in (*CLOUD_FORMATS, "auto"):
        raise ValueError(f"cloud format {cloud_format!r} is not one of {', '.join(CLOUD_FORMATS)}")
    asked = cloud_format
    grid, why = grid_of(result.cloud) if cloud_format in ("auto", "x3p") else (None, "")
    if cloud_format == "auto":
        cloud_format = "x3p" if grid is not None else "csv"
    elif cloud_format == "x3p" and grid is None:
        raise PointsProError(f"--cloud-format x3p: {why}; use csv, ply or npz")
    cloud_name = f"cloud.{cloud_format}"

    timings = {} if timings is None else timings
    has_map = "residual" in result.cloud.channels and result.cloud.n
    skipped = skipped_figures([*result.artifacts, *([SUMMARY_FIGURE] if has_map else [])], figures)

    def timed(name, write):
        t0 = time.perf_counter()
        with naming_errors(folder / name):
            write()
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0

    t0 = time.perf_counter()
    report = build_report(input_path, recipe, result, figures, skipped)
    if paths is not None:
        report = paths.deep(report)
    timings["report (summary)"] = time.perf_counter() - t0
    report["cloud_file"] = cloud_name
    report["cloud_format_asked"] = asked
    if cloud_format == "x3p":
        report["cloud_file_note"] = (f"{why}: cloud.x3p holds the {grid_channel(result.cloud)} on that "
                                     "grid (metres, NaN where no point); --cloud-format csv writes "
                                     "every channel as text")
    elif asked == "auto":
        report["cloud_file_note"] = f"cloud.csv: {why}"
    else:  # every report says why its cloud file is what it is (a review: the key was missing here)
        report["cloud_file_note"] = f"{cloud_name}: asked by --cloud-format {asked}"
    if overrides:
        report["overrides"] = [str(o) for o in overrides]
    if input_sha256 is not None:  # --resume reruns an input whose content changed (is_complete)
        report["input_sha256"] = input_sha256
    if input_abspath is not None and input_abspath != str(input_path):
        # … and knows it named otherwise (relative, then absolute: same_input); an input named by its
        # absolute path already says where it is
        report["input_abspath"] = input_abspath
    if file_sha256:  # … or one of the recipe's files changed (calibration, model, mesh)
        report["parameter_files_sha256"] = file_sha256
    writer = {"csv": write_csv, "ply": write_ply_cloud, "npz": write_npz_cloud,
              "x3p": lambda c, path: write_x3p_cloud(path, c, grid)}[cloud_format]
    with atomic_dir(folder) as tmp:
        # cloud.csv is formatted in a forked process while the figures are drawn, where a core is
        # free (core/io/background.py); else here. Either way it is complete before the rename.
        # The binary formats (ply, npz) are a memory copy: written here.
        t1 = time.perf_counter()
        csv = BackgroundWrite(writer, result.cloud, tmp / cloud_name, what=f"{folder.name}/{cloud_name}",
                              fork=fork_csv and cloud_format in ("csv", "x3p"))
        timings[cloud_name + (" (started in a forked process)" if csv.forked else "")] = \
            time.perf_counter() - t1
        try:
            tasks = [(name, functools.partial(write_artifact, tmp, name, art))
                     for name, art in result.artifacts.items() if name not in skipped]
            if has_map and SUMMARY_FIGURE not in skipped:
                tasks.append((SUMMARY_FIGURE, functools.partial(_summary_figure, result.cloud, tmp / SUMMARY_FIGURE)))
            # the figures (and the steps' other files) shared between this process and forked ones
            # where cores are free (core/io/background.py share_out); in list order otherwise
            workers = thread_count() if fork_csv else 1
            if workers > 1 and len(tasks) > 1 and any(name.endswith(".png") for name, _ in tasks):
                # (not for --figures none: matplotlib's load is ~0.2 s of a process's start)
                from .figures import preload

                timed("matplotlib loaded before the figure processes fork", preload)
            for name, s in share_out(tasks, workers=workers, fork=fork_csv).items():
                timings[name] = timings.get(name, 0.0) + s
            # every file of the folder, which --resume checks are all still there (is_complete)
            report["files"] = sorted({cloud_name, *(name for name, _ in tasks), "report.json", "report.html"})
            timed("report.json", lambda: (tmp / "report.json").write_text(dumps(report),
                                                                           encoding="utf-8"))
            timed("report.html", lambda: (tmp / "report.html").write_text(render_html(report, tmp),
                                                                           encoding="utf-8"))
            if csv.forked:
                timed(f"{cloud_name} (waiting for the forked writer)", csv.wait)
        finally:
            csv.cancel()  # only if still running: an error above; the folder is then removed
    return report


def _summary_figure(cloud, path: Path) -> None:
    from .figures import save_png, scattered_map

    save_png(scattered_map(cloud.x, cloud.y, cloud["residual"],
                           title="Form error (residual) after all steps",
                           pixel_mm=cloud.meta.get("pixel_mm")), path)


def process_input(path: Path, recipe: Recipe, out_dir: Path, stem: str, *,
                  sink: Callable[[float, str], None] | None = None, token: CancelToken | None = None,
                  surface=None, log: logging.Logger | None = None,
                  allowed_dirs=None, figures: str = "all", fork_csv: bool = False,
                  cloud_format: str = "csv", overrides=(), shown: str | None = None,
                  paths=None, absolute: str | None = None) -> InputOutcome:
    """Read, run, write one input (``path``; ``shown``: its name in the report and the messages,
    as the user typed it, when ``path`` is where a worker reads it; ``paths``: see write_outputs;
    ``absolute``: its absolute path on the client, report.json's ``input_abspath`` — by default
    ``path`` made absolute here when ``paths`` is None, i.e. read where the user named it).
    Any exception but Cancelled → a failed outcome for this input
    alone (one line naming the input and the step or stage; the traceback kept for summary.json and
    --debug); Cancelled propagates. The steps' log records carry the input's name
    (``record.input``, see ``InputLogFilter``)."""
    import warnings

    token_input = CURRENT_INPUT.set(Path(path).name)
    try:
        # a library's warning (numpy's "invalid value encountered in divide") is one log line
        # naming the input, as the steps' own lines — not two lines of file path and source text
        # on stderr, nor lost in a pool worker's
        # one BLAS thread for the whole input (core.parallel.single_threaded_blas): the steps', the
        # summary's and the writer's own contexts nest in it (one library scan an input, not three)
        with warnings.catch_warnings(), single_threaded_blas():
            warnings.simplefilter("default")
            warnings.showwarning = log_warning
            return _process_input(path, recipe, out_dir, stem, sink=sink, token=token, surface=surface,
                                  log=log, allowed_dirs=allowed_dirs, figures=figures, fork_csv=fork_csv,
                                  cloud_format=cloud_format, overrides=overrides,
                                  shown=str(path) if shown is None else str(shown), paths=paths,
                                  absolute=os.path.abspath(path) if absolute is None and paths is None
                                  else absolute)
    finally:
        CURRENT_INPUT.reset(token_input)


def log_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` while an input runs: a WARNING of the ``pointspro.warnings`` logger,
    "RuntimeWarning: invalid value encountered in divide (core/metrics/profiles.py:104)"."""
    parts = Path(filename).parts
    where = "/".join(parts[-3:]) if len(parts) > 3 else filename
    logging.getLogger("pointspro.warnings").warning("%s: %s (%s:%d)", category.__name__, message, where, lineno)


def _process_input(path, recipe, out_dir, stem, *, sink, token, surface, log, allowed_dirs, figures,
                   fork_csv, cloud_format, overrides, shown, paths, absolute) -> InputOutcome:
    t0 = time.perf_counter()
    stage = "reading"
    try:
        progress = Progress(sink, token)
        cloud = read_cloud(path, **recipe.input)  # the recipe's `input:` reader options
        digest = input_digest(path)  # the content these results are of (--resume compares it)
        files = parameter_file_digests(recipe)  # and of the files the recipe names
        progress.update(0.05, "read")
        stage = "running the steps"
        result = run_pipeline(cloud, recipe, progress=progress.sub(0.05, 0.9), surface=surface,
                              log=log, allowed_dirs=allowed_dirs)
        stage = "writing the outputs"
        report = write_outputs(out_dir / stem, shown, recipe, result, figures=figures,
                               fork_csv=fork_csv, cloud_format=cloud_format, overrides=overrides,
                               paths=paths, input_sha256=digest, file_sha256=files,
                               input_abspath=absolute)
        progress.update(1.0, "written")
        return InputOutcome(shown, True, None, time.perf_counter() - t0, str(out_dir / stem),
                            report["summary"], warnings=step_warnings(result))
    except Cancelled:
        raise
    except Exception as e:  # noqa: BLE001 — isolation is the point: one bug must not sink the night
        return failed_outcome(shown, stage, e, time.perf_counter() - t0, paths)


def read_warning(cloud) -> str | None:
    """The rows the reader dropped for a NaN or infinite value, with the columns that held them: a
    point is dropped whole, whichever column it was (docs/formats.md); None when none were."""
    meta = getattr(cloud, "meta", None) or {}
    n = meta.get("invalid_dropped") or 0
    # the readers of rows (x y z text, PointsPro .npz, PCD/PTS), where the option `invalid` applies; an
    # instrument map's masked pixels (outside the aperture, every interferometer file) are no news (a
    # review: opd, sur and x3p maps were warned of, with advice that does not apply to them)
    if not n or not ("invalid_columns" in meta or meta.get("format") in ("npz", "pcd", "pts")):
        return None
    cols = meta.get("invalid_columns") or {}
    where = (" in " + ", ".join(f"{c} ({k})" for c, k in cols.items())) if cols else ""
    first = f", the first at line {meta['invalid_first_line']}" if meta.get("invalid_first_line") else ""
    return (f"{n:,} row(s) dropped on reading, each point whole: a NaN or infinite value{where}{first}"
            " — the recipe's input: {invalid: error} refuses such a file instead")


def step_warnings(result) -> list[str]:
    """The reader's dropped rows ("'read': text"), then each step's report warnings, "'step_id':
    text", in the order the steps ran, then the uncertainty's ("'uncertainty': text")."""
    dropped = read_warning(result.input_cloud)
    out = [f"'read': {dropped}"] if dropped else []
    out += [f"'{rec.id}': {w}" for rec in result.steps
            for w in (rec.report.get("warnings") or []) if isinstance(w, str)]
    block = result.summary().get("uncertainty") if result.uncertainty is not None else None
    meta = (block or {}).get("_meta") or {}
    return out + [f"'uncertainty': {w}" for w in meta.get("warnings") or [] if isinstance(w, str)]


def failed_outcome(path: str, stage: str, e: BaseException, seconds: float = 0.0,
                   paths=None) -> InputOutcome:
    """The outcome of an input that failed with ``e`` while ``stage``: a PointsProError's own line, or
    "internal error … — please report" for a bug; prefixed with the input; traceback kept.
    ``paths``: a ``cluster.PathMap`` naming a worker's files as the client does."""
    import traceback

    from .pipeline import internal_message

    if isinstance(e, PointsProError):
        msg = str(e)
    elif isinstance(e, OSError):  # the machine, not a bug: disk full, permissions, a lost share
        where = f" {e.filename}:" if getattr(e, "filename", None) else ""
        msg = f"{stage}:{where} {e.strerror or e}"
    else:
        msg = internal_message(stage, e)
    if paths is not None:
        msg = paths.text(msg)
    if not msg.startswith(path):
        msg = f"{path}: {msg}"
    return InputOutcome(path, False, msg, seconds, traceback="".join(traceback.format_exception(e)))


def process_job(recipe_path: str, path: str, out_dir: str, stem: str,
                allowed_dirs: list[str] | None = None, figures: str = "all",
                options: dict | None = None) -> InputOutcome:
    """One input in a worker of the process pool (Dask's run ``cluster.cluster_job``, with the recipe
    sent as data): the recipe is read there from its file, so only plain strings cross process
    boundaries — once per worker and recipe version
    (``worker_recipe``), not once per input. ``options`` (plain values): ``cloud_format``,
    ``overrides`` (the ``--set`` texts) and ``log_level`` — the records at that level or above of
    the ``pointspro`` loggers come back in the outcome's ``log`` instead of this process's stderr."""
    options = options or {}
    overrides = tuple(options.get("overrides") or ())
    with capture_log(options.get("log_level")) as records:
        try:
            st = os.stat(recipe_path)
            recipe, surface = worker_recipe(recipe_path, st.st_mtime_ns, st.st_size, overrides)
        except Exception as e:  # noqa: BLE001 — e.g. the recipe changed or vanished since the start
            oc = failed_outcome(path, "reading the recipe in the worker", e)
        else:
            oc = process_input(Path(path), recipe, Path(out_dir), stem, surface=surface, figures=figures,
                               allowed_dirs=None if allowed_dirs is None else [Path(d) for d in allowed_dirs],
                               cloud_format=options.get("cloud_format", "csv"), overrides=overrides)
    oc.log = records
    return oc


@functools.lru_cache(maxsize=4)
def worker_recipe(recipe_path: str, mtime_ns: int, size: int, overrides: tuple = ()):
    """(Recipe, nominal surface) of a recipe file, parsed and built once per worker process for a
    given version of the file (its modification time and size are part of the key, so an edited
    recipe is read again) and the same ``--set`` overrides. A cache, not state: the same key always
    gives the same recipe, and the steps never modify either (a step's Params are frozen; surfaces
    are immutable)."""
    recipe = load_batch_recipe(recipe_path, overrides)
    return recipe, (recipe.build_surface() if recipe.surface_spec is not None else None)


# --- --set STEP.KEY=VALUE -------------------------------------------------------------------------

def load_batch_recipe(path, overrides=()) -> Recipe:
    """The recipe file with the ``--set`` overrides applied to its YAML, then validated as the file
    itself is (core.recipe.parse_recipe): a bad value is the same RecipeError, naming the key, with
    the overrides said. An override naming no step, an ambiguous step id or an unknown key is a
    RecipeError naming the override."""
    from .recipe import check_recipe_whole, load_recipe, parse_recipe
    from .yamlio import load_yaml

    if not overrides:
        return load_recipe(path)
    path = Path(path)
    # the file as written first: its own errors name its lines, as without --set; the checks across
    # steps after the overrides, which may mend them (`--set 3.enabled=true` for a step the order needs)
    load_recipe(path, whole=False)
    data = load_yaml(path.read_text(encoding="utf-8"), str(path))
    seen = {}
    for text in overrides:
        target = apply_override(data, text)
        if target is not None and target in seen:
            # a review: the last of two silently won (`--set 5.diameter=10 --set aperture.diameter=20`)
            raise RecipeError(f"--set {text}: sets what --set {seen[target]} set already; give each key once")
        seen.setdefault(target, text)
    try:
        recipe = parse_recipe(data, str(path), base=path)
        check_recipe_whole(recipe, str(path))
        return recipe
    except RecipeError as e:
        shown = " ".join(f"--set {o}" for o in overrides)
        raise RecipeError(f"{e} (with {shown})") from None


def parse_override(text: str) -> tuple[str, str, object]:
    """``STEP.KEY=VALUE`` → (STEP, KEY, VALUE parsed as YAML: 10 → int, [1, 2] → list, true …)."""
    from .yamlio import load_yaml

    target, eq, value = str(text).partition("=")
    step, dot, key = target.strip().partition(".")
    if not (eq and dot and step and key.strip()):
        raise RecipeError(f"--set {text}: write STEP.KEY=VALUE (e.g. --set knn_denoise.window=10, "
                          "--set 2.window=10 by position, --set surface.k=-1)")
    # read as the recipe file is (YAML 1.2 core schema: 3e-4 a number, yes a word)
    return step.strip(), key.strip(), load_yaml(value, f"--set {text}")


def _copy(d, **changes):
    """A mapping of the recipe with ``changes``, keeping the line numbers a LineDict remembers."""
    from .yamlio import LineDict

    out = LineDict(d) if isinstance(d, dict) else LineDict()
    out.line = getattr(d, "line", None)
    out.key_lines = dict(getattr(d, "key_lines", {}) or {})
    out.update(changes)
    return out


def _entry_id(entry):
    if isinstance(entry, str):
        return entry
    if isinstance(entry, dict):
        keys = [k for k in entry if k != "enabled"]
        return keys[0] if len(keys) == 1 else None
    return None


def apply_override(data, text: str):
    """Apply one ``--set`` to the recipe's YAML data in place (see ``load_batch_recipe``); returns what
    it set — ("surface", KEY), ("input", KEY) or ("step", position, KEY) — or None where the recipe
    is malformed there (parse_recipe says how).

    STEP is a 1-based position in ``steps:`` (``2.window``), a step id that occurs once
    (``knn_denoise.window``), or ``surface`` / ``input`` for those blocks' keys. KEY ``enabled``
    switches a step on or off."""
    from .registry import Registry

    step, key, value = parse_override(text)
    if not isinstance(data, dict):
        return  # not a recipe: parse_recipe says so
    if step in ("surface", "input"):
        block = data.get(step)
        if block is not None and not isinstance(block, dict):
            return  # parse_recipe names the block's own error
        if "." in key and key.split(".")[0] in (block or {}):
            raise RecipeError(f"--set {text}: {step}: key '{key}'" + _nested_hint(step, key, block))
        data[step] = _copy(block or {}, **{key: value})
        return (step, key)
    steps = data.get("steps")
    steps = steps if isinstance(steps, list) else []
    ids = [_entry_id(e) for e in steps]
    if step.isdigit():
        i = int(step)
        if not 1 <= i <= len(steps):
            raise RecipeError(f"--set {text}: no step {i}; the recipe has {len(steps)} step(s)"
                              + (f": {', '.join(f'{k} {s}' for k, s in enumerate(ids, 1))}" if ids else ""))
    else:
        where = [k for k, s in enumerate(ids, 1) if s == step]
        if not where:
            raise RecipeError(f"--set {text}: the recipe has no step '{step}' (its steps: "
                              f"{', '.join(map(str, ids)) or 'none'}; surface.KEY and input.KEY set "
                              "those blocks)")
        if len(where) > 1:
            raise RecipeError(f"--set {text}: step '{step}' occurs {len(where)} times (steps "
                              f"{', '.join(map(str, where))}); name it by position, e.g. "
                              f"--set {where[0]}.{key}=…")
        i = where[0]
    entry, sid = steps[i - 1], ids[i - 1]
    if sid is None:
        return  # a malformed entry: parse_recipe names it
    reg = Registry()
    if key != "enabled" and sid in reg:
        fields = reg.load(sid).Params.model_fields
        if key not in fields:
            raise RecipeError(f"--set {text}: step {i} '{sid}' has no parameter '{key}' (its "
                              f"parameters: {', '.join(fields) or 'none'})" + _nested_hint(step, key, fields))
    if isinstance(entry, str):
        entry = _copy({}, **{sid: {}})
        entry.line = getattr(steps[i - 1], "line", None)
    if key == "enabled":
        new = _copy(entry, enabled=value)
    else:
        params = entry.get(sid)
        new = _copy(entry, **{sid: _copy(params if isinstance(params, dict) else {}, **{key: value})})
    data["steps"][i - 1] = new
    return ("step", i, key)


def _nested_hint(step: str, key: str, names) -> str:
    """For ``--set step.initial.dx=…``: KEY is one name, a mapping is set whole (a review: "has no
    parameter 'initial.dx'" beside a list naming `initial`)."""
    head = key.split(".")[0]
    if "." not in key or head not in names:
        return ""
    return (f"; KEY is one name — set the mapping whole: --set '{step}.{head}={{{key.split('.', 1)[1]}: …}}' "
            "(what it leaves out takes its default)")


# --- the steps' log records, with the input's name, across processes --------------------------------

#: the input being processed in this thread (its file name), stamped on log records
CURRENT_INPUT: "contextvars.ContextVar[str]" = contextvars.ContextVar("pointspro_input", default="")


class InputLogFilter(logging.Filter):
    """Sets ``record.input`` (the input's file name; "" outside an input) unless a worker set it."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not getattr(record, "input", None):
            record.input = CURRENT_INPUT.get()
        return True


class _Collect(logging.Handler):
    def __init__(self, level):
        super().__init__(level)
        self.records: list[dict] = []
        self.addFilter(InputLogFilter())

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append({"name": record.name, "levelno": record.levelno,
                             "levelname": record.levelname, "msg": record.getMessage(),
                             "created": record.created, "input": getattr(record, "input", "")})


class capture_log:
    """``with capture_log(level) as records:`` the ``pointspro`` loggers' records at ``level`` or
    above are collected as plain dicts (picklable, for the parent) and not shown here; ``level``
    None: nothing collected, nothing changed."""

    def __init__(self, level: int | None):
        self.level = level
        self.records: list[dict] = []

    def __enter__(self) -> list[dict]:
        if self.level is None:
            return self.records
        self.logger = logging.getLogger("pointspro")
        self.saved = (self.logger.level, self.logger.propagate)
        self.handler = _Collect(self.level)
        self.handler.records = self.records
        self.logger.addHandler(self.handler)
        self.logger.setLevel(self.level)
        self.logger.propagate = False
        return self.records

    def __exit__(self, *exc) -> None:
        if self.level is None:
            return
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self.saved[0])
        self.logger.propagate = self.saved[1]


def replay_log(records: list[dict]) -> None:
    """A worker's records handed to this process's ``pointspro`` loggers (its handlers show them)."""
    for r in records or ():
        rec = logging.makeLogRecord({**r, "args": None})
        logger = logging.getLogger(rec.name)
        if logger.isEnabledFor(rec.levelno):
            logger.handle(rec)


#: an atomic write's leftover beside ``<name>`` (core/io/atomic.py): ``.<name>.<token>.partial`` (a
#: temporary folder or file) or ``.<name>.<token>.old`` (a folder set aside while being replaced),
#: the token 8 hex digits — ``.part.b.0a1b2c3d.partial`` is part.b's, not part's
_LEFTOVER = re.compile(r"\.(.+)\.[^.]+\.(?:partial|old)")


def cleanup_partials(out_dir: Path, names) -> list[str]:
    """Remove what an interrupted run left of these outputs: the temporary folders and files and the
    folders set aside (``.<name>.<token>.partial|.old``) of each of ``names`` — the batch's inputs'
    folder names (stems) and its own files (``BATCH_FILES``). Never another name's: a second batch
    sharing the output folder deleted the temporary folder the first was writing, and that input
    failed (a review); the batch's lock (``lock_output_folder``) keeps a second batch of the same
    inputs out. Returns the names removed."""
    names = set(names)
    return remove_leftovers(sorted(p for p in Path(out_dir).glob(".*")
                                   if (m := _LEFTOVER.fullmatch(p.name)) and m.group(1) in names))


def remove_leftovers(paths) -> list[str]:
    """Remove those of ``paths`` that are atomic writes' leftovers (``*.partial``, ``*.old``: files or
    folders); the names removed. A folder set aside as ``.<name>.<hex>.old`` whose ``<name>`` is
    missing is an earlier complete output whose replacement never arrived: it is renamed back
    (``_set_aside_to_restore``)."""
    import contextlib
    import shutil

    paths = list(paths)
    for p in _set_aside_to_restore(paths):
        paths.remove(p)  # put back, or where that fails left as it is — never deleted
        with contextlib.suppress(OSError):  # the clean-up never fails a batch
            os.replace(p, p.parent / _LEFTOVER.fullmatch(p.name).group(1))
    gone = []
    for p in paths:
        if p.name.endswith((".partial", ".old")):
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            gone.append(p.name)
    return gone


def _set_aside_to_restore(paths) -> list[Path]:
    """Of ``paths``, the ``.<name>.<hex>.old`` folders to rename back to ``<name>``: an earlier complete
    output set aside by a swap that did not finish (core/io/atomic.py atomic_dir's two renames, a
    process killed between them) — where ``<name>`` is missing, the newest such folder that still
    holds its report.json (another may be an old folder whose deletion failed half-way: a review)."""
    best: dict[str, Path] = {}
    for p in paths:
        m = _LEFTOVER.fullmatch(p.name)
        if not (m and p.name.endswith(".old") and p.is_dir() and not p.is_symlink()):
            continue
        name = m.group(1)
        if os.path.lexists(p.parent / name) or not (p / "report.json").is_file():
            continue
        if name not in best or p.stat().st_mtime > best[name].stat().st_mtime:
            best[name] = p
    return list(best.values())


def input_digest(path) -> str:
    """SHA-256 of an input file's bytes (hex): what ``--resume`` compares (~20 ms for a 31 MB CSV)."""
    import hashlib

    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def parameter_file_digests(recipe: Recipe) -> dict[str, str | None]:
    """SHA-256 of every file the recipe names — a mesh surface's ``path``, the steps' file parameters
    (a calibration, a volumetric or dynamic model, a register mesh), ``inputs:`` — keyed by where the
    recipe names it (``step 2 'z_scale': calibration``), so that ``--resume`` runs an input again when
    one of them changed under the same name (a review: a re-calibrated artefact's file kept the old
    amplification, 3 % off, with exit 0). None for a file that cannot be read (the run says why)."""
    from .recipe import named_files

    labels = {"surface": lambda f: "surface: path", "inputs": lambda f: f"inputs: {f.key}",
              "step": lambda f: f"step {f.step} '{f.step_id}': {f.key}"}
    named = {labels[f.section](f): f.path for f in named_files(recipe)}
    out = {}
    for what, p in named.items():
        try:
            out[what] = input_digest(p)
        except OSError:
            out[what] = None
    return out


#: --figures, from fewest to most figures drawn
FIGURE_MODES = ("none", "summary", "all")


def same_input(report: dict, path) -> bool:
    """The input of an earlier output's ``report`` is ``path``: the same name as typed, or the same
    file however it was named — its absolute path recorded then (``input_abspath``; a report from
    before it was recorded: its name, from here) and ``path`` resolved alike (``os.path.realpath``).
    A review: a cron job naming the inputs by absolute paths after a manual run naming them
    relatively ran the whole night again with --resume. ``input`` itself stays as typed then."""
    shown = report.get("input")
    if shown == str(path):
        return True
    then = report.get("input_abspath")
    then = then if isinstance(then, str) else shown
    return isinstance(then, str) and os.path.realpath(then) == os.path.realpath(path)


def is_complete(out_dir: Path, stem: str, path: Path, recipe: Recipe,
                cloud_format: str = "auto", figures: str = "all", file_digests: dict | None = None) -> dict | None:
    """The report of a complete earlier output of this input with this recipe, else None.

    Output folders appear only when complete (atomic rename); the report must also name the same
    input (``same_input``: named alike or resolving to the same file) with the same content (its SHA-256: a file measured again under the same name, or edited,
    is run again — before, its old numbers were reported as done), the same recipe (every
    parameter, ``--set`` overrides applied) and the same cloud file (``--cloud-format``), so a
    changed recipe or format is run again; the files its steps wrote are all still there, and the
    figures asked (``--figures``) were drawn then; and the files the recipe names have the digests
    recorded (``file_digests``: ``parameter_file_digests(recipe)``, computed once by a batch)."""
    import json

    folder = Path(out_dir) / stem
    rep = folder / "report.json"
    cloud_name = f"cloud.{cloud_format}"
    if cloud_format != "auto" and not (rep.is_file() and (folder / cloud_name).is_file()):
        return None
    try:
        data = json.loads(rep.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    from .report import jsonable

    if not same_input(data, path) or data.get("recipe") != jsonable(recipe.to_dict(full=True)):
        return None
    # the figures asked now were drawn then (a run with --figures none does not stand for one with all)
    done_mode = (data.get("figures") or {}).get("mode", "all")
    if FIGURE_MODES.index(figures) > FIGURE_MODES.index(done_mode if done_mode in FIGURE_MODES else "none"):
        return None
    # every file it wrote is still there (a review: map.csv deleted, the input "skipped"); reports
    # written before report.json listed its files: the steps' artifacts
    named = data.get("files") or [f for st in data.get("steps") or [] for f in st.get("artifacts") or []]
    if not all((folder / f).is_file() for f in [*named, "report.html"]):
        return None
    try:  # the same content: a file measured again under the same name is run again
        if data.get("input_sha256") != input_digest(path):
            return None
    except OSError:
        return None
    # … and the same calibrations, models and meshes (a report from before they were recorded: run
    # again when the recipe names any). A file this machine cannot read (a cluster's workers' own
    # path, without --ship) is not compared: its digest is unknown here, not changed (a review: every
    # input ran again on each --resume)
    now = parameter_file_digests(recipe) if file_digests is None else file_digests
    then = data.get("parameter_files_sha256") or {}
    if any(d is not None and then.get(what) != d for what, d in now.items()):
        return None
    if cloud_format == "auto":  # what "auto" chose (x3p for a grid, else csv), when it was asked
        done = data.get("cloud_file", "cloud.csv")
        if data.get("cloud_format_asked", "auto" if done == "cloud.csv" else None) != "auto" \
                or not (folder / done).is_file():
            return None
    elif data.get("cloud_file", "cloud.csv") != cloud_name:
        return None
    return data
