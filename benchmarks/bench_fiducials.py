"""`fiducials` + `volumetric {frame: reference}` on simulated 000 §2.4 cases (issue 16): workpiece error
and seconds per seed.

    .venv/bin/python benchmarks/bench_fiducials.py [--seeds 0 1 2 3] [--kinds fourier kinematic]

Cases (core.calibration.fiducial_sim.case_000): 24 balls at random in 200 × 40 × 50 mm, a random smooth
field of 1.3 µm RMS |e|, 0.2 µm probing and 0.2 µm calibration noise, 3,000 workpiece points inside
the workspace. Columns: RMS |corrected − true| over the workpiece (µm) after the GP and after the
affine transform alone; the chosen kernel ("none": no GP, the transform alone); its 6-fold
cross-validated RMS at held-out fiducials and that of "none" (µm, |e|, includes their noise; the
transform re-fitted in each fold too); the step's seconds (Monte Carlo 2000 runs, the default).
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
from pointspro.core.calibration import volumetric_model as vm  # noqa: E402
from pointspro.core.calibration.fiducial_sim import case_000  # noqa: E402
from pointspro.core.calibration.fiducials import PARAMS, AffineFit  # noqa: E402
from pointspro.core.step import Context  # noqa: E402
from pointspro.plugins.fiducials import FiducialsStep  # noqa: E402
from pointspro.plugins.volumetric import VolumetricStep  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--kinds", nargs="+", default=["fourier", "kinematic"])
    args = ap.parse_args()
    print("| field | seed | GP µm | affine only µm | kernel | CV µm | no-GP CV µm | fiducials s |\n"
          "|---|---:|---:|---:|---|---:|---:|---:|")
    for kind in args.kinds:
        for seed in args.seeds:
            c = case_000(seed, kind)
            d = Path(tempfile.mkdtemp(prefix="bench-fid-"))
            (d / "reference.csv").write_text(c.reference_csv(), encoding="utf-8")
            cloud = PointCloud.from_xyz(*c.points.T, fiducial=c.ids)
            t0 = time.perf_counter()
            res = FiducialsStep().run(cloud, FiducialsStep.Params(reference="reference.csv"), Context(base_dir=d))
            t = time.perf_counter() - t0
            (d / "m.json").write_text(res.artifacts["volumetric_model.json"], encoding="utf-8")
            out = VolumetricStep().run(PointCloud(c.work_meas),
                                       VolumetricStep.Params(model="m.json", frame="reference"), Context(base_dir=d))
            tr = vm.loads(res.artifacts["volumetric_model.json"], "m.json").transform
            fit = AffineFit(np.array([tr["params"][n] for n in PARAMS]), np.zeros((12, 12)), 0, 0, 0, None)

            def rms(p):
                return float(np.sqrt(np.mean(np.sum((p - c.work_ref) ** 2, axis=1))) * 1e3)

            sel = res.report["gp_selection"]
            print(f"| {kind} | {seed} | {rms(out.cloud.xyz):.3f} | {rms(fit.inverse(c.work_meas)):.3f} | "
                  f"{sel['chosen']} | {sel['gp_cv_rms_um']['norm']:.3f} | {sel['no_gp_rms_um']['norm']:.3f} | {t:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()
