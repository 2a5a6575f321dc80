"""How many threads a computation in this process may use (neighbour searches, for now).

The batch's worker processes run with a single-threaded BLAS (core.executors.SINGLE_THREADED sets
OMP_NUM_THREADS=1 and the like): N workers × N threads on N cores ran 5× slower than one worker.
Work that threads by itself (scipy's cKDTree queries) follows the same budget: OMP_NUM_THREADS when
set, else the cores this process may run on — a lone input in the window or a one-input batch uses
the whole machine, a worker of a pool one core.
"""
from __future__ import annotations

import os


def thread_count() -> int:
    """Threads this process may use: $OMP_NUM_THREADS when set to a positive integer, else its cores."""
    env = os.environ.get("OMP_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
