"""One whole input, end to end: wall time, peak RSS and a stage table, against a fixed numpy workload.

    .venv/bin/python benchmarks/bench_input.py                  # all three cases
    .venv/bin/python benchmarks/bench_input.py --case raster    # raster | map | small
    .venv/bin/python benchmarks/bench_input.py --profile        # + cProfile's top functions

Cases (issue 17):
  raster  1,000,000-point CMM raster (bench_batch's generator: the example part's probe-centre points,
          misaligned, 0.3 µm noise, five spikes) through the example recipe, all outputs;
  map     the real Zygo MetroPro map tests/data/realdata/metropro-1.dat (307,200 px) with
          zernike {terms: 4, remove: [piston, tilt]} + bspline_map {};
  small   a 50,000-point raster through the example recipe, all figures.

Each case is timed twice as a user runs it — `python -m pointspro.core.cli --batch … --quiet` in a
fresh process (imports included), wall time and the process's peak RSS (os.wait4) — and once in
process for the stage table: read, each step, the summary, each file written (core.batch's
``timings``). The fixed workload (`lstsq` of 10⁶ × 36 plus a sort of 2·10⁶, best of 3) is measured
in the same run so the ratios travel between machines. The physical floor beside it: bytes read and
written, at the machine's memory bandwidth (a 256 MiB copy), i.e. one pass over the data.
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
from bench_batch import make_input  # noqa: E402

MAP_RECIPE = """pointspro: 1
steps:
  - zernike: {terms: 4, remove: [piston, tilt]}
  - bspline_map: {}
"""


def workload_seconds() -> float:
    """The fixed numpy workload the goals are stated against (best of 3)."""
    rng = np.random.default_rng(0)
    A = rng.standard_normal((1_000_000, 36))
    b = rng.standard_normal(1_000_000)
    s = rng.standard_normal(2_000_000)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        np.linalg.lstsq(A, b, rcond=None)
        np.sort(s)
        best = min(best, time.perf_counter() - t0)
    return best


def bandwidth_bytes_per_s() -> float:
    a = np.ones(32 * 2**20)  # 256 MiB
    b = np.empty_like(a)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - t0)
    return 2 * a.nbytes / best  # read + write


OUTPUTS = "all outputs written"


def total_seconds(rows) -> float:
    """The in-process total of a stage table: read, steps, summary and the outputs' wall time (the
    per-file rows are the seconds of whichever process drew each file, shared out: not added)."""
    return sum(s for stage, s in rows if not stage.startswith("write "))


def run_cli(recipe: Path, data: Path, out: Path, extra=()) -> tuple[float, float]:
    """(wall s, peak RSS MiB) of one `--batch` in a fresh process."""
    cmd = [sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(data), "--out", str(out),
           "--quiet", *extra]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}\n{err}")
    return wall, ru.ru_maxrss / 1024


def stage_table(recipe: Path, data: Path, out: Path, profile: bool = False,
                extra: dict | None = None) -> list[tuple[str, float]]:
    """[(stage, seconds)] of one input run in process (imports already paid); ``extra``: keywords
    of write_outputs (bench_large_map.py passes the cloud format). numpy without its huge-page advice,
    as in the console command (core/cli.py without_hugepage_advice)."""
    from pointspro.core.cli import without_hugepage_advice
    from pointspro.core.parallel import single_threaded_blas

    without_hugepage_advice()  # as the console command runs (core/cli.py)
    with single_threaded_blas():  # as the batch command runs an input (core.executors)
        return _stage_table(recipe, data, out, profile, extra or {})


def _stage_table(recipe, data, out, profile, extra):
    from pointspro.core.batch import write_outputs
    from pointspro.core.io import read_cloud
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import load_recipe

    rec = load_recipe(recipe)
    prof = None
    if profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    t0 = time.perf_counter()
    cloud = read_cloud(data, **rec.input)
    rows = [("read", time.perf_counter() - t0)]
    result = run_pipeline(cloud, rec)
    rows += [(f"step {r.id}", r.seconds) for r in result.steps]
    t0 = time.perf_counter()
    result.summary()
    rows.append(("summary (RMS, PV, PVr, slope RMS)", time.perf_counter() - t0))
    timings: dict = {}
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    write_outputs(out / data.stem, str(data), rec, result, timings=timings, fork_csv=True, **extra)
    wall = time.perf_counter() - t0
    rows += [(f"write {k}", v) for k, v in timings.items()]
    from pointspro.core.parallel import thread_count

    rows.append((f"{OUTPUTS} (wall; the files above drawn by up to {thread_count()} processes)", wall))
    if prof is not None:
        import pstats

        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(30)
    return rows


def bytes_of(paths) -> int:
    return sum(p.stat().st_size for p in paths if p.is_file())


def case(name: str, tmp: Path, profile: bool):
    if name == "raster":
        data = tmp / "raster_1m.csv"
        make_input(data, 1_000_000)
        recipe = ROOT / "resources/example/recipe.yaml"
    elif name == "small":
        data = tmp / "raster_50k.csv"
        make_input(data, 50_000)
        recipe = ROOT / "resources/example/recipe.yaml"
    else:
        data = ROOT / "tests/data/realdata/metropro-1.dat"
        recipe = tmp / "map_recipe.yaml"
        recipe.write_text(MAP_RECIPE, encoding="utf-8")
    runs = [run_cli(recipe, data, tmp / f"cli_{name}_{k}") for k in range(2)]
    rows = stage_table(recipe, data, tmp / f"stages_{name}", profile)
    written = bytes_of((tmp / f"cli_{name}_0" / data.stem).iterdir())
    return data, runs, rows, data.stat().st_size, written


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", choices=["raster", "map", "small", "all"], default="all")
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    w = workload_seconds()
    bw = bandwidth_bytes_per_s()
    print(f"fixed workload (lstsq 10⁶×36 + sort 2·10⁶): {w:.3f} s; memory bandwidth {bw / 1e9:.1f} GB/s\n")
    goals = {"raster": 6.0, "map": 2.0, "small": None}
    with tempfile.TemporaryDirectory(prefix="pointspro-input-") as d:
        tmp = Path(d)
        for name in (["raster", "map", "small"] if args.case == "all" else [args.case]):
            data, runs, rows, nread, nwritten = case(name, tmp, args.profile)
            best = min(r[0] for r in runs)
            rss = max(r[1] for r in runs)
            goal = goals[name]
            print(f"### {name}: {data.name}")
            print(f"whole command (fresh process, imports included): {best:.2f} s "
                  f"(runs: {', '.join(f'{r[0]:.2f}' for r in runs)}) = {best / w:.2f}× the workload"
                  + (f" (goal ≤ {goal:g}×)" if goal else " (goal ≤ 1 s)") + f"; peak RSS {rss:.0f} MiB")
            print(f"bytes read {nread / 1e6:.1f} MB, written {nwritten / 1e6:.1f} MB; one pass at memory "
                  f"bandwidth: {(nread + nwritten) / bw * 1e3:.1f} ms\n")
            print("| stage | seconds |\n|---|---:|")
            for stage, s in rows:
                print(f"| {stage} | {s:.3f} |")
            print(f"| total in process | {total_seconds(rows):.3f} |\n")


if __name__ == "__main__":
    main()
