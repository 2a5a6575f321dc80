"""Form-error maps: `bspline_map`'s spline on 10⁶ scattered points to a 1000 × 1000 grid, and the
ratio against scipy's FITPACK `SmoothBivariateSpline` on a size it can handle.

    .venv/bin/python benchmarks/bench_maps.py [--points 1000000] [--fitpack 20000 50000]

Data: uniform random points over a 1300 mm aperture, a polishing-like form error (astigmatism,
trefoil, a zone, a 120 mm ripple; ~1 µm RMS) plus 20 nm noise. Error = RMS of map − truth over the
nodes inside 95 % of the aperture. FITPACK gets the same number of knots per axis as ours and s = N σ²
(its documented choice for noise σ).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from pointspro.core.maps import fit_bspline, grid_map


def form(x, y):
    r, t = np.hypot(x, y) / 650.0, np.arctan2(y, x)
    return (1e-3 * r**2 * np.cos(2 * t) + 4e-4 * r**3 * np.cos(3 * t)
            + 3e-4 * np.exp(-((r - 0.6) / 0.08) ** 2) + 1e-4 * np.sin(2 * np.pi * x / 120.0))


def data(n, seed=1):
    rng = np.random.default_rng(seed)
    r = 650 * np.sqrt(rng.random(n))
    t = 2 * np.pi * rng.random(n)
    x, y = r * np.cos(t), r * np.sin(t)
    return x, y, form(x, y) + rng.normal(0, 2e-5, n)


def err_um(grid):
    X, Y = np.meshgrid(grid.xs, grid.ys)
    m = (np.hypot(X, Y) <= 0.95 * 650) & np.isfinite(grid.z)
    return float(np.sqrt(np.mean((grid.z[m] - form(X[m], Y[m])) ** 2)) * 1e3)


def ours(x, y, z, spacing, knot=None):
    t0 = time.perf_counter()
    s = fit_bspline(x, y, z, knot_spacing=knot, bounds=(-650, 650, -650, 650))
    g = grid_map(s, spacing, x, y, diameter=1300.0)
    return time.perf_counter() - t0, s, g


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--fitpack", type=int, nargs="+", default=[20_000, 50_000])
    args = ap.parse_args()
    from scipy.interpolate import LSQBivariateSpline, SmoothBivariateSpline

    print("| method | points | knots per axis | grid | seconds | error µm RMS |\n|---|---:|---:|---|---:|---:|")
    x, y, z = data(args.points)
    best = min((ours(x, y, z, 1.3) for _ in range(2)), key=lambda r: r[0])
    sec, s, g = best
    print(f"| bspline_map | {args.points:,} | {s.intervals[0] + 3} | {len(g.xs)} × {len(g.ys)} | "
          f"{sec:.2f} | {err_um(g):.4f} |")
    for n in args.fitpack:
        x, y, z = data(n, seed=2)
        sec, s, g = ours(x, y, z, 1.3)
        print(f"| bspline_map | {n:,} | {s.intervals[0] + 3} | {len(g.xs)} × {len(g.ys)} | {sec:.2f} | "
              f"{err_um(g):.4f} |")
        from pointspro.core.maps import MapGrid

        def fitpack(make):
            import warnings

            t0 = time.perf_counter()
            with warnings.catch_warnings(record=True) as w:
                warnings.simplefilter("always")
                fp = make()
                Z = fp(g.xs, g.ys).T
            fsec = time.perf_counter() - t0
            fg = MapGrid(g.xs, g.ys, np.where(np.isfinite(g.z), Z, np.nan), g.spacing)
            note = (" (warns: " + " ".join(str(w[0].message).split())[:48] + "…)") if w else ""
            return fsec, fp, err_um(fg), note

        fsec, fp, e, note = fitpack(lambda: SmoothBivariateSpline(
            x, y, z, s=n * (2e-5) ** 2, bbox=[-650, 650, -650, 650]))
        print(f"| scipy SmoothBivariateSpline (s = Nσ²){note} | {n:,} | {len(fp.get_knots()[0]) - 4} | "
              f"{len(g.xs)} × {len(g.ys)} | {fsec:.2f} | {e:.4f} |")
        inner = s.x0 + s.h * np.arange(1, s.intervals[0])
        tk = np.r_[[-650.0] * 4, inner[(inner > -650) & (inner < 650)], [650.0] * 4]
        lsec, lp, le, lnote = fitpack(lambda: LSQBivariateSpline(
            x, y, z, tk[4:-4], tk[4:-4], bbox=[-650, 650, -650, 650]))
        print(f"| scipy LSQBivariateSpline (our knots){lnote} | {n:,} | {len(tk) - 4} | "
              f"{len(g.xs)} × {len(g.ys)} | {lsec:.2f} | {le:.4f} |")
        print(f"| ratio SmoothBivariateSpline / ours at {n:,} | | | | {fsec / sec:.0f}× | |")


if __name__ == "__main__":
    main()
