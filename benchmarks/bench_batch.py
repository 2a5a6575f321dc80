"""Night-batch throughput: many inputs with the example recipe, 1 vs N workers vs a Dask LocalCluster.

    .venv/bin/python benchmarks/bench_batch.py [--inputs 200] [--points 50000] [--workers 2]

One simulated CMM measurement of the example part (paper 002 Table 1 set-up, probe-centre points
of a 4 mm ball on a 5 mm raster, misaligned, 0.3 µm noise, a few spikes) with ~50,000 points is
hard-linked under `--inputs` names (the same bytes: the page cache serves them alike), and
`pointspro --batch` runs the example recipe over all of them. Wall time of the whole command.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "resources" / "example"))
from make_example import NOISE, POSE, PROBE_RADIUS, SURFACE, form_error  # noqa: E402


def make_input(path: Path, points: int) -> None:
    rng = np.random.default_rng(0)
    pitch = 1290 * np.sqrt(np.pi / 4 / points)
    g = np.arange(-645, 645.001, pitch)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    keep = np.hypot(x, y) <= 645
    x, y = x[keep], y[keep]
    contact = np.column_stack([x, y, SURFACE.sag(x, y) + form_error(x, y)])
    centre = contact + PROBE_RADIUS * SURFACE.normal(x, y)
    centre[:, 2] += rng.normal(0, NOISE, len(x))
    centre[rng.choice(len(x), 5, replace=False), 2] += 0.015
    np.savetxt(path, POSE.to_measuring(centre), fmt="%.6f", delimiter=",", header="x,y,z", comments="")


def run(args, files, out, extra, env=None) -> float:
    cmd = [sys.executable, "-m", "pointspro.core.cli", "--batch", str(ROOT / "resources/example/recipe.yaml"),
           *map(str, files), "--out", str(out), "--quiet", *extra]
    wall0 = time.time()
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, env=None if env is None else os.environ | env)
    dt = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(res.stderr)
    inputs = json.loads((out / "summary.json").read_text())["inputs"]
    # each input's output folder is renamed into place as its last act (core/io/atomic.py): its
    # ctime is when the input ended, and that less its own seconds is when a worker took it up
    ends = [os.stat(out / Path(e["input"]).stem).st_ctime - wall0 for e in inputs]
    starts = [end - e["seconds"] for end, e in zip(ends, inputs)]
    return Run(dt, sorted(e["seconds"] for e in inputs), min(starts), max(ends))


class Run(float):
    """A run's wall seconds, with each input's own seconds (summary.json) beside them."""

    def __new__(cls, wall: float, per_input: list[float], first_start: float, last_end: float):
        r = super().__new__(cls, wall)
        r.per_input = per_input
        r.first_start, r.last_end = first_start, last_end
        return r


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--inputs", type=int, default=200)
    ap.add_argument("--points", type=int, default=50_000)
    ap.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)))
    ap.add_argument("--repeat", type=int, default=1,
                    help="run the N-worker batch this many times (each listed: a short run varies)")
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster run")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the one-core run (a night's 200 inputs on one core take ~10 min): "
                         "wall time and inputs/s of the N-worker runs only")
    ap.add_argument("--no-shared", action="store_true",
                    help="skip the one-worker run that shares its figures out on the free cores")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="pointspro-batch-"))
    first = tmp / "in" / "m000.csv"
    first.parent.mkdir()
    make_input(first, args.points)
    files = [first]
    for k in range(1, args.inputs):
        p = tmp / "in" / f"m{k:03d}.csv"
        os.link(first, p)
        files.append(p)
    n_pts = sum(1 for _ in open(first)) - 1
    # the baseline on one core: a lone batch process otherwise draws an input's figures on the free
    # cores too (core/io/background.py share_out), which is not the scaling asked about
    t1 = None if args.no_baseline else run(args, files, tmp / "w1", ["--workers", "1"], {"OMP_NUM_THREADS": "1"})
    t1s = None if args.no_shared or args.no_baseline else run(args, files, tmp / "w1s", ["--workers", "1"])
    tns = [run(args, files, tmp / f"wn{i}", ["--workers", str(args.workers)]) for i in range(max(1, args.repeat))]
    td = None if args.no_dask else run(args, files, tmp / "dask",
                                       ["--scheduler", "local", "--workers", str(args.workers)])
    print(f"{args.inputs} inputs of {n_pts:,} points, example recipe, {args.workers} workers\n")
    print("| run | seconds | inputs/s | speed-up | efficiency |\n|---|---:|---:|---:|---:|")
    rows = [] if t1 is None else [("--workers 1, one core (OMP_NUM_THREADS=1)", t1, 1)]
    if t1s is not None:
        rows.append(("--workers 1, its figures shared out on the free cores", t1s, 1))
    for i, tn in enumerate(tns):
        rows.append((f"--workers {args.workers}" + (f" (run {i + 1})" if len(tns) > 1 else ""), tn, args.workers))
    if td is not None:
        rows.append((f"--scheduler local (LocalCluster, {args.workers} processes)", td, args.workers))
    for label, t, w in rows:  # efficiency: speed-up per worker (1 = perfect scaling)
        ratio = "— | —" if t1 is None else f"{t1 / t:.2f}× | {t1 / t / w:.0%}"
        print(f"| {label} | {t:.1f} | {args.inputs / t:.2f} | {ratio} |")
    # where the wall time goes beyond the inputs' own: the ideal is the inputs' seconds spread evenly
    # the timeline: until the first input starts (the batch's and its workers' start-up), the inputs,
    # and after the last one ends (summary.json, the pool's shutdown, the interpreter's exit)
    print("\n| run | an input's seconds: min / median / max | sum / workers | wall − that "
          "| first input began | last input ended | batch returned |\n|---|---|---:|---:|---:|---:|---:|")
    for label, t, w in rows:
        p = t.per_input
        even = sum(p) / w
        print(f"| {label} | {p[0]:.2f} / {p[len(p) // 2]:.2f} / {p[-1]:.2f} | {even:.1f} | {t - even:.1f} "
              f"| {t.first_start:.2f} s | {t.last_end:.2f} s | {float(t):.2f} s |")
    if td is not None:
        print(f"\nDask overhead per input against the process pool: {(td - min(tns)) / args.inputs * 1e3:+.0f} ms "
              f"(cluster start-up included)")


if __name__ == "__main__":
    main()
