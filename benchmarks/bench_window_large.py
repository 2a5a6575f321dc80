"""The window with an interferometer's map of 12.6 million points (issue 26).

    xvfb-run -a .venv/bin/python benchmarks/bench_window_large.py [--points 12600000] [--profile]

Input: a circular map as binary PLY (x, y, z float64, mm), the pixels of a square n × n grid inside
a 100 mm aperture (n = round(√(4N/π)): 4,000 × 4,000 pixels for 12.6 M valid points), heights a few
Zernike terms (~0.5 µm) plus 2 nm of white noise (seed 0), written in blocks by the benchmark.

Measured, in this process, under Xvfb (software OpenGL):
- open + first render: File → Open of the PLY until both views are drawn (the 2D map's draw and the
  3D view's paint are forced, not left pending);
- lasso + delete, median of 3: a lasso (a 40-vertex polygon, a different place each time) selected
  through the 3D view over all points and highlighted in both views, then deleted (manual_edit
  recorded, undo snapshot, both views redrawn) — each part timed, and the sum;
- undo of the last deletion (both views redrawn);
- the autosave after each deletion (the project with its manual_edit steps — runs of consecutive
  rows as remove_ranges pairs — written in a thread),
  waited for before the next lasso and timed apart;
- peak RSS of the process (imports, the window and the map included).

Goals (issue 26): open ≤ 5 s, lasso + delete ≤ 0.5 s. The 3D view draws a level of detail
(display.DEFAULT_3D_BUDGET points); the 2D map is binned from all points; the selection, the deleted
rows and the edited cloud are always at full resolution.
"""
from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the same 100 mm circular map as bench_large_map.py (binary PLY, x, y, z float64)
from bench_large_map import make_map  # noqa: E402


def lasso_polygon(cx: float, cy: float, r: float, k: int = 40) -> np.ndarray:
    """A lumpy closed loop around (cx, cy), radius ~r (pixels), as an optician's hand draws it."""
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    rr = r * (1 + 0.25 * np.sin(3 * t) + 0.1 * np.cos(5 * t))
    return np.column_stack([cx + rr * np.cos(t), cy + rr * np.sin(t)])


def flush(app, win) -> None:
    """Run what is pending — the 3D view's paint renders it — and draw the 2D map now if a full
    draw is pending (edits blit at once)."""
    app.processEvents()
    if win.map.canvas.figure.stale:
        win.map.canvas.draw()
    app.processEvents()


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=float, default=12_600_000)
    ap.add_argument("--profile", action="store_true", help="cProfile of the open and one deletion")
    ap.add_argument("--tmp", default=None)
    args = ap.parse_args()
    d = Path(tempfile.mkdtemp(dir=args.tmp))
    path = d / "map.ply"
    t0 = time.perf_counter()
    n = make_map(path, int(args.points))
    print(f"generated {path.name}: {n:,} points, {path.stat().st_size / 1e6:.0f} MB "
          f"({time.perf_counter() - t0:.1f} s, not timed)")
    rss_before = peak_rss_mb()
    import os

    os.environ.setdefault("POINTSPRO_NO_DIALOGS", "1")
    os.environ.setdefault("POINTSPRO_AUTOSAVE_DIR", str(d))  # never the user's autosave
    os.environ.setdefault("POINTSPRO_SETTINGS", str(d / "settings.ini"))

    from PySide6 import QtWidgets

    t0 = time.perf_counter()
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    from pointspro.app.main import build_window

    win = build_window([])
    win.show()
    flush(app, win)
    t_start = time.perf_counter() - t0
    prof = None
    if args.profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    t0 = time.perf_counter()
    win.open_any(str(path))
    flush(app, win)
    t_open = time.perf_counter() - t0
    if prof is not None:
        prof.disable()
        _print_profile(prof, "open + first render")
    assert win.session.n_shown == n, win.log_widget.toPlainText()
    rss_open = peak_rss_mb()
    app.processEvents()
    time.sleep(0.5)  # the step classes load at idle after opening
    app.processEvents()

    w = win.view3d.plotter.interactor
    W, H = w.width(), w.height()
    rows, autosaves = [], []
    for k, (fx, fy) in enumerate(((0.45, 0.45), (0.6, 0.35), (0.35, 0.62))):
        before = win.session.n_shown
        poly = lasso_polygon(fx * W, fy * H, 0.08 * min(W, H))
        if prof is not None and k == 1:
            prof = cProfile.Profile()
            prof.enable()
        t0 = time.perf_counter()
        mask = win.view3d.select_lasso(poly)
        win.set_selection(mask)
        flush(app, win)
        t_sel = time.perf_counter() - t0
        m = int(mask.sum())
        t0 = time.perf_counter()
        win.delete_selection()
        flush(app, win)
        t_del = time.perf_counter() - t0
        if prof is not None and k == 1:
            prof.disable()
            _print_profile(prof, "lasso + delete")
            prof = None
        assert win.session.n_shown == before - m
        # the autosave (1.5 s after a change, in a thread) written now and waited for, so that it
        # does not share the interpreter with the next lasso: it is timed apart
        win._autosave_timer.stop()
        t0 = time.perf_counter()
        win.autosave_now()
        win._autosave_thread.join()
        autosaves.append(time.perf_counter() - t0)
        rows.append((m, t_sel, t_del))
    t0 = time.perf_counter()
    win.session.undo()
    flush(app, win)
    t_undo = time.perf_counter() - t0
    rss = peak_rss_mb()
    med = sorted(rows, key=lambda r: r[1] + r[2])[1]
    edits = [st.params for st in win.session.recipe.steps if st.id == "manual_edit"]
    print(f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}; manual_edit pairs, single rows: "
          f"{', '.join(f'{len(p.remove_ranges):,}, {len(p.remove):,}' for p in edits)}")
    print(f"{win.view3d.info.text()}; {win.map.im.get_array().shape[0]}² map bins; "
          f"deleted per lasso: {', '.join(f'{r[0]:,}' for r in rows)}")
    print("| action | points | seconds | goal |\n|---|---:|---:|---:|")
    print(f"| start the window (imports, empty window) | – | {t_start:.2f} | – |")
    print(f"| open + first render (read the binary PLY, both views drawn) | {n:,} | {t_open:.2f} | 5 |")
    print(f"| lasso through the 3D view over all points, highlighted in both views (of the median) "
          f"| {n:,} | {med[1]:.3f} | – |")
    print(f"| deletion of the selection (manual_edit, undo snapshot, both views redrawn) (of the median) "
          f"| {n:,} | {med[2]:.3f} | – |")
    print(f"| **lasso + delete, median of 3** (all three: "
          f"{', '.join(f'{r[1] + r[2]:.3f}' for r in rows)}) | {n:,} | {med[1] + med[2]:.3f} | 0.5 |")
    print(f"| undo of the last deletion (both views redrawn) | {n:,} | {t_undo:.3f} | – |")
    print(f"| autosave of the project after each deletion (a thread; manual_edit's runs of rows as "
          f"remove_ranges pairs) | {n:,} | {', '.join(f'{a:.2f}' for a in autosaves)} | – |")
    print(f"peak RSS: {rss_before:.0f} MB before the window, {rss_open:.0f} MB after opening, "
          f"{rss:.0f} MB at the end (file {path.stat().st_size / 1e6:.0f} MB)")
    win.close()
    path.unlink()


def _print_profile(prof, title):
    import pstats

    print(f"--- cProfile: {title}")
    pstats.Stats(prof).sort_stats("cumulative").print_stats(30)
    pstats.Stats(prof).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
