"""Megapixel interferograms (issue 26): a circular map of 1M … 16M valid points through
``zernike {terms: 36, remove: [piston, tilt, power]}`` + ``bspline_map {}``, all outputs.

    .venv/bin/python benchmarks/bench_large_map.py                       # 1M, 4M, 12.6M, 16M
    .venv/bin/python benchmarks/bench_large_map.py --points 1e6 4e6      # chosen sizes
    .venv/bin/python benchmarks/bench_large_map.py --points 1e6 --profile   # + cProfile, in process
    .venv/bin/python benchmarks/bench_large_map.py --points 1e6 --stages    # + stage table, in process
    .venv/bin/python benchmarks/bench_large_map.py --points 4e6 --cloud-format csv

Input: the issue's maps — binary PLY, x, y, z float64 (mm), the pixels of a square n × n grid
(pitch 100/n mm) that lie inside a 100 mm aperture, heights a few Zernike terms (power, astigmatism,
coma, spherical; ~0.5 µm) plus 2 nm of white noise (fixed seed). Sizes are the number of valid
points asked for; n = round(√(4N/π)).

Each size runs ``python -m pointspro.core.cli --batch … --quiet`` in a fresh process, one at a time
(imports included): wall time and peak RSS from os.wait4, best of ``--repeat`` (default 1 above
4M points, else 2). ``--stages`` adds a run in this process with the stage table (read, each step,
summary, each file: core.batch.write_outputs(timings=…)). The fixed numpy workload (``lstsq`` of
10⁶ × 36 plus a sort of 2·10⁶, bench_input.py's) is measured in the same run for the ratio.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_input import bandwidth_bytes_per_s, stage_table, total_seconds, workload_seconds  # noqa: E402

RECIPE = """pointspro: 1
steps:
  - zernike: {terms: 36, remove: [piston, tilt, power]}
  - bspline_map: {}
"""
SIZES = (1_000_000, 4_000_000, 12_600_000, 16_000_000)


def make_map(path: Path, npoints: int, seed: int = 0) -> int:
    """Write the circular map as binary PLY (x, y, z float64, mm); returns the number of points.
    Row by row in blocks, so the generator holds a few MB whatever the size."""
    n = int(round(np.sqrt(4 * npoints / np.pi)))
    h = 100.0 / n
    rng = np.random.default_rng(seed)
    axis = -50.0 + h * (np.arange(n) + 0.5)
    # count first (the header states it)
    count = 0
    for y in axis:
        count += int(np.count_nonzero(axis * axis + y * y <= 2500.0))
    header = ("ply\nformat binary_little_endian 1.0\ncomment issue-26 benchmark map (mm)\n"
              f"element vertex {count}\nproperty double x\nproperty double y\nproperty double z\n"
              "end_header\n").encode("ascii")
    with open(path, "wb") as f:
        f.write(header)
        for y in axis:
            x = axis[axis * axis + y * y <= 2500.0]
            u, v = x / 50.0, y / 50.0
            r2 = u * u + v * v
            z = 1e-4 * (2 * r2 - 1) + 8e-5 * (u * u - v * v) + 5e-5 * (3 * r2 - 2) * u \
                + 3e-5 * (6 * r2 * r2 - 6 * r2 + 1) + 2e-6 * rng.standard_normal(len(x))
            block = np.empty((len(x), 3))
            block[:, 0], block[:, 1], block[:, 2] = x, y, z
            f.write(block.astype("<f8").tobytes())
    return count


def run_cli(recipe: Path, data: Path, out: Path, extra=()) -> tuple[float, float]:
    """(wall s, peak RSS MiB) of one `--batch` in a fresh process."""
    cmd = [sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(data), "--out",
           str(out), "--quiet", *extra]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(cmd)}\n{err}")
    return wall, ru.ru_maxrss / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=float, nargs="+", default=list(SIZES))
    ap.add_argument("--repeat", type=int, default=None)
    ap.add_argument("--stages", action="store_true")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--cloud-format", default=None)
    ap.add_argument("--tmp", default=None, help="folder for the inputs and outputs (default: a "
                    "temporary folder)")
    args = ap.parse_args()
    w = workload_seconds()
    bw = bandwidth_bytes_per_s()
    print(f"fixed workload (lstsq 10⁶×36 + sort 2·10⁶): {w:.3f} s; memory bandwidth {bw / 1e9:.1f} GB/s")
    extra_cli = ["--cloud-format", args.cloud_format] if args.cloud_format else []
    extra_wo = {"cloud_format": args.cloud_format} if args.cloud_format else {}
    table = []
    with tempfile.TemporaryDirectory(prefix="pointspro-large-", dir=args.tmp) as d:
        tmp = Path(d)
        recipe = tmp / "recipe.yaml"
        recipe.write_text(RECIPE, encoding="utf-8")
        for target in args.points:
            target = int(target)
            data = tmp / f"map_{target}.ply"
            npts = make_map(data, target)
            repeat = args.repeat or (1 if npts > 4_500_000 else 2)
            runs = []
            for k in range(repeat):
                out = tmp / f"out_{target}_{k}"
                runs.append(run_cli(recipe, data, out, extra_cli))
                written = sum(p.stat().st_size for p in (out / data.stem).iterdir())
                cloud_file = [p.name for p in (out / data.stem).iterdir() if p.name.startswith("cloud.")]
                import shutil

                shutil.rmtree(out)
            wall = min(r[0] for r in runs)
            rss = max(r[1] for r in runs)
            table.append((npts, wall, rss, written, cloud_file))
            print(f"\n### {npts:,} points ({data.stat().st_size / 1e6:.0f} MB PLY)\nwhole command: "
                  f"{wall:.2f} s (runs: {', '.join(f'{r[0]:.2f}' for r in runs)}) = {wall / w:.1f}× the "
                  f"workload; peak RSS {rss:.0f} MiB = {rss * 2**20 / npts:.0f} B/point; "
                  f"{wall / npts * 1e6:.2f} µs/point; written {written / 1e6:.0f} MB ({', '.join(cloud_file)})")
            if args.stages or args.profile:
                rows = stage_table(recipe, data, tmp / f"stages_{target}", args.profile, extra_wo)
                print("\n| stage | seconds |\n|---|---:|")
                for stage, s in rows:
                    print(f"| {stage} | {s:.3f} |")
                print(f"| total in process | {total_seconds(rows):.3f} |")
            data.unlink()
    print(f"\nfixed workload {w:.3f} s\n\n| valid points | wall | × workload | peak RSS | bytes/point | "
          "µs/point | outputs |\n|---:|---:|---:|---:|---:|---:|---|")
    for npts, wall, rss, written, cf in table:
        print(f"| {npts:,} | {wall:.1f} s | {wall / w:.1f}× | {rss / 1024:.2f} GiB | "
              f"{rss * 2**20 / npts:.0f} | {wall / npts * 1e6:.2f} | {written / 1e6:.0f} MB ({', '.join(cf)}) |")


if __name__ == "__main__":
    main()
