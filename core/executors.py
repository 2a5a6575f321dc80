"""Ways to run a batch's inputs: in this process, in a pool of processes, on a Dask cluster.

Each is a generator of `InputOutcome`s in completion order; closing it (the caller does on Ctrl-C or
SIGTERM) stops its workers — the caller then removes the temporary folders they leave, so every
output folder is complete or absent. Every input is processed by the same function
(`batch.process_input`) with the same recipe, so all three give the same results (on Dask the
recipe travels as data: core/cluster.py).
"""
from __future__ import annotations

import functools
import signal
from pathlib import Path
from typing import Iterator

from .batch import InputOutcome, failed_outcome, process_input, process_job
from .parallel import single_threaded_blas


def run_sequential(recipe, surface, jobs, out_dir: Path, bar_factory=None,
                   allowed_dirs=None, figures: str = "all", options: dict | None = None
                   ) -> Iterator[InputOutcome]:
    """In this process, one input after the other (``options``: as ``batch.process_job``'s; the
    log records go straight to this process's handlers)."""
    options = options or {}
    for k, (path, stem) in enumerate(jobs, 1):
        bar = bar_factory(k, path) if bar_factory else None
        try:
            # the batch's own process: cloud.csv may be formatted by a fork beside the figures;
            # BLAS on one thread (core.parallel.single_threaded_blas: narrow calls, spinning threads)
            with single_threaded_blas():
                outcome = process_input(path, recipe, out_dir, stem, sink=bar, surface=surface,
                                        allowed_dirs=allowed_dirs, figures=figures, fork_csv=True,
                                        cloud_format=options.get("cloud_format", "csv"),
                                        overrides=tuple(options.get("overrides") or ()))
            yield outcome
        finally:
            if bar is not None:
                bar.done()


def largest_first(jobs):
    """The jobs (path, stem) by input file size, largest first (a missing file last: it fails fast)."""
    import os

    def size(job):
        try:
            return os.stat(job[0]).st_size
        except OSError:
            return -1
    return sorted(jobs, key=size, reverse=True)


def _strings(dirs) -> list[str] | None:
    """Folders as plain strings: only strings cross process and machine boundaries."""
    return None if dirs is None else [str(d) for d in dirs]


# What every input needs and a worker would otherwise import inside its first input (~1 s each):
# a worker imports them as it starts, while the batch's own process reads the recipe and checks the
# inputs (core/cli.py starts the pool first). Measured on 16 cores, 48 inputs of 50,000 points: the
# first input of each worker took 5.3 s against 4.2 s for the others (benchmarks/README.md).
WARM_MODULES = ("scipy.spatial", "scipy.linalg", "scipy.sparse", "scipy.ndimage", "pyarrow.csv",
                "pointspro.core.recipe", "pointspro.core.pipeline")


def _start_worker(figures: str) -> None:
    """A pool worker's start: Ctrl-C is left to the parent (which stops the workers); the libraries
    every input needs are imported and matplotlib loaded unless no figures are drawn. The recipe is
    not read here: the batch's process checks first which files it may name (``--allow-path``), and
    a worker reads it with its first input (``batch.worker_recipe``). A failed import is not
    reported here: the first input meets the same error and reports it, naming the input."""
    import importlib

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from .lean_imports import skip_scipy_capability_notes

        skip_scipy_capability_notes()  # scipy's docstring tables: 0.35–0.45 s of a worker's start
        for name in WARM_MODULES:
            importlib.import_module(name)
        if figures != "none":
            from .figures import preload

            preload()
    except Exception:  # noqa: BLE001,S110 — reported by the input that meets it (above)
        pass
    # No gc.freeze() here: tried (2026-11-25) and measured slower — after a freeze CPython's full
    # collections run far more often (they wait for a quarter of the long-lived objects, now ~none):
    # bench_batch 24 × 50k on 2 workers 50.0–51.3 s with it, 43.5 s without.


def _lost_input(out_dir: Path, task: tuple, reason: str) -> InputOutcome:
    """The outcome of an input whose worker process ended while processing it (``reason``: how,
    workerpool.death_reason): failed, with what it left in the output folder removed; the batch goes
    on with the other inputs on a fresh worker."""
    import re

    from .batch import remove_leftovers

    path, stem = task[1], task[3]
    # its own temporary folders only (core/io/atomic.py names them .<stem>.<8 hex>.partial|.old):
    # another worker may be writing ".<stem>.b.<hex>.partial" of an input named <stem>.b meanwhile
    mine = re.compile(rf"\.{re.escape(stem)}\.[0-9a-f]{{8}}\.(partial|old)")
    remove_leftovers(sorted(p for p in Path(out_dir).glob(".*") if mine.fullmatch(p.name)))
    hint = " (out of memory? the system stops the largest process when memory runs out)" \
        if "SIGKILL" in reason else ""
    return InputOutcome(path, False, f"{path}: its worker process {reason}{hint}; nothing was "
                                     "written for it, the other inputs went on")


