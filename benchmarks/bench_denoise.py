"""Outlier finding on residual maps: knn_denoise against open3d and scikit-learn, F1 and seconds.

    .venv/bin/python benchmarks/bench_denoise.py [--sizes 50000 1000000]
    .venv/bin/python benchmarks/bench_denoise.py --classes [--seeds 4 --points 60000 --raster]

Data (tests/denoise_cases.py `injected`): a 1000 mm aperture, a smooth 0.3 µm RMS polishing residual,
20 nm noise and 0.2 % of the points pushed up or down by 0.5–20 µm; gridded (raster) and scattered
(uniform random) inputs. `knn_denoise paper (count)` is the paper's manual mode given the true number
of outliers; `auto` decides alone. open3d: `remove_statistical_outlier(20, 2.0)` on (x, y, D);
scikit-learn: `LocalOutlierFactor(n_neighbors=20)` on (x, y, D), its own `contamination='auto'`.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from pointspro.core.step import Context  # noqa: E402
from pointspro.plugins.knn_denoise import KnnDenoiseStep  # noqa: E402
from pointspro.plugins.knn_denoise.peers import hampel  # noqa: E402
from tests.denoise_cases import ISSUE_MIX, injected, mixture  # noqa: E402


def f1(found: set, truth: set) -> float:
    tp = len(found & truth)
    if not found or not truth:
        return 0.0
    p, r = tp / len(found), tp / len(truth)
    return 0.0 if tp == 0 else 2 * p * r / (p + r)


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def prf(found: set, truth: set):
    tp = len(found & truth)
    p = tp / len(found) if found else 1.0
    r = tp / len(truth) if truth else 1.0
    return p, r, (0.0 if tp == 0 else 2 * p * r / (p + r))


def classes(seeds, n, scattered):
    """Issue 16 part 3: per class (a case holding only that class) and the mixtures, robust against
    the paper's ω and a Hampel filter (25 nearest neighbours, median ± 8 robust σ): P / R / F1."""
    print("| case | points | method | precision | recall | F1 | seconds |\n|---|---:|---|---:|---:|---:|---:|")
    cases = [(c, (c,)) for c in ("small", "digs", "rim", "big", "steep")] + [
        ("issue mixture", ISSUE_MIX), ("mixture + steep", ISSUE_MIX + ("steep",))]
    for label, cl in cases:
        acc = {}
        for seed in seeds:
            cloud, truth, _ = mixture(n=n, seed=seed, classes=cl, scattered=scattered)
            every = set().union(*truth.values())
            x, y, d = cloud.x, cloud.y, cloud["residual"]
            for method in ("robust", "paper"):
                p = KnnDenoiseStep.Params(window=3.0, method=method)
                t, res = timed(lambda: KnnDenoiseStep().run(cloud, p, Context()))
                acc.setdefault(method, []).append((*prf(set(res.report["removed_index"]), every), t))
            t, bad = timed(lambda: hampel(x, y, d))
            acc.setdefault("hampel", []).append((*prf(set(np.flatnonzero(bad).tolist()), every), t))
        for method, rows in acc.items():
            a = np.mean(rows, axis=0)
            print(f"| {label} | {cloud.n:,} | {method} | {a[0]:.3f} | {a[1]:.3f} | {a[2]:.3f} | {a[3]:.2f} |",
                  flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[50_000, 1_000_000])
    ap.add_argument("--classes", action="store_true", help="issue 16's classes instead (60,000 points)")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--points", type=int, default=60_000)
    ap.add_argument("--raster", action="store_true")
    args = ap.parse_args()
    if args.classes:
        classes(range(args.seeds), args.points, not args.raster)
        return
    import open3d as o3d
    from sklearn.neighbors import LocalOutlierFactor

    print("| input | points | method | F1 | seconds |\n|---|---:|---|---:|---:|")
    for n in args.sizes:
        for scattered in (False, True):
            cloud, truth = injected(n, scattered=scattered)
            kind = "scattered" if scattered else "gridded"
            x, y, d = cloud.x, cloud.y, cloud["residual"]
            rows = []
            for label, params in (("knn_denoise paper (count)", {"remove": len(truth), "method": "paper"}),
                                  ("knn_denoise paper auto", {"method": "paper"}),
                                  ("knn_denoise robust auto", {"method": "robust"})):
                p = KnnDenoiseStep.Params(window=10.0, **params)
                t, res = timed(lambda: KnnDenoiseStep().run(cloud, p, Context()))
                rows.append((label, f1(set(res.report["removed_index"]), truth), t))
            pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([x, y, d])))
            t, (_, kept) = timed(lambda: pc.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0))
            removed = set(np.setdiff1d(np.arange(cloud.n), np.asarray(kept)).tolist())
            rows.append(("open3d remove_statistical_outlier", f1(removed, truth), t))
            t, lab = timed(lambda: LocalOutlierFactor(n_neighbors=20).fit_predict(np.column_stack([x, y, d])))
            rows.append(("scikit-learn LocalOutlierFactor", f1(set(np.flatnonzero(lab < 0).tolist()), truth), t))
            for label, score, t in rows:
                print(f"| {kind} | {cloud.n:,} | {label} | {score:.3f} | {t:.2f} |", flush=True)


if __name__ == "__main__":
    main()
