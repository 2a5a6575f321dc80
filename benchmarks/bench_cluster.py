"""A real Dask cluster against the process pool: inputs per second on 1, 2, 4 … workers.

    .venv/bin/python benchmarks/bench_cluster.py [--inputs 24] [--points 10000] [--workers 1,2,4]
                                                 [--figures none] [--ship]

For each worker count N: `pointspro --batch` with `--workers N` (the process pool), then on a cluster
started as the README says — `dask scheduler` and N `dask worker --nworkers 1 --nthreads 1` processes
on loopback (free ports), stopped by their ids afterwards — with `--scheduler` (shared folder) and,
with `--ship`, the inputs sent as bytes. Wall time of the whole command (start of Python, connection,
pre-flight, the inputs, summary). One simulated CMM measurement of the example part
(benchmarks/bench_batch.py) hard-linked under the input names; the example recipe.

The overhead per input is (cluster seconds − pool seconds) / inputs: what the scheduler, the
transfers and the pre-flight cost each input at that count; `check s` is `--check-only` alone
(connection and pre-flight on every worker).
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_batch import make_input  # noqa: E402
from bench_batch import run as run_batch  # noqa: E402

DASK = Path(sys.executable).parent / "dask"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """`dask scheduler` + n workers, each its own process group; stopped by pid on exit."""

    def __init__(self, n: int, home: Path):
        from distributed import Client

        self.address = f"tcp://127.0.0.1:{free_port()}"
        self.procs = []
        self.log = open(home / f"dask-{n}.log", "ab")  # noqa: SIM115 — closed in stop()
        self._start("scheduler", "--host", "127.0.0.1", "--port", self.address.rsplit(":", 1)[1],
                    "--no-dashboard", cwd=home)
        for _ in range(n):
            self._start("worker", self.address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                        "--host", "127.0.0.1", "--local-directory", str(home), cwd=home)
        with Client(self.address, timeout="60s") as c:
            c.wait_for_workers(n, timeout=120)

    def _start(self, *args, cwd):
        self.procs.append(subprocess.Popen([str(DASK), *args], cwd=cwd, stdout=self.log,
                                           stderr=subprocess.STDOUT, start_new_session=True))

    def stop(self):
        for p in self.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
        self.log.close()


def run(files, out: Path, extra) -> float:
    """Wall seconds of one `--batch` of the example recipe into a fresh ``out`` (bench_batch.run)."""
    shutil.rmtree(out, ignore_errors=True)
    return run_batch(None, files, out, extra)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--inputs", type=int, default=24)
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--workers", default="1,2,4", help="comma-separated worker counts")
    ap.add_argument("--figures", default="none", choices=["all", "summary", "none"])
    ap.add_argument("--ship", action="store_true", help="also run with --ship")
    args = ap.parse_args()
    counts = [int(w) for w in args.workers.split(",")]
    tmp = Path(tempfile.mkdtemp(prefix="pointspro-cluster-"))
    try:
        first = tmp / "in" / "m000.csv"
        first.parent.mkdir()
        make_input(first, args.points)
        files = [first]
        for k in range(1, args.inputs):
            f = tmp / "in" / f"m{k:03d}.csv"
            os.link(first, f)
            files.append(f)
        n = args.inputs
        extra = ["--figures", args.figures]
        print(f"{n} inputs of {args.points} points, example recipe, --figures {args.figures}; "
              f"{len(os.sched_getaffinity(0))} cores")
        head = (f"{'workers':>7}  {'pool s':>7}  {'pool in/s':>9}  {'check s':>7}  {'cluster s':>9}  "
                f"{'cluster in/s':>12}  {'overhead ms/input':>17}"
                + (f"  {'ship s':>7}  {'ship in/s':>9}" if args.ship else ""))
        print(head)
        print("-" * len(head))
        for w in counts:
            t_pool = run(files, tmp / "pool", [*extra, "--workers", str(w)])
            cl = Cluster(w, tmp)
            try:
                t0 = time.perf_counter()
                run(files, tmp / "check", ["--scheduler", cl.address, "--check-only"])
                t_check = time.perf_counter() - t0
                t_cl = run(files, tmp / "cluster", [*extra, "--scheduler", cl.address])
                t_ship = run(files, tmp / "ship", [*extra, "--scheduler", cl.address, "--ship"]) \
                    if args.ship else None
            finally:
                cl.stop()
            row = (f"{w:>7}  {t_pool:>7.2f}  {n / t_pool:>9.2f}  {t_check:>7.2f}  {t_cl:>9.2f}  "
                   f"{n / t_cl:>12.2f}  {1e3 * (t_cl - t_pool) / n:>17.0f}")
            if t_ship is not None:
                row += f"  {t_ship:>7.2f}  {n / t_ship:>9.2f}"
            print(row, flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