# One BLAS/OpenMP thread per worker process: with N processes each starting N spinning BLAS threads
# the batch ran 5× *slower* on 2 workers than on 1 here (Dask's nanny sets the same for its workers).
SINGLE_THREADED = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                     "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")}


def start_pool(workers: int, figures: str = "all"):
    """A pool of ``workers`` spawned processes (no inherited threads or locks), each with one BLAS
    thread, starting to import what the inputs need at once (``_start_worker``). A worker that dies
    (out of memory, a crash) fails the input it held and is replaced (core/workerpool.py). The caller
    terminates it (``run_processes`` does when it is done with it)."""
    from .workerpool import WorkerPool

    return WorkerPool(workers, _start_worker, (figures,), env=SINGLE_THREADED)


def run_processes(recipe_path: Path, jobs, out_dir: Path, workers: int,
                  allowed_dirs=None, figures: str = "all", options: dict | None = None, pool=None
                  ) -> Iterator[InputOutcome]:
    """The jobs on a pool of processes (``pool``, started by the caller with ``start_pool`` as early
    as it could, or one of ``workers`` started here); the pool is terminated when the generator ends
    or is closed. ``options``: plain values for ``batch.process_job`` (cloud format, --set, log
    level)."""
    options = options or {}
    if pool is None:
        pool = start_pool(workers, figures)
    try:
        allowed = _strings(allowed_dirs)
        args = [(str(recipe_path), str(p), str(out_dir), s, allowed, figures, options)
                for p, s in largest_first(jobs)]
        # one input per task: inputs differ in size, and the largest go first so the last round is
        # short and no worker idles while one finishes a big map
        yield from pool.map_unordered(process_job, args, functools.partial(_lost_input, Path(out_dir)))
        pool.close()
    finally:
        pool.terminate()
        pool.join()


