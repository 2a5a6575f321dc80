"""Ways to run a batch's inputs: in this process, in a pool of processes, on a Dask cluster.

Each is a generator of `InputOutcome`s in completion order; closing it (the caller does on Ctrl-C or
SIGTERM) stops its workers at once — the caller then removes the temporary folders they leave, so
every output folder is complete or absent. Every input is processed by the same function
(`batch.process_input`) from the same recipe file, so all three give the same results.
"""
from __future__ import annotations

import signal
from pathlib import Path
from typing import Iterator

from .batch import InputOutcome, failed_outcome, process_input, process_job


def run_sequential(recipe, surface, jobs, out_dir: Path, bar_factory=None,
                   allowed_dirs=None, figures: str = "all", options: dict | None = None
                   ) -> Iterator[InputOutcome]:
    """In this process, one input after the other (``options``: as ``batch.process_job``'s; the
    log records go straight to this process's handlers)."""
    options = options or {}
    for k, (path, stem) in enumerate(jobs, 1):
        bar = bar_factory(k, path) if bar_factory else None
        try:
            # the batch's own process: cloud.csv may be formatted by a fork beside the figures
            yield process_input(path, recipe, out_dir, stem, sink=bar, surface=surface,
                                allowed_dirs=allowed_dirs, figures=figures, fork_csv=True,
                                cloud_format=options.get("cloud_format", "csv"),
                                overrides=tuple(options.get("overrides") or ()))
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


def _ignore_sigint():  # workers leave Ctrl-C to the parent, which stops them
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _job(args):
    return process_job(*args)


# One BLAS/OpenMP thread per worker process: with N processes each starting N spinning BLAS threads
# the batch ran 5× *slower* on 2 workers than on 1 here (Dask's nanny sets the same for its workers).
SINGLE_THREADED = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                     "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")}


def run_processes(recipe_path: Path, jobs, out_dir: Path, workers: int,
                  allowed_dirs=None, figures: str = "all", options: dict | None = None
                  ) -> Iterator[InputOutcome]:
    """A pool of spawned processes (no inherited threads or locks); terminated on close.
    ``options``: plain values for ``batch.process_job`` (cloud format, --set, log level)."""
    import multiprocessing
    import os

    saved = {k: os.environ.get(k) for k in SINGLE_THREADED}
    os.environ.update(SINGLE_THREADED)  # the spawned workers copy the environment as they start
    try:
        pool = multiprocessing.get_context("spawn").Pool(workers, initializer=_ignore_sigint)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    try:
        allowed = _strings(allowed_dirs)
        args = [(str(recipe_path), str(p), str(out_dir), s, allowed, figures, options)
                for p, s in largest_first(jobs)]
        # one input per task (chunksize 1): inputs differ in size, and the largest go first so the
        # last round is short and no worker idles while one finishes a big map
        yield from pool.imap_unordered(_job, args, chunksize=1)
        pool.close()
    finally:
        pool.terminate()
        pool.join()


def run_dask(recipe_path: Path, jobs, out_dir: Path, workers: int, address: str,
             allowed_dirs=None, figures: str = "all", options: dict | None = None
             ) -> Iterator[InputOutcome]:
    """On a Dask distributed cluster (`address`), or a LocalCluster of `workers` processes ("local").

    The workers must see the same files (a shared file system for a real cluster) and have pointspro
    installed. Each input is one task; results come back as they complete.
    """
    import logging

    from distributed import Client, LocalCluster, as_completed  # lazy: only for --scheduler

    # the scheduler's and nannies' INFO chatter (clients, workers coming and going) is not the
    # batch's progress: shown with -vv (DEBUG) only
    dlog = logging.getLogger("distributed")
    saved_level = dlog.level
    if logging.getLogger("pointspro").getEffectiveLevel() > logging.DEBUG:
        dlog.setLevel(logging.WARNING)
    try:
        yield from _run_dask(recipe_path, jobs, out_dir, workers, address, allowed_dirs, figures,
                             options, Client, LocalCluster, as_completed)
    finally:
        dlog.setLevel(saved_level)


def _run_dask(recipe_path, jobs, out_dir, workers, address, allowed_dirs, figures, options,
              Client, LocalCluster, as_completed):
    cluster = None
    if address == "local":
        import dask

        # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 for its workers, which stops glibc from
        # raising its mmap threshold: every large numpy temporary is then a fresh mmap with page
        # faults — 30 % slower here than the process pool. Keep its single-threaded BLAS settings.
        env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
        env.pop("MALLOC_TRIM_THRESHOLD_", None)
        with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, host="127.0.0.1")
        client = Client(cluster)
    else:
        client = Client(address, timeout="30s")
    futures = []
    try:
        allowed = _strings(allowed_dirs)
        jobs = largest_first(jobs)
        # priority: Dask runs the largest inputs first too (higher priority first)
        futures = [client.submit(process_job, str(recipe_path), str(p), str(out_dir), s, allowed,
                                 figures, options, pure=False, priority=len(jobs) - k,
                                 key=f"pointspro-{s}-{k}") for k, (p, s) in enumerate(jobs)]
        path_of = {f.key: str(p) for f, (p, _) in zip(futures, jobs)}
        for fut in as_completed(futures):
            try:
                yield fut.result()
            except Exception as e:  # noqa: BLE001 — the task itself died (KilledWorker, lost data…)
                yield failed_outcome(path_of[fut.key], "on the cluster", e)
    finally:
        if futures:
            client.cancel(futures, force=True)
        client.close()
        if cluster is not None:
            cluster.close()
