"""`fiducials` + `volumetric {frame: reference}` on simulated 000 §2.4 cases (issue 16): workpiece error
and seconds per seed.

    .venv/bin/python benchmarks/bench_fiducials.py [--seeds 0 1 2 3] [--kinds fourier kinematic]

Cases (core.calibration.fiducial_sim.case_000): 24 balls at random in 200 × 40 × 50 mm, a random smooth
field of 1.3 µm RMS |e|, 0.2 µm probing and 0.2 µm calibration noise, 3,000 workpiece points inside
the workspace. Columns: RMS |corrected − true| over the workpiece (µm) after the GP and after the
affine transform alone; the chosen kernel ("none": no GP, the transform alone); its 6-fold
cross-validated RMS at held-out fiducials and that of "none" (µm, |e|, includes their noise; the
transform re-fitted in each fold too); the step's seconds (Monte Carlo 2000 runs, the default).

    .venv/bin/python benchmarks/bench_fiducials.py --coverage [--seeds 0 1 … 7]

Issue 16 part 1, the coverage of u: five layouts of 24 balls (``layout``: two planes z = 0 and 50 with
the workpiece between; 4 random balls on each face of the box; a 6 × 2 × 2 grid on the box's edges; balls
in the left half with the workpiece reaching 50 mm beyond them; the ordinary random layout of 000 §2.4),
fourier fields on even seeds and kinematic on odd, 3,000 workpiece points. Per seed: the share of the
workpiece's per-axis errors within 2u with the GP's σ alone (the model file without ``u_calibration``,
as before) and with the blocked cross-validation's distance term, the median u (µm) of both, the
workpiece RMS |error| (µm, the same for both: only u changes) and the step's seconds (no Monte Carlo).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from pointspro.core import PointCloud  # noqa: E402
from pointspro.core.calibration import volumetric_model as vm  # noqa: E402
from pointspro.core.calibration.fiducial_sim import EXTENT, LOW, case_000, machine_frame, smooth_field  # noqa: E402
from pointspro.core.calibration.fiducials import PARAMS, AffineFit, ball_points  # noqa: E402
from pointspro.core.step import Context  # noqa: E402
from pointspro.plugins.fiducials import FiducialsStep  # noqa: E402
from pointspro.plugins.volumetric import VolumetricStep  # noqa: E402

LAYOUTS = ("two_planes", "box_faces", "box_grid", "one_side", "ordinary")


def layout(name, rng, n=24):
    """(24 reference centres, the workpiece's box lo, hi) of a coverage layout (module doc), mm."""
    if name == "box_faces":
        ref = []
        for ax in range(3):
            for side in (0.0, 1.0):
                u = rng.uniform(0, 1, (4, 3))
                u[:, ax] = side
                ref.append(LOW + u * EXTENT)
        ref = np.vstack(ref)
    elif name == "box_grid":
        g = np.array([[x, y, z] for x in np.linspace(0, 1, 6) for y in (0.0, 1.0) for z in (0.0, 1.0)])
        g[:, 0] = np.clip(g[:, 0] + rng.uniform(-0.03, 0.03, n), 0, 1)
        ref = LOW + g * EXTENT
    else:
        ref = LOW + rng.uniform(0, 1, (n, 3)) * EXTENT * ([0.5, 1, 1] if name == "one_side" else 1)
        if name == "two_planes":
            ref[:, 2] = np.where(np.arange(n) % 2, 50.0, 0.0)
    lo, hi = ref.min(0), ref.max(0)
    if name == "one_side":
        lo[0], hi[0] = -50.0, 50.0  # half the workpiece lies up to 50 mm beyond the balls
    return ref, lo, hi


def coverage(name, seed, m=3000):
    rng = np.random.default_rng(1000 * seed + zlib.crc32(name.encode()) % 997)
    ref, lo, hi = layout(name, rng)
    f = smooth_field(seed, ("fourier", "kinematic")[seed % 2], 1.3, EXTENT, machine_frame(LOW))
    true_c = machine_frame(ref)
    pts, ids = ball_points(true_c - f(true_c), noise=0.2e-3, seed=seed)
    given = ref + rng.normal(0, 0.2e-3, ref.shape)
    W = lo + rng.uniform(0, 1, (m, 3)) * (hi - lo)
    TW = machine_frame(W)
    d = Path(tempfile.mkdtemp(prefix="bench-fidcov-"))
    (d / "reference.csv").write_text("fiducial,x,y,z\n" + "".join(
        f"{i + 1},{float(r[0])!r},{float(r[1])!r},{float(r[2])!r}\n" for i, r in enumerate(given)))
    t0 = time.perf_counter()
    res = FiducialsStep().run(PointCloud.from_xyz(*pts.T, fiducial=ids),
                              FiducialsStep.Params(reference="reference.csv", monte_carlo_runs=0), Context(base_dir=d))
    t = time.perf_counter() - t0
    text = res.artifacts["volumetric_model.json"]
    old = json.loads(text)  # the model file as before the blocked cross-validation: u = the GP's σ
    for k in ("u_calibration", "sha256", "pointspro_volumetric_model"):
        old.pop(k, None)
    out = []
    for name_, body in (("gp", vm.dumps(old)), ("blocked", text)):
        (d / f"{name_}.json").write_text(body, encoding="utf-8")
        o = VolumetricStep().run(PointCloud(TW - f(TW)), VolumetricStep.Params(model=f"{name_}.json", frame="reference"),
                                 Context(base_dir=d))
        err = o.cloud.xyz - W
        u = np.column_stack([o.cloud[c] for c in ("u_x", "u_y", "u_z")])
        out.append((float(np.mean(np.abs(err) <= 2 * u)), float(np.median(u) * 1e3),
                    float(np.sqrt(np.mean(np.sum(err**2, axis=1))) * 1e3)))
    return out, t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--kinds", nargs="+", default=["fourier", "kinematic"])
    ap.add_argument("--coverage", action="store_true", help="the coverage of 2u on five layouts (module doc)")
    ap.add_argument("--layouts", nargs="+", default=list(LAYOUTS))
    args = ap.parse_args()
    if args.coverage:
        print("| layout | seed | 2u coverage, GP σ | with the distance term | median u µm (GP → term) | RMS µm | s |\n"
              "|---|---:|---:|---:|---:|---:|---:|")
        for name in args.layouts:
            for seed in args.seeds:
                ((c0, u0, r0), (c1, u1, _)), t = coverage(name, seed)
                print(f"| {name} | {seed} | {c0:.3f} | {c1:.3f} | {u0:.3f} → {u1:.3f} | {r0:.3f} | {t:.1f} |", flush=True)
        return
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
