"""The one entry point `pointspro` (README "Batch"; docs/conventions.md "Errors").

    pointspro [FILE…]                                   open the window with the files
    pointspro [--run] --screenshot PNG [FILE…]          render the window to PNG and exit (--run:
                                                        run the recipe first)
    pointspro --batch RECIPE INPUT… --out DIR [--workers N] [--scheduler ADDRESS [--ship]]
                                        [--check-only] [--resume]
                                        [--allow-path DIR]… [--set STEP.KEY=VALUE]…
                                        [--cloud-format csv|ply|npz|x3p] [-v|-vv] [--log-file FILE]
    pointspro info FILE [--json]                        what a measurement file holds
    pointspro steps                                     list the installed steps
    pointspro simulate / explain                        simulated measurements, missing effects

Exit codes: 0 all done; 1 some inputs failed (the others are complete); 2 usage, recipe or input
error, or the only input failed — one line on stderr naming what is wrong, no traceback unless
--debug; 130 interrupted.
Only the window path imports Qt; the batch, `info` and `steps` paths never do.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from .errors import Cancelled, PointsProError, RecipeError
from .pathnames import resolved

EXIT_OK, EXIT_SOME_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130

EPILOG = """\
commands:
  pointspro [FILE…]                   open the window (PySide6) with the files
  pointspro --batch RECIPE INPUT… --out DIR
                                      run RECIPE on each INPUT, no window: DIR/<stem>/cloud.csv,
                                      report.json, report.html and the steps' files
  pointspro info FILE [--json]        format, points, channels and units, extents (mm), grid or
                                      spacing, RMS/PV of z after piston and tilt removal
  pointspro steps [STEP…]             the installed steps and their parameters with units
  pointspro simulate MODEL.yaml --out FILE
                                      a simulated measurement from a model
  pointspro explain --model MODEL.yaml --measured FILE --out DIR
                                      the effects a simulation misses, and the gap they close