class DaskSession:
    """A connection to a Dask cluster (``address``) or a LocalCluster of ``workers`` processes
    ("local"). A scheduler that does not answer is one line naming it within
    ``cluster.CONNECT_TIMEOUT`` seconds. The scheduler's and nannies' INFO chatter (clients, workers
    coming and going) is not the batch's progress: shown with -vv (DEBUG) only."""

    def __init__(self, address: str, workers: int = 1):
        import logging
        import time

        # lazy: only for --scheduler; it sets its loggers' levels as it is first imported, so
        # before ours are set below
        from distributed import Client, LocalCluster

        from .cluster import CONNECT_TIMEOUT, probe_scheduler
        from .errors import PointsProError

        self.address, self.cluster, self.client = address, None, None
        self.bundle, self.workers = None, 0  # set by the CLI: the recipe bundle, the workers found
        # Dask's loggers, and tornado's "application" logger, on which distributed's event loop logs the
        # exceptions of its own callbacks with their traceback (a Ctrl-C while the client was waiting
        # printed distributed/utils.py's "NameError: cannot access free variable 'future'" — a race in
        # its sync() — above our "interrupted" line): shown with -vv (DEBUG) only
        self._loggers = {name: logging.getLogger(name) for name in ("distributed", "tornado.application")}
        self._saved_levels = {name: lg.level for name, lg in self._loggers.items()}
        if logging.getLogger("pointspro").getEffectiveLevel() > logging.DEBUG:
            self._loggers["distributed"].setLevel(logging.WARNING)
            self._loggers["tornado.application"].setLevel(logging.CRITICAL)
        try:
            if address == "local":
                import dask

                # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 for its workers, which stops glibc
                # from raising its mmap threshold: every large numpy temporary is then a fresh mmap
                # with page faults — 30 % slower here than the process pool. Keep its
                # single-threaded BLAS settings.
                env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
                env.pop("MALLOC_TRIM_THRESHOLD_", None)
                with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
                    self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                dashboard_address=None, host="127.0.0.1")
                self.client = Client(self.cluster)
            else:
                t0 = time.monotonic()
                probe_scheduler(address, CONNECT_TIMEOUT)  # nothing listening: said at once
                left = max(CONNECT_TIMEOUT - (time.monotonic() - t0), 1.0)
                try:
                    self.client = Client(address, timeout=f"{left:.0f}s")
                except (OSError, TimeoutError) as e:
                    raise PointsProError(f"--scheduler {address}: no Dask scheduler answers there "
                                         f"within {CONNECT_TIMEOUT:.0f} s ({e})") from None
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Disconnect (and stop a LocalCluster); may be called again."""
        client, cluster, self.client, self.cluster = self.client, self.cluster, None, None
        try:
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
        finally:
            for name, lg in self._loggers.items():
                lg.setLevel(self._saved_levels[name])


def run_dask(session: DaskSession, bundle: dict, jobs, out_dir: Path, allowed_dirs=None,
             figures: str = "all", options: dict | None = None, ship: bool = False
             ) -> Iterator[InputOutcome]:
    """The inputs on a Dask cluster (``session``), one task each, largest first; outcomes as they
    complete. The recipe travels as data (``bundle``: ``cluster.recipe_bundle``), the inputs and
    ``out_dir`` as absolute paths (the workers must see them: a shared file system), or with
    ``ship`` the inputs' bytes go to the workers and their output folders come back to be written
    here. Closing the generator (Ctrl-C, SIGTERM) stops the inputs at their next progress update,
    cancels the rest and closes the session; every output folder is then complete or absent."""
    import os
    import uuid

    from distributed import Event, as_completed, wait

    from . import cluster

    client = session.client
    run_id = uuid.uuid4().hex[:12]
    out_abs = os.path.abspath(out_dir)
    allowed = _strings(allowed_dirs)
    jobs = largest_first(jobs)
    event = Event(f"pointspro-cancel-{run_id}", client=client)
    bundle_f = client.scatter([bundle], broadcast=True, hash=False)[0]  # once, not once per input
    futures: dict = {}  # future → (path as typed, stem)
    pending = list(enumerate(jobs))
    finished = False

    def submit(k, path, stem):
        shown = str(path)
        kw = dict(pure=False, priority=len(jobs) - k, key=f"pointspro-{run_id}-{k}-{stem}")
        if ship:
            try:
                data = Path(path).read_bytes()
            except OSError as e:
                return failed_outcome(shown, "reading", e)
            fut = client.submit(cluster.cluster_job, bundle_f, Path(path).name, shown, out_abs, stem,
                                allowed, figures, options, data, event.name, **kw)
        else:
            fut = client.submit(cluster.cluster_job, bundle_f, os.path.abspath(path), shown, out_abs, stem,
                                allowed, figures, options, None, event.name, **kw)
        futures[fut] = (path, stem)
        return fut

    try:
        # with --ship at most two inputs per worker are in flight: the client reads each input's
        # bytes only when it is sent, so its memory holds a few inputs, not the night's
        window = max(2, 2 * len(client.scheduler_info().get("workers", {}))) if ship else len(jobs)
        ac = as_completed()
        early = []
        while pending and ac.count() < window:
            k, (p, s) = pending.pop(0)
            got = submit(k, p, s)
            if isinstance(got, InputOutcome):  # --ship: the client could not read it
                early.append(got)
            else:
                ac.add(got)
        yield from early
        for fut in ac:
            path, stem = futures.pop(fut)
            try:
                res = fut.result()
            except Exception as e:  # noqa: BLE001 — the task itself died (KilledWorker, lost data…)
                oc = failed_outcome(str(path), "on the cluster", e)
            else:
                oc, files = res if ship else (res, None)
                if ship and oc.ok:
                    try:
                        cluster.write_shipped(Path(out_dir), stem, files)
                    except OSError as e:
                        oc = failed_outcome(str(path), "writing the outputs sent back", e)
                if oc.ok:
                    oc.out_dir = str(Path(out_dir) / stem)
            fut.release()
            yield oc
            while pending and ac.count() < window:
                k, (p, s) = pending.pop(0)
                got = submit(k, p, s)
                if isinstance(got, InputOutcome):
                    yield got
                else:
                    ac.add(got)
        finished = True
    finally:
        try:
            if not finished and futures:
                event.set()  # the running inputs stop at their next progress update, the queued at once
                try:
                    wait(list(futures), timeout=15)
                except Exception:  # noqa: BLE001 — a timeout or a lost worker: cancel below anyway
                    pass
            if futures:
                client.cancel(list(futures), force=True)
            if not ship:  # what a worker lost in the middle of an input left (it was run again)
                cluster.cleanup_stems(Path(out_abs), [s for _, s in jobs])
        finally:
            session.close()
