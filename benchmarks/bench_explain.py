"""`pointspro explain` on a 290,011-point spiral against the whole effect library.

    .venv/bin/python benchmarks/bench_explain.py [--points 290011] [--bootstrap 10]

Model: the even asphere of tests/test_explain.py (R 200 mm, k −0.5), a spiral of radius 20 mm at
60 rpm sampled at 1 kHz, 2 nm noise; the measurement hides spindle tilt (0.3″, 2 lobes) and a 61 Hz
vibration (8 nm). Wall time of `explain` (reading, selection with bootstrap, figures, files).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pointspro.core import PointCloud  # noqa: E402
from pointspro.core.explain.workflow import explain  # noqa: E402
from pointspro.core.io import write_csv  # noqa: E402
from pointspro.core.simulate.model import ModelSpec, simulate  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=290_011)
    ap.add_argument("--bootstrap", type=int, default=10)
    args = ap.parse_args()
    revs = args.points / 1000.0  # 60 rpm at 1 kHz: 1000 samples a revolution
    scan = {"type": "spiral", "radius": 20.0, "rpm": 60.0, "pitch": 20.0 / revs, "fs": 1000.0}
    base = [{"pose": {"alpha_deg": 0.001, "dz": 0.001}}]
    spec = lambda eff, seed: ModelSpec.model_validate({  # noqa: E731
        "pointspro_model": 1, "surface": {"type": "even_asphere", "R": 200.0, "k": -0.5, "aperture": 50.0},
        "scan": scan, "probe": {"noise": 2e-6}, "seed": seed, "effects": eff})
    truth = spec(base + [{"spindle_tilt": {"a2_arcsec": 0.3}},
                         {"vibration": {"frequency_hz": 61.0, "amplitude": 8e-6}}], 1)
    d = Path(tempfile.mkdtemp())
    sim = simulate(truth)
    write_csv(PointCloud.from_xyz(sim["x"], sim["y"], sim["z"], t=sim["t"], c=sim["c"]), d / "meas.csv")
    (d / "base.yaml").write_text(spec(base, 2).to_yaml(), encoding="utf-8")
    t0 = time.perf_counter()
    rep = explain(d / "meas.csv", d / "out", d / "base.yaml", bootstrap=args.bootstrap)
    sec = time.perf_counter() - t0
    print("| points | bootstrap | seconds | verdict | found | gap before → after (nm RMS) |\n|---:|---:|---:|---|---|---|")
    print(f"| {len(sim['x']):,} | {args.bootstrap} | {sec:.1f} | {rep['verdict']} | "
          f"{', '.join(f['effect'] for f in rep['found'])} | {rep['gap_before']['rms_um'] * 1e3:.2f} → "
          f"{rep['gap_after']['rms_um'] * 1e3:.2f} |")


if __name__ == "__main__":
    main()
