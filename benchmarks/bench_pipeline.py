"""Seconds and peak memory per stage on a generated 1,000,000-point raster.

    .venv/bin/python benchmarks/bench_pipeline.py [--points 1000000] [--keep DIR]

The raster samples the paper-002 asphere (R 3000 mm, k −0.98) over ±640 mm with 0.3 µm noise and is
written as an x,y,z CSV first (not timed). Stages: read the CSV, run each foundation step, write CSV
and PLY, read the PLY back. Peak memory is the largest block of Python/numpy allocations alive during
the stage (tracemalloc, on a separate run so the tracer does not slow the timed ones), plus the process's peak RSS at the end. Not a timed test: run it by hand and
put the table in benchmarks/README.md.
"""
from __future__ import annotations

import argparse
import resource
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from pointspro.core.io import read_cloud, write_cloud
from pointspro.core.pipeline import run_pipeline
from pointspro.core.recipe import parse_recipe
from pointspro.core.surfaces import EvenAsphere


def make_raster(n_points: int, path: Path) -> None:
    side = int(round(np.sqrt(n_points)))
    g = np.linspace(-640.0, 640.0, side)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    s = EvenAsphere(1 / 3000, -0.98, {4: 7e-13, 6: 1e-19})
    z = s.sag(x, y) + np.random.default_rng(0).normal(0, 0.3e-3, x.size)
    with open(path, "w") as f:
        f.write("x,y,z\n")
        np.savetxt(f, np.column_stack([x, y, z]), fmt="%.6f", delimiter=",")


def measure(label, fn, rows):
    """Time a stage (best of 2, no tracer), then run it once more under tracemalloc for its peak."""
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rows.append((label, min(times), peak / 2 ** 20))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--keep", help="keep the generated files in this folder")
    args = ap.parse_args()
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="pointspro-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    src = folder / "raster.csv"
    make_raster(args.points, src)
    rows = []
    cloud = measure("read CSV", lambda: read_cloud(src), rows)
    recipe = parse_recipe({"pointspro": 1, "steps": [
        {"aperture": {"diameter": 1250}},
        {"manual_edit": {"remove": list(range(0, cloud.n, 997))}},
        {"transform": {"pose": {"alpha_deg": 0.17, "beta_deg": -0.01, "dx": 0.8, "dy": 4, "dz": 12.5}}},
    ]})
    cur = cloud
    for st in recipe.steps:
        single = parse_recipe({"pointspro": 1, "steps": [st.to_yaml_entry()]})
        cur = measure(f"step {st.id}", lambda: run_pipeline(cur, single).cloud, rows)
    measure("write CSV", lambda: write_cloud(cur, folder / "out.csv"), rows)
    measure("write PLY", lambda: write_cloud(cur, folder / "out.ply"), rows)
    measure("read PLY", lambda: read_cloud(folder / "out.ply"), rows)
    print(f"{cloud.n} points read, {cur.n} after the steps "
          f"({src.stat().st_size / 2 ** 20:.0f} MB CSV in)\n")
    print("| stage | seconds | peak MiB |\n|---|---:|---:|")
    for label, dt, mib in rows:
        print(f"| {label} | {dt:.2f} | {mib:.0f} |")
    print(f"\nprocess peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
