"""How many threads a computation in this process may use (neighbour searches, BLAS).

The batch's worker processes run with a single-threaded BLAS (core.executors.SINGLE_THREADED sets
OMP_NUM_THREADS=1 and the like): N workers × N threads on N cores ran 5× slower than one worker.
Work that threads by itself (scipy's cKDTree queries) follows the same budget: OMP_NUM_THREADS when
set, else the cores this process may run on — a lone input in the window or a one-input batch uses
the whole machine, a worker of a pool one core.
"""
from __future__ import annotations

import os
import sys
import threading


def thread_count() -> int:
    """Threads this process may use: $OMP_NUM_THREADS when set to a positive integer, else its cores."""
    env = os.environ.get("OMP_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class single_threaded_blas:
    """Context: BLAS (OpenBLAS, MKL, …) runs one thread in this process while it is open.

    The pipeline's BLAS calls are narrow — ≤ 36-column chunks of 2¹³ rows (Zernike, PVr), 3 × N pose
    products, banded Cholesky solves of the B-spline (band ≈ 3 × the knots across) — where BLAS
    threads only synchronise, and OpenBLAS's waiting threads spin: with another process on the cores
    (a colleague's job, a second batch) they were descheduled mid-call and the summary's B-spline
    solve took 15–26 s instead of 0.23 s, a 50,000-point input 60 s instead of 10 s
    (benchmarks/bench_input.py, 2026-11-23). The batch ran its inputs inside this context; since
    2026-11-27 ``run_pipeline``, the summary and ``write_outputs`` open it themselves, so the window
    and the Python API get it too (a 200,000-point raster in the API with one other busy process:
    10.6–11.3 s with the default two BLAS threads, 2.9–3.5 s with one; zernike 1.5 s → 0.06 s).
    Neighbour searches thread by themselves (``thread_count``), untouched.

    scipy's own OpenBLAS (loaded by the first ``scipy.linalg`` import) is loaded as the first context
    opens, so that it is limited with numpy's and given back its threads after: the window and the
    Python API leave the caller's BLAS as they found them. The environment is not touched (until
    2026-11-27 ``OPENBLAS_NUM_THREADS`` was set to 1 meanwhile, so that scipy's BLAS, loaded inside,
    kept one thread for good; and changing the environment from the window's worker thread while
    Qt's threads may read it is not safe). The batch's pool workers get their one thread from their
    environment at start (core.executors).

    Re-entrant and shared between threads: the BLAS thread count is the process's, not a thread's,
    so the first context to open sets it and the last to close restores it (a count under a lock) —
    two pipelines in two threads of the window must not restore the other's setting half-way. A
    forked child (a figure process, a Monte Carlo worker) gets a fresh lock (``os.register_at_fork``):
    one held by another thread at the fork would never be released there. threadpoolctl (≥ 3.6) lets
    only the first thread that set OpenBLAS's (process-wide) pool set it again and silently ignores
    the others: the window's worker thread would have kept two BLAS threads after any other thread
    had set a limit. This context takes that control for its set and its restore, and leaves no
    thread holding it."""

    # the process's one BLAS setting, and how many contexts hold it (see the class doc)
    _lock = threading.Lock()
    _depth = 0
    _held = None

    def __enter__(self):
        cls = type(self)
        with cls._lock:
            if cls._depth == 0:
                cls._held = _limit_blas()
            cls._depth += 1
        return self

    def __exit__(self, *exc):
        cls = type(self)
        with cls._lock:
            cls._depth -= 1
            if cls._depth > 0:
                return False
            limits, cls._held = cls._held, None
            _release_blas_control()
            limits.restore_original_limits()
            _release_blas_control()
        return False


def _limit_blas():
    """One BLAS thread (single_threaded_blas' doc); returns threadpoolctl's limiter, to restore."""
    import importlib.util

    from threadpoolctl import threadpool_limits

    if "scipy.linalg" not in sys.modules and importlib.util.find_spec("scipy") is not None:
        import scipy.linalg  # noqa: F401 — its OpenBLAS loaded now, so limited now and restored after
    _release_blas_control()
    limits = threadpool_limits(1, user_api="blas")
    _release_blas_control()
    return limits


def _fresh_lock_in_child() -> None:
    single_threaded_blas._lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_fresh_lock_in_child)


def _release_blas_control() -> None:
    """Let the next thread that sets OpenBLAS's thread count do it (threadpoolctl's rule, see
    single_threaded_blas); nothing where threadpoolctl has no such rule."""
    try:
        from threadpoolctl import OpenBLASController
    except ImportError:
        return
    clear = getattr(OpenBLASController, "clear_controlling_thread", None)
    if clear is not None:
        clear(force=True)


def in_chunks(fn, n: int, size: int, threads: int | None = None) -> list:
    """[fn(slice)] over consecutive slices of ``size`` of range(n), in order, on up to ``threads``
    threads (default and ceiling: ``thread_count()``). For numpy work that releases the GIL (gathers,
    partitions, einsum, ufuncs) where each slice writes its own part of an output or returns it: the
    bits are those of one thread, whatever the thread count."""
    slices = [slice(lo, min(lo + size, n)) for lo in range(0, n, size)]
    threads = min(thread_count() if threads is None else min(threads, thread_count()), len(slices))
    if threads <= 1:
        return [fn(sl) for sl in slices]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads) as pool:
        return list(pool.map(fn, slices))


class interrupts_deferred:
    """Context: SIGINT and SIGTERM that arrive inside it take effect as it closes, with the handler
    they would have met (Python's KeyboardInterrupt, the batch's SIGTERM one, the default action).
    Main thread only (where Python runs signal handlers); a signal ignored (nohup) stays ignored.

    - core/workerpool.py: a worker is spawned by starting a fresh interpreter and then writing its
      start-up data into a pipe; a Ctrl-C or SIGTERM between the two left the child reading a pipe
      its parent had closed, and its traceback ("EOFError: Ran out of input") on the terminal (a
      review: 1 run in 8 with SIGTERM 0.3 s after the start). Deferred, the parent finishes the write
      (milliseconds), then the signal acts, and the worker is stopped with the others.
    - scipy's cKDTree.query(workers=…) (``threaded_query``) starts Python threads running C code and
      joins them: a KeyboardInterrupt raised in the join left those threads reading the query's
      arrays as they were freed — a sequential batch interrupted at the wrong moment ended in a
      segmentation fault after writing its summary (2 runs in ~36, an independent review;
      faulthandler showed a thread with no Python frame of its own, as cKDTree's are)."""

    def __enter__(self):
        import signal

        self._old = {}
        self._got: list[int] = []
        if threading.current_thread() is not threading.main_thread():
            return self
        for sig in (signal.SIGINT, signal.SIGTERM):
            old = signal.getsignal(sig)
            if old not in (signal.SIG_IGN, None):
                self._old[sig] = old
                signal.signal(sig, lambda signum, frame: self._got.append(signum))
        return self

    def __exit__(self, *exc):
        import signal

        for sig, old in self._old.items():
            signal.signal(sig, old)
        if self._got:
            signal.raise_signal(self._got[0])  # now, with the handler it would have met
        return False


def threaded_query(tree, *args, **kwargs):
    """``tree.query(*args, **kwargs)`` (a scipy cKDTree's, with ``workers``) with interruptions
    deferred to its end (``interrupts_deferred``)."""
    with interrupts_deferred():
        return tree.query(*args, **kwargs)