examples:
  pointspro info part.datx
  pointspro --batch recipe.yaml scans/*.csv --out results --workers 4
  pointspro --batch recipe.yaml part.csv --out results --set knn_denoise.window=10 \\
            --set 5.diameter=1290 --set surface.k=-0.98 --cloud-format ply -v
  pointspro --batch recipe.yaml scans/*.csv --out results --resume --log-file run.log
  pointspro --batch recipe.yaml scans/*.csv --out results --scheduler tcp://HOST:8786 --check-only
  pointspro steps knn_denoise

inputs (chosen by content, not by extension; docs/formats.md):
  x y z text columns (.csv .txt .xyz .asc .dat), .ply, .pcd/.pts, a PointsPro cloud.npz,
  Zygo .datx / MetroPro .dat, Digital Surf .sur, ISO 25178 .sdf and .x3p, Wyko .opd, Sensofar
  .plu/.plux, Keyence .vk4/.zon, Gwyddion .gwy and the other SurfaceTopography formats, text
  height matrices (Gwyddion, SPIP, Wyko, Nova headers), laser scanners' LAS/LAZ and E57
  (with the `scanners` extra: pip install 'pointspro[scanners]')

exit codes:
  0    all done
  1    some inputs failed (the others are complete; see summary.json)
  2    usage, recipe or input error, or the only input failed: one line on stderr naming the
       file, line, step or key
  130  interrupted (Ctrl-C, SIGTERM): no partial output left; --resume finishes
"""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's own convention too)
        # a sub-command names its own help (`pointspro explain --help`), which lists its options
        self.exit(EXIT_USAGE, f"pointspro: {message} (see {self.prog or 'pointspro'} --help)\n")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="pointspro", description="Form-error maps of aspheric and freeform optics.",
                epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("files", nargs="*", metavar="FILE", help="measurement files (window), or with "
                   "--batch: RECIPE INPUT…")
    p.add_argument("--batch", action="store_true", help="run RECIPE on each INPUT without a window")
    p.add_argument("--out", metavar="DIR", help="output folder of --batch")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="inputs processed in parallel (default: the number of cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on a Dask cluster (tcp://host:8786), "
                   "or `local` for a LocalCluster on this machine")
    p.add_argument("--ship", action="store_true", help="with --scheduler, for workers that see no "
                   "shared folder: send each input's bytes to the worker (at most 2 GiB each) and "
                   "write the outputs it sends back here")
    p.add_argument("--check-only", action="store_true", help="with --batch: only check, on every "
                   "worker of --scheduler (else this machine), the PointsPro version, the recipe's "
                   "steps and their versions, the inputs readable and --out writable; exit 0 when "
                   "ready, 2 with one line per problem")
    p.add_argument("--resume", action="store_true", help="skip inputs whose outputs are complete "
                   "(same input, same recipe and --set, same --cloud-format)")
    p.add_argument("--allow-path", action="append", default=[], metavar="DIR",
                   help="with --batch: let the recipe read parameter files (calibrations, models, "
                   "meshes) in DIR; by default only the recipe's folder and the inputs' folders "
                   "(repeatable)")
    p.add_argument("--set", action="append", default=[], metavar="STEP.KEY=VALUE", dest="overrides",
                   help="with --batch: override one recipe parameter, VALUE read as YAML (10, 0.5, "
                   "[1, 2], true); STEP is a step id that occurs once, its 1-based position, or "
                   "surface / input for those blocks; KEY enabled switches a step (repeatable; "
                   "validated like the recipe file, listed in report.json's overrides)")
    p.add_argument("--cloud-format", choices=["csv", "ply", "npz", "x3p"], default=None,
                   help="with --batch: the processed cloud as cloud.csv (every channel, shortest "
                   "round-trip decimals), cloud.ply (binary float64), cloud.npz (NumPy, with a "
                   "pointspro_meta JSON entry) or cloud.x3p (a gridded input's residual as a map); "
                   "default: x3p when the input is a regular pixel grid (an interferometer's map), "
                   "else csv")
    p.add_argument("--screenshot", metavar="PNG", help="open the window, render, save PNG, exit")
    p.add_argument("--run", action="store_true", help="with a data file and a recipe: run the "
                   "recipe's steps in the window at once (before --screenshot's picture)")
    p.add_argument("--figures", choices=["all", "summary", "none"], default="all",
                   help="figures --batch draws: all (default), summary (form_error.png only) or none; "
                        "report.json says which were not drawn")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="the steps' log on stderr: -v their key numbers (INFO), -vv DEBUG")
    p.add_argument("--log-file", metavar="FILE", help="append the steps' log (INFO, or DEBUG with "
                   "-vv) to FILE, each line with its time, step and input")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    p.add_argument("--quiet", action="store_true", help="no progress output and no table at the end (summary.json has it)")
    p.add_argument("--version", action="store_true", help="print the version and exit")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["steps"]:
        return _guard(lambda: cmd_steps(argv[1:]), "--debug" in argv)
    if argv[:1] in (["simulate"], ["explain"], ["info"]):
        cmd = {"simulate": cmd_simulate, "explain": cmd_explain, "info": cmd_info}[argv[0]]
        try:
            args = _sub_parser(argv[0]).parse_args(argv[1:])
        except SystemExit as e:
            return int(e.code or 0)
        return _guard(lambda: cmd(args), args.debug)
    try:
        args = _parser().parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2): return, never exit from main()
        return int(e.code or 0)
    if args.version:
        from . import __version__

        print(f"pointspro {__version__}")
        return EXIT_OK
    if args.batch:
        return _guard(lambda: cmd_batch(args), args.debug)
    if (args.out or args.workers is not None or args.scheduler or args.resume or args.allow_path
            or args.overrides or args.cloud_format or args.ship or args.check_only):
        print("pointspro: --out, --workers, --scheduler, --ship, --check-only, --resume, --allow-path, "
              "--set and --cloud-format go with --batch (see pointspro --help)", file=sys.stderr)
        return EXIT_USAGE
    return _guard(lambda: _with_logging(args, lambda: cmd_window(args)), args.debug)


class _LogFormatter(logging.Formatter):
    """"pointspro.knn_denoise: part.csv: 12 outliers removed …" — the input when there is one."""

    def format(self, record: logging.LogRecord) -> str:
        name = getattr(record, "input", "")
        record.where = f" {name}:" if name else ""
        return super().format(record)


class _StderrHandler(logging.Handler):
    """Log lines on the stderr of the moment (so a test's capture sees them), through tqdm so an
    overall progress bar is redrawn below them rather than torn."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            msg = self.format(record)
            if "tqdm" in sys.modules:
                from tqdm import tqdm

                tqdm.write(msg, file=sys.stderr)
            else:
                sys.stderr.write(msg + "\n")
                sys.stderr.flush()
        except Exception:  # noqa: BLE001 — logging never stops the batch
            self.handleError(record)


def _with_logging(args, fn):
    """Run ``fn`` with the ``pointspro`` loggers (the steps' ``ctx.log``) shown on stderr at
    WARNING, INFO with -v, DEBUG with -vv, and written to --log-file (INFO, DEBUG with -vv); the
    loggers are as they were afterwards (main() may be called again in the same process)."""
    from .batch import InputLogFilter
    from .errors import RecipeError

    levels = {0: logging.WARNING, 1: logging.INFO}
    shown = levels.get(args.verbose, logging.DEBUG)
    handlers: list[logging.Handler] = []
    err = _StderrHandler(shown)
    err.setFormatter(_LogFormatter("%(name)s:%(where)s %(message)s"))
    handlers.append(err)
    level = shown
    if args.log_file:
        _check_log_file(args)
        try:
            fh = logging.FileHandler(args.log_file, mode="a", encoding="utf-8")
        except OSError as e:
            raise RecipeError(f"--log-file {args.log_file}: cannot write ({e.strerror or e})") from None
        fh.setLevel(min(logging.INFO, shown))
        fh.setFormatter(_LogFormatter("%(asctime)s %(levelname)s %(name)s:%(where)s %(message)s"))
        handlers.append(fh)
        level = min(level, fh.level)
    logger = logging.getLogger("pointspro")
    saved = (logger.level, logger.propagate)
    logger.setLevel(level)
    logger.propagate = False  # shown once, by these handlers
    for h in handlers:
        h.addFilter(InputLogFilter())
        logger.addHandler(h)
    try:
        return fn()
    finally:
        for h in handlers:
            logger.removeHandler(h)
            h.close()
        logger.setLevel(saved[0])
        logger.propagate = saved[1]


def _guard(fn, debug: bool) -> int:
    try:
        code = fn()
        return code
    except PointsProError as e:
        if debug:
            raise
        print(f"pointspro: {e}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # `pointspro steps | head`: the reader left; not an error of ours
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except (Cancelled, KeyboardInterrupt):
        print("pointspro: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as e:  # a bug, not the user's fault: still one line unless --debug
        if debug:
            raise
        print(f"pointspro: internal error: {type(e).__name__}: {e} (run again with --debug for the "
              "traceback and please report it)", file=sys.stderr)
        return EXIT_USAGE


def cmd_batch(args) -> int:
    """--batch, with the ``pointspro`` loggers set (``_with_logging``). First of all SIGTERM stops it
    as Ctrl-C does, and either one before the end is exit 130 with summary.json saying what was not
    run (``_interrupted``) — a review: a SIGTERM in its first half second, while the pool started and
    the recipe was read, ended it with status −15 and left the previous summary.json as if current."""
    with _stop_on_sigterm():
        run = _BatchRun(args)
        try:
            return _with_logging(args, lambda: _cmd_batch(args, run))
        except KeyboardInterrupt:
            return _interrupted(args, run)
        finally:
            run.release()


def _cmd_batch(args, run) -> int:
    _check_batch_args(args)
    run.args_ok = True
    recipe_path = Path(args.files[0])
    # the pool first: its workers import what the inputs need while this process reads the recipe
    # and checks the inputs (core/executors.py WARM_MODULES); stopped on any error below
    pool = None
    try:
        pool = _early_pool(args)
        if pool is None and not args.scheduler:  # the inputs run here: scipy without its docstring
            from .lean_imports import skip_scipy_capability_notes  # tables (0.35–0.45 s of imports)

            skip_scipy_capability_notes()
        return _batch(args, recipe_path, pool, run)
    finally:
        if pool is not None:
            pool.terminate()
            pool.join()


class _BatchRun:
    """How far a batch got, for its interruption (``_interrupted``): the output folder's lock once
    held (core.batch.lock_output_folder), the stems, the inputs' entries reported so far."""

    def __init__(self, args):
        import time

        self.t0 = time.perf_counter()
        self.lock = None
        self.stems: list[str] | None = None
        self.results: dict[str, dict] = {}
        self.workers = args.workers or 1
        self.args_ok = False  # _check_batch_args passed

    def hold(self, out: Path) -> None:
        from .batch import lock_output_folder

        with _signals_held():  # a lock taken is a lock recorded (released on the way out)
            self.lock = lock_output_folder(out)

    def release(self) -> None:
        if self.lock is not None:
            with _signals_held():
                self.lock.release()


def _signals_held():
    """A context in which SIGINT and SIGTERM wait (blocked; they act when it ends)."""
    import contextlib
    import signal

    @contextlib.contextmanager
    def ctx():
        try:
            saved = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        except (AttributeError, OSError, ValueError):  # no such call here
            yield
            return
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, saved)

    return ctx()


def _stop_on_sigterm():
    """A context in which SIGTERM raises KeyboardInterrupt in this process, as Ctrl-C does (Python's
    own SIGINT handler): the batch stops, exit 130, summary.json says what was not run. Not where the
    batch was started with SIGTERM ignored (it stays ignored, as core/io/background.py's forked
    writers keep it), nor off the main thread; the handler before is restored on the way out. A
    forked writer sets SIGTERM back to its default first thing (``_die_on_interrupt``); the pool's
    workers are spawned, with the default handler."""
    import contextlib
    import signal
    import threading

    def on_sigterm(signum, frame):
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def ctx():
        previous = None
        if threading.current_thread() is threading.main_thread() \
                and signal.getsignal(signal.SIGTERM) is not signal.SIG_IGN:
            previous = signal.signal(signal.SIGTERM, on_sigterm)
        try:
            yield
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)

    return ctx()


def _interrupted(args, run: _BatchRun) -> int:
    """Ctrl-C or SIGTERM outside the inputs' run (``_drain`` handles those): while the pool started,
    the recipe was read, the outputs were planned or the summary written. Exit 130 with the closing
    line; summary.json says so — the inputs reported so far as they were, the others "not run" —
    where the batch may write it: an output folder that exists, is a batch's (check_output_targets)
    and that no other batch is writing (its lock, taken here if it was not yet). Not --check-only."""
    import time

    from .batch import check_output_targets, cleanup_partials, output_stems
    from .summary import entry, table, write_summary

    if args.check_only or not run.args_ok:
        raise KeyboardInterrupt  # "pointspro: interrupted", 130 (_guard); nothing to write
    inputs = [Path(f) for f in args.files[1:]]
    out = Path(args.out)
    entries = [run.results.get(str(p)) or entry(str(p), "not run") for p in inputs]
    try:
        if not (run.lock is not None and run.lock.held):
            run.release()
            if not out.is_dir():
                raise RecipeError("no output folder: nothing to say there")
            run.stems = output_stems(inputs)
            check_output_targets(out, inputs, run.stems, resume=True)  # summary.json is a batch's
            run.hold(out)
        cleanup_partials(out, [*run.stems, "summary.json"])
        write_summary(out, Path(args.files[0]), entries, workers=run.workers, scheduler=args.scheduler,
                      seconds=time.perf_counter() - run.t0, interrupted=True, figures=args.figures,
                      overrides=list(args.overrides))
    except (PointsProError, OSError):
        pass  # not ours to write, or another batch is writing it: the line below says enough
    print(table(entries), file=sys.stderr)
    return _batch_exit_code(entries, True)


def _early_pool(args):
    """The process pool of a batch that will surely use one (several inputs and workers, no
    --scheduler, not --check-only), started before anything is read; else None."""
    from . import executors

    n = min(args.workers or _cores(), len(args.files) - 1)
    if args.scheduler or args.check_only or n < 2:
        return None
    return executors.start_pool(n, args.figures)


def _batch(args, recipe_path: Path, pool, run: _BatchRun) -> int:
    import time

    from .batch import check_output_folder, check_output_targets, load_batch_recipe, output_stems
    from .summary import entry, table, write_summary

    inputs = [Path(f) for f in args.files[1:]]
    try:
        recipe = load_batch_recipe(recipe_path, tuple(args.overrides))  # --set applied, then validated
    except RecipeError as e:
        later = next((p for p in inputs if p.suffix.lower() in (".yaml", ".yml")), None)
        if later is None or recipe_path.suffix.lower() in (".yaml", ".yml"):
            raise
        # a review: inputs written first read "asphere_cmm.csv: a recipe is a mapping …"
        raise RecipeError(f"{e} — --batch takes the recipe first (pointspro --batch RECIPE INPUT… --out "
                          f"DIR); {later} looks like the recipe") from None
    allowed = _allowed_dirs(recipe_path, inputs, args.allow_path)
    # before any file the recipe names is read; on a cluster without --ship the workers may see
    # paths this machine does not, so only there is a missing one left to the worker to say
    _check_recipe_files(recipe, allowed, must_exist=not (args.scheduler and not args.ship))
    surface = recipe.build_surface()  # a missing mesh file is a recipe error: fail before any input
    _check_surface_needed(recipe, recipe_path, surface)
    out = Path(args.out)
    stems = output_stems(inputs)
    check_output_targets(out, inputs, stems, resume=args.resume)  # before the folder is made: a refusal leaves nothing
    made = not out.exists()
    check_output_folder(out)
    if not args.check_only:
        run.stems = stems
        try:  # no other batch writes this folder from here to the end (refused: one line, exit 2)
            run.hold(out)
        except BaseException:
            _remove_if_made_empty(out, made)
            raise
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    t0 = time.perf_counter()
    workers = run.workers = args.workers or _cores()

    try:  # a cluster that does not answer, or --check-only: no empty --out folder left behind
        session = _cluster_session(args, recipe_path, recipe, inputs, out, workers)  # --scheduler
        if args.check_only:
            try:
                if args.resume:  # what --resume would run must be replaceable, as the run checks it
                    _plan_jobs(inputs, stems, out, recipe, True, args.cloud_format or "auto", args.figures,
                               dry=True)
                return _check_only(args, recipe, inputs, out, session)
            finally:
                _remove_if_made_empty(out, made)
    except BaseException:
        run.release()  # its lock file goes too: nothing left
        _remove_if_made_empty(out, made)
        raise
    try:
        results, jobs = _plan_jobs(inputs, stems, out, recipe, args.resume, args.cloud_format or "auto",
                                   args.figures)
        run.results = results  # what an interruption from here on reports (_interrupted)
        # the steps' ctx.resolve applies `allowed` here and in every worker (sent with each job)
        runner = _choose_runner(args, recipe_path, recipe, surface, jobs, out, workers, allowed, session,
                                pool)
        if session is not None:  # the cluster's workers, as the pre-flight found them
            workers = session.workers or workers
        progress = None
        if not args.quiet and runner.__name__ != "run_sequential":  # workers: one overall bar
            from .terminal import BatchProgress

            progress = BatchProgress(len(jobs))
        try:
            interrupted = _drain(runner, _reporter(results, args, progress), out, stems)
        finally:
            if progress is not None:
                progress.close()
    finally:
        if session is not None:
            session.close()

    entries = [results.get(str(p)) or entry(str(p), "not run") for p in inputs]
    try:
        write_summary(out, recipe_path, entries, workers=1 if runner.__name__ == "run_sequential" else workers,
                      scheduler=args.scheduler, seconds=time.perf_counter() - t0, interrupted=interrupted,
                      figures=args.figures, overrides=list(args.overrides))
    except PointsProError as e:
        if not interrupted:
            raise
        # an interrupted batch stays an interrupted one (130, its closing line) when summary.json
        # cannot be written either (a full disk): the summary's line said 2 before
        print(f"pointspro: {e}", file=sys.stderr)
    if not args.quiet or interrupted:
        print(table(entries), file=sys.stdout if not interrupted else sys.stderr)
    return _batch_exit_code(entries, interrupted)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and a.samefile(b)
    except OSError:
        return False


def _check_log_file(args) -> None:
    """--log-file is appended to: never a file this run reads (the recipe, an input — a log line
    at the end of a CSV made its next read fail, of a recipe made it invalid YAML), nor a file in
    --out, whose folders the batch replaces and whose summary.json it writes."""
    from .errors import RecipeError

    log = Path(args.log_file)
    for i, f in enumerate(args.files or []):
        if _same_file(log, Path(f)):
            what = "the recipe" if args.batch and i == 0 else "an input"
            raise RecipeError(f"--log-file {log}: is {what} ({f}); the log would be appended to it — "
                              "choose another file")
    if args.batch and args.out:
        out, target = resolved(args.out), resolved(log)
        if target == out or out in target.parents:
            raise RecipeError(f"--log-file {log}: is inside --out {args.out}, whose folders the batch "
                              "replaces and whose summary.json it writes — put the log beside it")


#: what --screenshot writes (Qt's image writers by suffix)
SCREENSHOT_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")


def _check_screenshot(args) -> None:
    """--screenshot PNG: an image suffix, a folder that exists, and never a file the window opens
    (Qt's save truncated the file first — an input given as the picture's name was emptied)."""
    from .errors import RecipeError

    shot = Path(args.screenshot)
    for f in args.files:
        if _same_file(shot, Path(f)):
            raise RecipeError(f"--screenshot {shot}: is a file the window opens ({f}); choose another name")
    if shot.suffix.lower() not in SCREENSHOT_SUFFIXES:
        raise RecipeError(f"--screenshot {shot}: give an image file name ({', '.join(SCREENSHOT_SUFFIXES)})")
    if not shot.parent.is_dir():
        what = "is a file, not a folder" if shot.parent.exists() else "does not exist"
        raise RecipeError(f"--screenshot {shot}: {shot.parent} {what}")


def _check_batch_args(args) -> None:
    """The usage errors of --batch, before anything is read."""
    from .errors import RecipeError

    if len(args.files) < 2:
        raise RecipeError("--batch needs RECIPE and at least one INPUT (pointspro --batch RECIPE "
                          "INPUT… --out DIR)")
    if not args.out:
        raise RecipeError("--batch needs --out DIR")
    if args.workers is not None and args.workers < 1:
        raise RecipeError("--workers must be ≥ 1")
    if args.ship and not args.scheduler:
        raise RecipeError("--ship goes with --scheduler ADDRESS (it sends the inputs to a cluster's "
                          "workers)")


def _remove_if_made_empty(out: Path, made: bool) -> None:
    """Remove the --out folder this run made when nothing was written into it."""
    if made:
        try:
            out.rmdir()  # only an empty folder goes
        except OSError:
            pass


def _cluster_session(args, recipe_path: Path, recipe, inputs: list[Path], out: Path, workers: int):
    """With --scheduler: the connection to the cluster, after the pre-flight on every worker
    (core/cluster.py) found nothing wrong — else one line per problem naming the worker, exit 2,
    before any input runs. The recipe bundle is kept on the session for the runner."""
    if not args.scheduler:
        return None
    from . import cluster
    from .errors import PointsProError
    from .executors import DaskSession

    bundle = cluster.recipe_bundle(recipe_path, recipe, tuple(args.overrides))
    if args.ship:
        cluster.check_ship_sizes(inputs)
    session = DaskSession(args.scheduler, workers)
    try:
        session.bundle = bundle
        session.workers = len(session.client.scheduler_info().get("workers", {}))
        problems = cluster.check_workers(session.client,
                                         cluster.expectations(recipe, bundle, inputs, out, args.ship))
        if problems:
            for line in problems[:-1]:
                print(f"pointspro: {line}", file=sys.stderr)
            raise PointsProError(f"{problems[-1]}" + (f" ({len(problems)} problems on the cluster; "
                                                       "nothing was run)" if len(problems) > 1 else
                                                       " (nothing was run)"))
    except BaseException:
        session.close()
        raise
    return session


def _check_surface_needed(recipe, recipe_path: Path, surface) -> None:
    """A step that works against the nominal (``needs_surface``: probe_radius, misalignment) in a
    recipe without `surface:` is the recipe's error, said once before any input (and by
    --check-only), not each input's failure."""
    from .errors import RecipeError

    if surface is not None:
        return
    for i, rs in enumerate(recipe.steps, 1):
        if rs.enabled and getattr(rs.step_cls, "needs_surface", False):
            where = f"{recipe_path}, line {rs.line}" if rs.line else str(recipe_path)
            raise RecipeError(f"{where}: step {i} '{rs.id}' needs the recipe's nominal `surface:` "
                              "(the design the part is measured against)")


def _check_only(args, recipe, inputs: list[Path], out: Path, session) -> int:
    """--check-only: the pre-flight alone (on the cluster it already ran in _cluster_session; here
    on this machine), and whether another batch is writing --out now. Exit 0 when ready, 2 with one
    line per problem."""
    from . import cluster
    from .batch import batch_running
    from .errors import PointsProError

    if session is not None:
        n = len(session.client.scheduler_info().get("workers", {}))
        session.close()
        where = f"{n} worker(s) at {args.scheduler}"
        problems = []
    else:
        problems = [f"this machine: {line}"
                    for line in cluster.preflight(cluster.expectations(recipe, {}, inputs, out, False))]
        where = "this machine"
    live = batch_running(out)  # the run would be refused (core.batch.lock_output_folder)
    if live:
        problems.append(live)
    for line in problems[:-1]:
        print(f"pointspro: {line}", file=sys.stderr)
    if problems:
        raise PointsProError(problems[-1])
    from . import __version__

    print(f"pointspro: ready on {where}: PointsPro {__version__}, the recipe's {len(recipe.steps)} "
          f"step(s) installed alike, {len(inputs)} input(s) readable"
          + (" here (--ship)" if args.ship else f", {out} writable"))
    return EXIT_OK


def _allowed_dirs(recipe_path: Path, inputs: list[Path], extra: list[str]) -> list[Path]:
    """Where the recipe's parameter files may lie: its own folder, each input's, --allow-path's."""
    from .errors import RecipeError

    for d in extra:
        if not Path(d).is_dir():
            raise RecipeError(f"--allow-path {d}: not a folder")
    dirs = [recipe_path.parent, *(p.parent for p in inputs), *(Path(d) for d in extra)]
    return list(dict.fromkeys(resolved(d) for d in dirs))


def _check_recipe_files(recipe, allowed: list[Path], must_exist: bool = True) -> None:
    """Every file the recipe names (steps' file parameters, ``inputs:``, a mesh surface) lies in
    ``allowed``: RecipeError naming the line, the step and the parameter otherwise — so a shared
    recipe cannot read files its user did not allow, on any executor. With ``must_exist``, a step's
    file parameter that is empty, missing or a folder is refused here too, before any input runs (a
    review: a missing `dynamic.model` or `kinematic.map` was found only at run time, on every
    input, behind "the scan has no t channel"; `volumetric: {model: ""}` read as the folder ".")."""
    from .errors import RecipeError
    from .recipe import named_files
    from .step import outside_allowed

    where = str(recipe.path)
    for i, rs in enumerate(recipe.steps, 1):  # a file parameter set, but to nothing
        for k, f in type(rs.params).model_fields.items():
            extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
            value = getattr(rs.params, k, None)
            if extra.get("file") and isinstance(value, str) and not value.strip():
                loc = f"line {rs.line}: " if rs.line else ""
                raise RecipeError(f"{where}, {loc}step {i} '{rs.id}': parameter '{k}' is empty; "
                                  "give a file name (relative to the recipe) or leave the key out")

    def say(f, why):
        if f.section == "step":
            loc = f"line {f.line}: " if f.line else ""
            what = f"{loc}step {f.step} '{f.step_id}': parameter '{f.key}'"
        else:
            what = f"{f.section}: key '{f.key}'"
        return f"{where}, {what}: {why}" if what.startswith("line") else f"{where}: {what}: {why}"

    for f in named_files(recipe):
        why = outside_allowed(f.path, allowed)
        if why:
            raise RecipeError(say(f, why))
        if must_exist and f.section == "step":
            if not f.path.exists():
                raise RecipeError(say(f, f"{f.path}: file not found"))
            if f.path.is_dir():
                raise RecipeError(say(f, f"{f.path}: a folder, not a file"))


def _cores() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _plan_jobs(inputs: list[Path], stems: list[str], out: Path, recipe, resume: bool,
               cloud_format: str = "csv", figures: str = "all", dry: bool = False):
    """(results of the inputs already complete, jobs (path, stem) left to run). With ``resume``,
    what a killed run of these inputs left behind is removed first (the batch holds the folder's
    lock: no live batch is writing them) and complete outputs (same recipe, same cloud
    format) are skipped; a folder run again must be replaceable (core.batch.check_replaceable).
    ``dry`` (--check-only): nothing is removed."""
    from .batch import cleanup_partials, is_complete, parameter_file_digests
    from .summary import entry

    results: dict[str, dict] = {}
    jobs = []
    files = None
    if resume and not dry:
        cleanup_partials(out, [*stems, "summary.json"])  # what a killed run of these inputs left behind
        files = parameter_file_digests(recipe)  # once for the batch, not per input (a 200 MB mesh: 0.15 s)
    for path, stem in zip(inputs, stems):
        done = is_complete(out, stem, path, recipe, cloud_format, figures, files) if resume else None
        if done is not None:
            results[str(path)] = entry(str(path), "skipped", report=done)
        else:
            jobs.append((path, stem))
    if resume:  # a folder run again is replaced whole: never over a file the user added to it
        from .batch import check_replaceable
        from .io.atomic import InputPlaces

        places = InputPlaces(inputs)  # resolved once (core/io/atomic.py)
        for path, stem in jobs:
            check_replaceable(out / stem, places, path)
    return results, jobs


def _reporter(results: dict, args, progress=None):
    """The callback for each finished input: shows a worker's log records, records its summary
    entry and prints one line (ok on stdout unless --quiet, failed on stderr, with the traceback
    under --debug); ``progress`` (workers' overall bar) counts it."""
    from .batch import replay_log
    from .summary import entry
    from .units import format_length

    def say(text: str, file=None):
        if progress is not None:
            progress.write(text, file or sys.stdout)
        else:
            print(text, file=file or sys.stdout, flush=True)

    def report(oc):
        replay_log(getattr(oc, "log", None))
        results[oc.input] = entry(oc.input, "ok" if oc.ok else "failed", oc)
        try:
            _line(oc)
        finally:
            if progress is not None:
                progress.advance(oc.ok, Path(oc.input).name)

    def _line(oc):
        if oc.ok:
            s = oc.summary or {}
            what = "residual" if s.get("figures_of", "residual") == "residual" else "height"
            extra = (f", {what} RMS {format_length(s['rms_um'] * 1e-3, 4)}, "
                     f"PV {format_length(s['pv_um'] * 1e-3, 4)}"
                     if s.get("rms_um") is not None else "")
            u = (s.get("uncertainty") or {}).get("rms_um")
            u = u if isinstance(u, dict) else {}
            if extra and u.get("value") is not None and u.get("U95") is not None:
                # the table's RMS column: noise bias removed, ± U95 (docs/uncertainty.md)
                from .statement import with_uncertainty

                extra += (f" as measured; RMS {with_uncertainty(u['value'], u['U95'], 'µm', u.get('k') or 2.0, u.get('interval95'))}"
                          " with the noise bias removed")
            if not args.quiet:
                say(f"{oc.input}: ok → {oc.out_dir} ({s.get('points_in')} → {s.get('points_out')} "
                    f"points{extra}, {oc.seconds:.2f} s)")
                for w in getattr(oc, "warnings", None) or []:
                    say(f"{oc.input}: warning: {w}", sys.stderr)
        else:
            if args.debug and oc.traceback:
                say(oc.traceback.rstrip("\n"), sys.stderr)
            say(f"pointspro: {oc.error}", sys.stderr)
            earlier = Path(getattr(args, "out", None) or ".") / Path(oc.input).stem
            if getattr(args, "out", None) and (earlier / "report.json").is_file():
                # outputs are swapped in only when complete: a failed re-run leaves the last good
                # ones, which looked current beside a summary.json saying "failed" (a review)
                say(f"pointspro: {oc.input}: {earlier} still holds an earlier run's outputs "
                    "(its report.json says when and with which recipe)", sys.stderr)

    return report


def _choose_runner(args, recipe_path: Path, recipe, surface, jobs, out: Path, workers: int,
                   allowed: list[Path], session=None, pool=None):
    """The executor: Dask with --scheduler, a process pool for several jobs and workers (``pool``
    when started already), else this process (with a progress bar unless --quiet)."""
    from . import executors

    # plain values for the workers: the cloud format, the --set texts (each worker applies them to
    # the recipe file it reads) and the level of the log records they send back
    options = {"cloud_format": args.cloud_format or "auto", "overrides": list(args.overrides),
               "log_level": logging.getLogger("pointspro").getEffectiveLevel()}
    if session is not None:  # --scheduler: the recipe travels as data, the paths as absolute ones
        import os

        options["cwd"] = os.getcwd()  # --ship: the inputs' absolute paths for --resume (cluster_job)
        return executors.run_dask(session, session.bundle, jobs, out, allowed, args.figures, options,
                                  ship=args.ship)
    if min(workers, len(jobs)) > 1:
        return executors.run_processes(recipe_path, jobs, out, min(workers, len(jobs)), allowed,
                                       args.figures, options, pool=pool)
    from .terminal import TerminalProgress

    factory = None if args.quiet else (
        lambda k, p: TerminalProgress(label=f"[{k}/{len(jobs)}] {p.name}"))
    return executors.run_sequential(recipe, surface, jobs, out, factory, allowed, args.figures, options)


def _drain(runner, report, out: Path, stems) -> bool:
    """Report each outcome as it comes; SIGTERM stops like Ctrl-C (``_stop_on_sigterm``): the workers
    are stopped and the partial outputs of the batch's inputs (``stems``) removed. True when
    interrupted."""
    from .batch import cleanup_partials

    with _stop_on_sigterm():
        try:
            for oc in runner:
                report(oc)
        except KeyboardInterrupt:
            runner.close()  # stops the workers
            cleanup_partials(out, [*stems, "summary.json"])
            return True
    return False


def _batch_exit_code(entries: list[dict], interrupted: bool) -> int:
    """130 interrupted, 0 all done, 1 some failed (2 when the only input failed), with the closing
    line on stderr."""
    n = len(entries)
    failed = [e for e in entries if e["status"] == "failed"]
    if interrupted:
        done = sum(e["status"] in ("ok", "skipped") for e in entries)
        print(f"pointspro: interrupted — {done} of {n} inputs complete, no partial output "
              "left; run the same command with --resume to finish", file=sys.stderr)
        return 130
    if not failed:
        return EXIT_OK
    if n == 1:
        return EXIT_USAGE
    if len(failed) == n:
        print(f"pointspro: all {n} inputs failed; no input's outputs were written (see the lines "
              "above and summary.json)", file=sys.stderr)
    else:
        print(f"pointspro: {len(failed)} of {n} inputs failed; the others are complete",
              file=sys.stderr)
    return EXIT_SOME_FAILED


def _sub_parser(name: str) -> argparse.ArgumentParser:
    p = _Parser(prog=f"pointspro {name}")
    if name == "info":
        p.description = ("What a measurement file holds, read as --batch reads it: the reader chosen, "
                         "points, channels with units, extents (mm), grid and pixel or mean "
                         "nearest-neighbour spacing, RMS and PV of z after piston and tilt removal.")
        p.add_argument("file", metavar="FILE")
        p.add_argument("--json", action="store_true", help="the same as JSON (lengths in mm)")
    elif name == "simulate":
        p.description = "Simulate a measurement from a model (surface, scan, probe, effects)."
        p.add_argument("model", metavar="MODEL.yaml")
        p.add_argument("--out", required=True, metavar="FILE", help="the simulated measurement (.csv/.ply)")
    else:
        p.description = ("Compare a simulation with a measurement, name the missing effects, add them "
                         "and show the gap shrink.")
        src = p.add_mutually_exclusive_group(required=True)
        src.add_argument("--model", metavar="MODEL.yaml")
        src.add_argument("--simulated", metavar="SIM")
        p.add_argument("--measured", required=True, metavar="MEAS")
        p.add_argument("--out", required=True, metavar="DIR")
        p.add_argument("--bootstrap", type=int, default=10, metavar="B",
                       help="bootstrap replicates for the stability of each choice (0: none)")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    return p


def cmd_info(args) -> int:
    from .info import describe, format_text

    d = describe(Path(args.file))
    if args.json:
        import json

        from .report import jsonable

        print(json.dumps(jsonable(d), indent=2, ensure_ascii=False, allow_nan=False))
    else:
        print(format_text(d))
    return EXIT_OK


def _check_simulate_out(out: Path, model: Path) -> None:
    """simulate writes one file: its folder must exist, the path must not be a folder or the model."""
    from .errors import RecipeError

    if resolved(out) == resolved(model):
        raise RecipeError(f"--out {out}: is the model file itself; choose another file name")
    if out.is_dir():
        raise RecipeError(f"--out {out}: is a folder; give the file to write (e.g. {out / 'simulated.csv'})")
    if not out.parent.is_dir():
        what = "is a file, not a folder" if out.parent.exists() else "does not exist"
        raise RecipeError(f"--out {out}: {out.parent} {what}")


def cmd_simulate(args) -> int:
    from .cloud import PointCloud
    from .errors import InputError, RecipeError
    from .io import write_cloud
    from .simulate.model import load_model, simulate

    model = load_model(args.model)
    try:
        sim = simulate(model, Path(args.model).parent)
    except (ValueError, KeyError, InputError) as e:
        raise RecipeError(f"{args.model}: {e}") from None
    extra = {"fiducial": sim["fiducial"]} if "fiducial" in sim else {}
    cloud = PointCloud.from_xyz(sim["x"], sim["y"], sim["z"], t=sim["t"], c=sim["c"], xd=sim["xd"], **extra)
    cloud.meta["channel_units"] = {"t": "s", "c": "deg"}  # written `t [s]`, `c [deg]` (docs/formats.md)
    _check_simulate_out(Path(args.out), Path(args.model))
    mesh = model.surface.get("path") if isinstance(model.surface, dict) else None
    if mesh is not None and resolved(args.out) == resolved(Path(args.model).parent / mesh):
        # a review: `--out partmesh.ply` replaced the model's nominal mesh with a point cloud
        raise RecipeError(f"--out {args.out}: is the model's nominal mesh ({mesh}); choose another file name")
    write_cloud(cloud, args.out)
    print(f"{args.out}: {cloud.n} simulated points")
    from .simulate.model import implausible_effects

    for w in implausible_effects(model, Path(args.model).parent):
        print(f"pointspro: {args.model}: warning: {w}", file=sys.stderr)
    return EXIT_OK


def _check_explain_out(out: Path, inputs: list[Path]) -> None:
    """explain replaces its --out folder as a whole: refuse a path that holds or is one of its inputs,
    a file, or a folder that is not an earlier explain output (no explain.json; an empty one is
    fine). Before: `--out meas.csv` moved the measurement aside, `--out notes/` deleted the notes."""
    from .errors import RecipeError
    from .io.atomic import why_not_replace

    why = why_not_replace(out, "explain.json", inputs)
    if why is not None and why[0] == "input":
        raise RecipeError(f"--out {out}: holds the input {why[1]}, and explain replaces that folder as a "
                          "whole; choose another --out")
    if why is not None and why[0] == "file":
        raise RecipeError(f"--out {out}: exists and is not a folder; explain writes a folder there — "
                          "choose another --out")
    if why is not None:
        raise RecipeError(f"--out {out}: exists and is not an explain output folder (no explain.json that PointsPro wrote); "
                          "explain would replace it — move it or choose another --out")


def cmd_explain(args) -> int:
    from .explain.workflow import explain

    if not 0 <= args.bootstrap <= 1000:
        from .errors import RecipeError

        raise RecipeError(f"--bootstrap {args.bootstrap}: replicates from 0 (none) to 1000")
    out = Path(args.out)
    _check_explain_out(out, [Path(a) for a in (args.measured, args.model, args.simulated) if a])
    out.parent.mkdir(parents=True, exist_ok=True)
    rep = explain(Path(args.measured), out, Path(args.model) if args.model else None,
                  Path(args.simulated) if args.simulated else None, bootstrap=args.bootstrap)
    from .explain.workflow import found_name

    for w in rep.get("warnings") or []:  # as the batch prints a step's: the input, then the warning
        print(f"{args.measured}: warning: {w}", file=sys.stderr)
    names = ", ".join(found_name(f) for f in rep["found"]) or "none"
    from .units import format_length

    print(f"{out}: verdict {rep['verdict']}; found {names}; gap {format_length(rep['gap_before']['rms_um'] * 1e-3, 4)}"
          f" → {format_length(rep['gap_after']['rms_um'] * 1e-3, 4)} RMS "
          f"(noise {format_length(rep['noise_um'] * 1e-3, 3)})")
    from .explain.workflow import region_words

    regs = rep["unexplained"].get("regions") or []
    for reg in regs[:3]:  # the strongest; every one is in explain.json and explain.html
        print(f"  unexplained: {region_words(reg)}")
    if len(regs) > 3:
        print(f"  … and {len(regs) - 3} more region(s) in {out / 'explain.json'}")
    if rep["unexplained"].get("note"):
        print(f"  note: {rep['unexplained']['note']}")
    return EXIT_OK


def cmd_steps(argv) -> int:
    from .forms import form_fields
    from .registry import Registry

    if "-h" in argv or "--help" in argv:
        print("usage: pointspro steps [STEP_ID …]\n\nEvery installed step (or the ones named) with its\n"
              "parameters: unit, default, bounds and help — what a recipe may write under it.")
        return EXIT_OK
    unknown_options = [a for a in argv if a.startswith("-") and a != "--debug"]
    if unknown_options:
        from .errors import PointsProError

        raise PointsProError(f"steps: unknown option {unknown_options[0]} (usage: pointspro steps "
                         "[STEP_ID …])")
    reg = Registry()
    wanted = [a for a in argv if not a.startswith("-")]
    for step_id in reg.ids():
        if wanted and step_id not in wanted:
            continue
        cls = reg.load(step_id)
        print(f"{step_id} — {cls.title}")
        if cls.summary:
            print(f"    {cls.summary}")
        for f in form_fields(cls.Params):
            _print_field(f, "    ")
        print()
    unknown = [w for w in wanted if w not in reg]
    if unknown:
        from .errors import RecipeError

        raise RecipeError(f"unknown step(s) {', '.join(unknown)}; installed: {', '.join(reg.ids())}")
    return EXIT_OK


def _print_field(f, indent: str, prefix: str = "") -> None:
    """One parameter of `pointspro steps`: key [unit]: kind, default, bounds, choices; its help; a
    mapping's own keys below it (misalignment's ``initial``: alpha_deg … — written nowhere before, a
    review); a union as what it takes ("'auto' or a whole number", not "one of ['auto']")."""
    default = "required" if f.required else f"default {f.default!r}"
    unit = f" [{f.unit}]" if f.unit else ""
    bounds = f.bounds_text()
    if f.widget == "union":
        number = "a whole number" if f.number == "int" else "a number"
        kind = " or ".join([*(repr(c) for c in f.choices or []), number])
        choices = ""
    else:
        kind = f.widget
        choices = f" one of {f.choices}" if f.choices else ""
    print(f"{indent}{prefix}{f.key}{unit}: {kind}, {default}{', ' + bounds if bounds else ''}{choices}")
    if f.help:
        print(f"{indent}    {f.help}")
    for sub in getattr(f, "fields", None) or ():
        _print_field(sub, indent + "    ", f"{prefix}{f.key}.")


def _check_display(args) -> None:
    """The window on Linux without a display: Qt aborts the process (exit 134, plugin noise); say
    what to do instead. A screenshot run, QT_QPA_PLATFORM set (offscreen, xcb …) or a display go on."""
    import os

    from .errors import PointsProError

    if not sys.platform.startswith("linux") or os.environ.get("QT_QPA_PLATFORM"):
        return
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return
    if args.screenshot:  # Qt aborted here (exit 134, plugin noise); offscreen draws no 3D view
        raise PointsProError("no display to render the window on (DISPLAY and WAYLAND_DISPLAY are "
                             "unset): run it under a virtual one, `xvfb-run -a pointspro --screenshot "
                             f"{args.screenshot} …`")
    raise PointsProError("no display to open the window on (DISPLAY and WAYLAND_DISPLAY are unset): "
                         "process files with `pointspro --batch RECIPE INPUT… --out DIR`, or run the "
                         "window under xvfb-run or with QT_QPA_PLATFORM=offscreen")


def cmd_window(args) -> int:
    from .errors import InputError

    for f in args.files:
        if not Path(f).exists():
            raise InputError(f"{f}: file not found")
    if args.screenshot:
        _check_screenshot(args)
    _check_display(args)
    from pointspro.app.main import run_window  # the only path that imports Qt

    return run_window([Path(f) for f in args.files], screenshot=args.screenshot, run=args.run)


def console() -> None:  # pragma: no cover - the console-script wrapper
    # under a C/POSIX locale (no UTF-8 mode) stdout is ASCII: the "ok → folder" line of a finished
    # input raised UnicodeEncodeError — an internal error, exit 2, after its outputs were written.
    # Characters the terminal cannot show become '?'; files are written as UTF-8 regardless
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="replace")
        except (AttributeError, ValueError):  # not a text stream of io's
            pass
    # a crash in a C library (a segfault) prints the Python stack of every thread on stderr instead
    # of ending silently with −11: one CI run of a SIGTERM'd two-worker batch ended so, never seen
    # again in 14 runs; the stack is what the next occurrence must show (Python exceptions are
    # unaffected: they stay one line without --debug)
    import faulthandler

    faulthandler.enable()
    without_hugepage_advice()
    code = main()
    argv = sys.argv[1:]
    if "--batch" in argv and not any(a.startswith("--scheduler") for a in argv):
        exit_now(code)
    sys.exit(code)


def without_hugepage_advice() -> None:
    """numpy asks Linux for transparent huge pages on every array of ≥ 4 MiB (madvise); where the
    kernel then compacts memory on the first touch of each 2 MiB page (THP ``defrag: madvise``, the
    default of common distributions, this machine's), a fresh process pays for it on each new large
    temporary: the 10⁶-point raster's whole command took 8.17–8.60 s with the advice and 7.37–7.74 s
    without (3 runs each, alternated), the steps run a second time in one process equally fast either
    way (2026-11-28, benchmarks/README.md). The process's own numpy stops advising; the batch's
    workers, spawned with this environment, start without it. A user's own NUMPY_MADVISE_HUGEPAGE
    is left as set (numpy reads it at import)."""
    import os

    if "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        return
    os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"  # for the processes this one starts
    import numpy as np

    core = getattr(np, "_core", None) or getattr(np, "core", None)
    setter = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if setter is not None:  # a private numpy function (1.x and 2.x); absent: the advice stays
        setter(False)


def exit_now(code: int) -> None:
    """End a finished local batch without the interpreter's teardown. By then every output is written
    and closed (folders renamed into place, summary.json written), forked writers waited for and the
    worker pool joined; what is left is Python clearing the modules of numpy, scipy, matplotlib and
    pyarrow one object at a time: 0.30–0.55 s of a 50,000-point input's 3 s command, measured
    2026-11-26 (0.02 s this way; issue 17). Streams and logging handlers are flushed first."""
    import logging
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can reach it
            pass
    logging.shutdown()
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    console()
