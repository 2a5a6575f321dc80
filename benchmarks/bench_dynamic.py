"""`dynamic` on 004's point count: 290,011 samples at 1 kHz, with a saved model and with the
identification from the calibration steps inside the step.

    .venv/bin/python benchmarks/bench_dynamic.py [--samples 290011]

Data: tests/paper004.py (spiral over the 25.4 mm off-axis parabola at 30 rpm, eq-12 loop); the
calibration: 10 up / 10 down steps of 10 µm (8,400 samples). Best of 3.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from pointspro.core import PointCloud  # noqa: E402
from pointspro.core.step import Context  # noqa: E402
from pointspro.plugins.dynamic import DynamicStep  # noqa: E402
from tests import paper004 as p4  # noqa: E402


def best(fn, n=3):
    out = None
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return min(ts), out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=290_011)
    args = ap.parse_args()
    d = Path(tempfile.mkdtemp())
    t, xd, ref = p4.calibration()
    np.savetxt(d / "cal.csv", np.column_stack([t, xd, ref]), delimiter=",", header="t,xd,ref",
               comments="", fmt="%.12g")
    revs = args.samples / p4.FS * 30 / 60
    s = p4.spiral_scan(radius=0.1 * revs)
    n = min(args.samples, len(s["t"]))
    cloud = PointCloud.from_xyz(s["x"][:n], s["y"][:n], s["z"][:n], t=s["t"][:n], xd=s["xd"][:n],
                                xc=s["xc"][:n])
    step = DynamicStep()
    sec_id, res = best(lambda: step.run(cloud, DynamicStep.Params(calibration="cal.csv"), Context(base_dir=d)))
    (d / "m.json").write_text(res.artifacts["dynamic_model.json"], encoding="utf-8")
    sec, res2 = best(lambda: step.run(cloud, DynamicStep.Params(model="m.json"), Context(base_dir=d)))
    before = s["z"][:n] - s["h"][:n]
    after = res2.cloud.z - s["h"][:n]
    print("| run | samples | seconds | error before RMS / PV µm | after RMS nm / PV µm |\n|---|---:|---:|---|---|")
    for name, sec_ in (("dynamic, saved model", sec), ("dynamic, identification inside", sec_id)):
        print(f"| {name} | {n:,} | {sec_:.3f} | {np.std(before) * 1e3:.2f} / {np.ptp(before) * 1e3:.2f} | "
              f"{np.std(after) * 1e6:.1f} / {np.ptp(after) * 1e3:.3f} |")


if __name__ == "__main__":
    main()
