"""The window with 1,000,000 points: open and first render; a rectangle selection plus deletion.

    xvfb-run -a .venv/bin/python benchmarks/bench_window.py [--points 1000000]

Targets (issue 9): open and first render under 3 s; selection + deletion under 300 ms. The deletion
time includes the model update (manual_edit recorded, undo snapshot) and redrawing both views.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=1_000_000)
    args = ap.parse_args()
    from PySide6 import QtWidgets

    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    d = Path(tempfile.mkdtemp())
    rng = np.random.default_rng(0)
    n = args.points
    r = 600 * np.sqrt(rng.random(n))
    t = 2 * np.pi * rng.random(n)
    x, y = r * np.cos(t), r * np.sin(t)
    write_csv(PointCloud.from_xyz(x, y, (x * x + y * y) / 6000, residual=1e-3 * np.sin(x / 50)), d / "big.csv")
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    from pointspro.app.main import build_window

    t0 = time.perf_counter()
    win = build_window([d / "big.csv"])
    win.show()
    app.processEvents()
    win.plotter.render()
    app.processEvents()
    t_open = time.perf_counter() - t0
    t0 = time.perf_counter()
    win.map.set_mask(win.session.select_rectangle(-100, 100, -100, 100))
    win.delete_selection()
    app.processEvents()
    win.plotter.render()
    t_del = time.perf_counter() - t0
    print("| action | points | seconds | target |\n|---|---:|---:|---:|")
    print(f"| open + first render | {n:,} | {t_open:.2f} | 3 |")
    print(f"| rectangle selection + deletion (both views redrawn) | {n:,} | {t_del:.3f} | 0.3 |")
    win.plotter.close()
    win.close()


if __name__ == "__main__":
    main()
