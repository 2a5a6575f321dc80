"""The window (pytest-qt, offscreen): open, colour, select in both views, delete, undo/redo, run in a
worker, report and Explain panels, profile cuts, projects, autosave and restore, bad input."""
from __future__ import annotations

import re
import time

import numpy as np
import pytest

from ..conftest import EXAMPLE

pytest.importorskip("pytestqt")


def _window(qtbot, files=()):
    from pointspro.app.main import build_window

    win = build_window(list(files))
    qtbot.addWidget(win)
    return win


def _example_window(qtbot, steps=5):
    from pointspro.core.recipe import load_yaml

    win = _window(qtbot, [EXAMPLE / "asphere_cmm.csv"])
    data = load_yaml((EXAMPLE / "recipe.yaml").read_text(encoding="utf-8"), "recipe")
    win.session.set_recipe({**data, "steps": list(data["steps"])[:steps]})
    return win


def _scattered(tmp_path, n=2000, seed=0):
    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-50, 50, (2, n))
    write_csv(PointCloud.from_xyz(x, y, (x * x + y * y) / 2000, residual=1e-4 * np.sin(x / 10)),
              tmp_path / "c.csv")
    return tmp_path / "c.csv"


def test_window_shows_example_and_switches_channels(qtbot):
    win = _window(qtbot, [EXAMPLE / "asphere_cmm.csv"])
    items = [win.channel.itemText(i) for i in range(win.channel.count())]
    assert items[0] == "z" and "line" in items
    win.channel.setCurrentText("line")
    assert "line" in win.view3d.mesh.array_names
    assert win.map.cbar.ax.get_ylabel() == "line"
    assert "4,680 points" in win.view3d.info.text()


def test_the_3d_point_budget_menu_ticks_the_default_and_can_return_to_it(qtbot):
    """The view draws 150,000 points by default; the menu offered 200,000… only, none ticked."""
    from pointspro.app.display import DEFAULT_3D_BUDGET

    win = _window(qtbot)
    view = next(a.menu() for a in win.menuBar().actions() if a.text() == "&View")
    lod = next(a.menu() for a in view.actions() if a.text() == "Points drawn in 3D")
    ticked = [a.text() for a in lod.actions() if a.isChecked()]
    assert ticked == [f"{DEFAULT_3D_BUDGET:,}"] and win.view3d.budget == DEFAULT_3D_BUDGET
    next(a for a in lod.actions() if a.text() == "500,000").trigger()
    assert win.view3d.budget == 500_000
    next(a for a in lod.actions() if a.text() == f"{DEFAULT_3D_BUDGET:,}").trigger()
    assert win.view3d.budget == DEFAULT_3D_BUDGET


def test_screenshot_command_writes_png(tmp_path, run_cli):
    from PySide6.QtGui import QImage

    png = tmp_path / "shot.png"
    code, _, err = run_cli("--screenshot", png, EXAMPLE / "asphere_cmm.csv")
    assert code == 0, err
    img = QImage(str(png))
    assert not img.isNull() and img.width() > 800
    # not blank: the window has many distinct colours (map, colour bars, widgets)
    colours = {img.pixel(x, y) for x in range(0, img.width(), 7) for y in range(0, img.height(), 7)}
    assert len(colours) > 50


def test_residual_opens_diverging_in_the_unit_its_size_asks_for(qtbot, tmp_path):
    """A processed cloud opens on its residual: diverging map centred on zero, in both views, in the
    unit its spread asks for — a ±0.1 µm residual reads in nm (±100), never as 1e-4 mm."""
    win = _window(qtbot, [_scattered(tmp_path)])
    assert win.channel.currentText() == "residual"
    img = win.map.im.get_array()
    assert np.nanmax(np.abs(img)) == pytest.approx(100, rel=0.05)  # 1e-4 mm·sin → ±100 nm
    lo, hi = win.map.im.get_clim()
    assert lo == -hi and win.map.im.get_cmap().name == "RdBu_r"
    assert win.map.cbar.ax.get_ylabel() == "residual (nm)"
    assert "residual (nm)" in win.view3d.mesh.array_names
    win.channel.setCurrentText("z")
    assert win.map.cbar.ax.get_ylabel().startswith("z − mean (") and win.map.im.get_cmap().name == "viridis"


def test_one_residual_gets_one_colour_range_in_map_3d_view_and_report(qtbot, tmp_path):
    """The map (binned means), the 3D view (a level of detail of the points) and the report's
    form_error.png used to take their limits from what each drew: ±1.70, ±1.76 and ±1.67 µm for the
    example's residual. Now all three from the points (core.figures.limits_sample), hidden ones out."""
    from pointspro.core import PointCloud
    from pointspro.core.figures import scattered_map
    from pointspro.core.io import write_csv

    rng = np.random.default_rng(3)
    x, y = rng.uniform(-50, 50, (2, 6000))
    r = 1e-4 * np.sin(x / 10) + rng.normal(0, 3e-5, x.size)
    r[:5] += 2e-3  # spikes: the limits are robust, not the extremes
    write_csv(PointCloud.from_xyz(x, y, (x * x + y * y) / 2000, residual=r), tmp_path / "c.csv")
    win = _window(qtbot, [tmp_path / "c.csv"])
    assert win.channel.currentText() == "residual"
    cloud = win.map.cloud
    win.view3d.budget = 700  # the 3D view draws ~700 of the 6000 points
    win.view3d.set_cloud(cloud, "residual", new_input=True)
    assert len(win.view3d._shown_idx) < 1000
    lo2, hi2 = win.map.im.get_clim()
    lo3, hi3 = win.view3d._clim
    fig = scattered_map(cloud.x, cloud.y, cloud["residual"])
    lor, hir = fig.axes[0].images[0].get_clim()
    assert hi2 == pytest.approx(hi3, rel=1e-12) and hi2 == pytest.approx(hir, rel=1e-12)
    assert lo2 == -hi2 and lo3 == -hi3 and lor == -hir
    # nm in all three: 0.5/99.5 percentiles of the points, spikes saturate
    assert hi2 == pytest.approx(np.percentile(np.abs(np.percentile(r * 1e6, [0.5, 99.5])), 100), rel=1e-9)
    # points hidden in the views (a lasso's "hide") leave the limits of the points still shown
    keep = np.abs(x) < 20
    win.view3d.set_cloud(cloud, "residual", new_input=True, keep=keep)
    rk = r[keep] * 1e6
    want = max(np.abs(np.percentile(rk, [0.5, 99.5])))
    assert win.view3d._clim[1] == pytest.approx(want, rel=1e-9)


def test_auto_fields_show_the_value_the_last_run_computed(qtbot):
    """An "auto" parameter hides its editor (a greyed default read as the value used); after a run it
    shows what the step computed, from the step's report — bspline_map's knot spacing, 86.56 mm on
    the example — and nothing for a step that did not run."""
    from pointspro.app.pipeline_dock import used_text

    win = _example_window(qtbot, steps=7)
    win.pipeline.list.setCurrentRow(6)
    w = win.pipeline.fields["knot_spacing"]
    assert w.auto.isChecked() and not w.used.isVisible() and w.used.text() == ""
    win.pipeline.run_all.click()
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    w = win.pipeline.fields["knot_spacing"]
    knots = win.last_report.steps[6].report["knot_spacing"]
    assert w.used.text() == f"last run: {used_text(knots, 'mm')}" == "last run: 86.56 mm"
    assert not w.used.isHidden()
    w.auto.setChecked(False)  # a value of one's own: the editor, not the readout
    assert w.used.isHidden() and not w.inner.isHidden()
    assert used_text(2.5e-4, "mm") == "250 nm" and used_text([1.0, -2.0], "mm") == "(1 mm, -2 mm)"
    assert used_text(5.0, None) == "5" and used_text(None, "mm") is None


def test_run_in_worker_keeps_the_window_responsive_and_fills_the_report(qtbot):
    """The pipeline runs in a thread: the event loop keeps turning meanwhile. (How long its longest
    stall is — the 100 ms target — is measured in benchmarks/bench_window.py, not asserted here: a
    timed assertion fails on a loaded machine.)"""
    from PySide6 import QtCore

    win = _example_window(qtbot, steps=4)
    win.pipeline.add_combo.setCurrentText("aperture")  # add a step from the installed list
    win.pipeline.add_button.click()
    assert win.session.steps[-1] == {"aperture": {}} and win.pipeline.list.count() == 5
    win.pipeline.list.setCurrentRow(4)
    win.pipeline.fields["diameter"].enter(1290.0)  # as typed: the form's edits go to the recipe
    assert win.session.steps[-1] == {"aperture": {"diameter": 1290}}
    gaps, last = [], [time.perf_counter()]

    def tick():
        now = time.perf_counter()
        if win.runner.busy:  # while the steps run (showing the result afterwards is measured apart)
            gaps.append(now - last[0])
        last[0] = now

    timer = QtCore.QTimer()
    timer.setInterval(10)
    timer.timeout.connect(tick)
    timer.start()
    win.pipeline.run_all.click()
    assert win.runner.busy
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    timer.stop()
    assert "residual" in win.session.shown.channels and win.session.shown.n == 4640
    assert len(gaps) >= 3  # the timer fired while the steps ran: the GUI thread was not blocked
    assert win.channel.currentText() == "residual"  # the first residual is shown when it appears
    assert win.pipeline.list.count() == 5 and win.pipeline.bar.value() == 1000
    # the report panel: summary, then each step with its numbers and (drawn on demand) figures
    assert win.report.list.count() == 6
    assert re.search(r"<th>RMS</th><td>[0-9.]+ nm</td>", win.report.html_for(0))  # the unit its size asks for
    row = next(i for i in range(1, 6) if win.report.figures_of(i))
    win.report.list.setCurrentRow(row)
    qtbot.waitUntil(lambda: not win.report.worker.busy, timeout=30_000)
    page = win.report.html_for(row)
    assert page.count("<img") == len(win.report.figures_of(row)) and "drawing" not in page
    assert "ran 5 step(s): 4,640 points, residual RMS" in win.log_widget.toPlainText()


def test_cancel_stops_a_run_and_keeps_the_cloud(qtbot):
    win = _example_window(qtbot)
    before = win.session.shown
    win.start_run(None)
    win.cancel_run()
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=60_000)
    log = win.log_widget.toPlainText()
    if "cancelled" in log:  # a fast machine may finish first; then it ran
        assert win.session.shown is before
    else:
        assert "ran 5 step(s)" in log


def test_select_delete_undo_redo_project_and_batch_replay(qtbot, tmp_path, run_cli):
    win = _example_window(qtbot)
    win.session.run()
    n0 = win.session.shown.n
    c = win.session.shown
    win.set_selection((np.abs(c.x) < 150) & (np.abs(c.y) < 150))
    k = int(win.selection.sum())
    assert k > 0 and f"{k:,} point(s) selected" in win.sel_label.text()
    assert win.view3d._sel_actor is not None  # highlighted in 3D
    actor, clim = win.view3d._actor, tuple(win.view3d._actor.mapper.scalar_range)
    win.delete_selection()
    assert win.session.shown.n == n0 - k and "manual_edit" in win.session.steps[1]  # before the fits
    assert win.view3d.mesh.n_points == n0 - k and win.selection is None
    # an edit updates the drawn points in place: the same actor and colour limits, the highlight
    # gone, and no deleted point among those drawn
    v3 = win.view3d
    assert v3._actor is actor and tuple(v3._actor.mapper.scalar_range) == clim and v3._sel_actor is None
    assert v3._sel_cache is None or not v3._sel_cache[0].GetVisibility()  # the highlight hidden
    # another selection reuses the highlight's actor
    sel = np.abs(win.session.shown.x - win.session.shown.x.mean()) < 100
    win.set_selection(sel)
    assert v3._sel_actor is v3._sel_cache[0] and v3._sel_actor.GetVisibility()
    assert v3._sel_cache[1].n_points == int(sel.sum())
    drawn = np.asarray(v3.mesh.points, dtype=np.float64) + v3.origin
    shown = win.session.shown
    assert np.allclose(np.sort(drawn[:, 0]), np.sort(shown.x), atol=1e-3)
    win.undo_action.trigger()
    assert win.session.shown.n == n0 and win.view3d.mesh.n_points == n0
    win.redo_action.trigger()
    assert win.session.shown.n == n0 - k
    # the pipeline form marks an invalid value and keeps the old one
    win.pipeline.list.setCurrentRow(5)  # the aperture: the deletion's step stands second
    win.pipeline.fields["diameter"].enter(-5.0)
    assert "ffd6d6" in win.pipeline.fields["diameter"].styleSheet()
    assert "diameter must be > 0 mm (got -5 mm)" in win.pipeline.message.text()
    assert win.session.steps[5] == {"aperture": {"diameter": 1290}}
    win.session.run()  # the steps without the deleted points
    # save, reopen in a new window: the same cloud
    win.session.save_project(tmp_path / "p.pointspro.yaml")
    w2 = _window(qtbot)
    w2.open_any(str(tmp_path / "p.pointspro.yaml"))  # its recipe runs in the worker, as Run all
    qtbot.waitUntil(lambda: not w2.runner.busy, timeout=120_000)
    assert w2.session.shown.equals(win.session.shown) and w2.last_report is not None
    # the saved recipe replays identically in the batch
    win.session.save_recipe(tmp_path / "r.yaml")
    code, _, err = run_cli("--batch", tmp_path / "r.yaml", EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o")
    assert code == 0, err
    from pointspro.core.io import read_cloud

    out = read_cloud(tmp_path / "o" / "asphere_cmm" / "cloud.csv")
    shown = win.session.shown
    assert np.array_equal(out.index, shown.index)
    assert np.allclose(out["residual"], shown["residual"], rtol=0, atol=1e-12)
    # a corrupt file: a message, and the window keeps what it had
    (tmp_path / "bad.csv").write_text("x,y,z\n1,2\n", encoding="utf-8")
    w2.open_any(str(tmp_path / "bad.csv"))
    assert "error:" in w2.log_widget.toPlainText() and "bad.csv" in w2.log_widget.toPlainText()
    assert w2.session.shown.equals(win.session.shown)


def test_rectangle_and_lasso_through_the_3d_view(qtbot, tmp_path):
    """Drag a rectangle in the 3D view (looking along z): the points under it are selected; a lasso
    around the centre selects the centre."""
    from PySide6 import QtCore

    win = _window(qtbot, [_scattered(tmp_path, 4000)])
    win.show()
    qtbot.waitExposed(win)
    w = win.view3d.plotter.interactor
    # where the cloud's centre is drawn (left of the view's centre: the colour bar has the right)
    from pointspro.app import display

    matrix, width, height = win.view3d._camera()
    centre = np.array([[win.session.shown.x.mean(), win.session.shown.y.mean(), win.session.shown.z.mean()]])
    sx, sy = display.to_screen(centre - win.view3d.origin, matrix, width, height)
    cx, cy = int(round(float(sx[0]))), int(round(float(sy[0])))
    assert cx < w.width() // 2 < w.width() * 0.82  # the data left of the colour bar
    win.view3d.mode.setCurrentText("select rectangle")
    qtbot.mousePress(w, QtCore.Qt.LeftButton, pos=QtCore.QPoint(cx - 30, cy - 30))
    qtbot.mouseMove(w, QtCore.QPoint(cx + 30, cy + 30))
    qtbot.mouseRelease(w, QtCore.Qt.LeftButton, pos=QtCore.QPoint(cx + 30, cy + 30))
    sel = win.selection
    c = win.session.shown
    assert sel is not None and 0 < sel.sum() < c.n / 2
    # the view centre is the cloud centre: selected points surround it, a square in x, y
    xs, ys = c.x[sel] - c.x.mean(), c.y[sel] - c.y.mean()
    half = max(np.abs(xs).max(), np.abs(ys).max())
    assert np.abs(xs).max() == pytest.approx(np.abs(ys).max(), rel=0.15)
    inner = (np.abs(c.x - c.x.mean()) < 0.8 * half) & (np.abs(c.y - c.y.mean()) < 0.8 * half)
    assert np.all(sel[inner])
    # lasso: a diamond around the centre
    win.view3d.mode.setCurrentText("select lasso")
    pts = [(cx, cy - 40), (cx + 40, cy), (cx, cy + 40), (cx - 40, cy), (cx, cy - 40)]
    qtbot.mousePress(w, QtCore.Qt.LeftButton, pos=QtCore.QPoint(*pts[0]))
    for p in pts[1:]:
        qtbot.mouseMove(w, QtCore.QPoint(*p))
    qtbot.mouseRelease(w, QtCore.Qt.LeftButton, pos=QtCore.QPoint(*pts[-1]))
    sel = win.selection
    d1 = np.abs(c.x[sel] - c.x.mean()) + np.abs(c.y[sel] - c.y.mean())
    assert sel.sum() > 0 and d1.max() < 1.15 * np.quantile(d1, 0.99)
    win.delete_selection()
    assert win.session.shown.n == c.n - sel.sum()


def test_map_rectangle_lasso_threshold_and_profile(qtbot, tmp_path):
    win = _window(qtbot, [_scattered(tmp_path)])
    m, c = win.map, win.session.shown

    class Ev:
        def __init__(self, x, y):
            self.xdata, self.ydata = x, y
    m._on_rect(Ev(-10, -20), Ev(30, 5))
    expect = (c.x >= -10) & (c.x <= 30) & (c.y >= -20) & (c.y <= 5)
    assert np.array_equal(win.selection, expect)
    assert np.any(m.sel_im.get_array()[..., 3] > 0)  # bins highlighted
    m._on_lasso([(0, 0), (40, 0), (0, 40)])
    assert np.array_equal(win.selection, (c.x > 0) & (c.y > 0) & (c.x + c.y < 40))
    # threshold: the slider at the 90 % quantile of the residual selects the top 10 %
    m.th_channel.setCurrentText("residual")
    m.slider.setValue(900)
    assert win.selection.sum() == pytest.approx(0.1 * c.n, abs=2)
    assert "points: residual > " in m.th_info.text() and "nm" in m.th_info.text()
    m.th_channel.setCurrentText("z")  # another channel re-selects at the slider's position
    assert "points: z" in m.th_info.text() and win.selection.sum() == pytest.approx(0.1 * c.n, abs=2)
    m.th_channel.setCurrentText("residual")
    # a profile cut along x through y = 0: the points near the line, in nm, sorted along the cut
    s, v = m.cut((-50, 0), (50, 0))
    near = np.abs(c.y) <= 1.5 * (m.ext[1] - m.ext[0]) / m._bins
    assert s.size == near.sum() and np.all(np.diff(s) >= 0)
    order = np.argsort(c.x[near])
    assert np.allclose(v, c["residual"][near][order] * 1e6)
    assert m.pax.lines and m.profile_info.text().startswith(f"profile: {s.size:,} points, PV")
    assert m.profile_info.text().endswith(" nm")
    # a deletion updates the cut (same limits, new points)
    win.set_selection(near & (c.x > 0))
    win.delete_selection()
    s2, _ = m.profile
    assert s2.size == near.sum() - (near & (c.x > 0)).sum()


def test_autosave_restores_an_unsaved_session(qtbot, tmp_path):
    from pointspro.app.window import autosave_path

    win = _window(qtbot, [_scattered(tmp_path)])
    win.session.add_step("aperture", {"diameter": 80})
    win.autosave_now()
    win._autosave_thread.join()
    assert autosave_path().is_file()
    # the "crash": the window never closed; a new one offers the session back
    w2 = _window(qtbot)
    assert not w2.banner.isHidden() and "unsaved session" in w2.banner_text.text()
    w2.restore_autosave()
    assert w2.session.steps == [{"aperture": {"diameter": 80}}]
    assert w2.session.input_path.resolve() == (tmp_path / "c.csv").resolve()
    w2.close()  # a normal close leaves nothing to restore
    assert not autosave_path().exists()


def test_bad_recipe_and_moved_data_leave_the_window_usable(qtbot, tmp_path):
    win = _window(qtbot, [_scattered(tmp_path)])
    (tmp_path / "r.yaml").write_text("pointspro: 1\nsteps:\n  - frobnicate: {}\n", encoding="utf-8")
    win.open_any(str(tmp_path / "r.yaml"))
    assert "frobnicate" in win.log_widget.toPlainText() and win.session.steps == []
    win.session.save_project(tmp_path / "p.pointspro.yaml")
    (tmp_path / "c.csv").rename(tmp_path / "moved.csv")
    w2 = _window(qtbot, [tmp_path / "p.pointspro.yaml"])
    assert "moved or deleted" in w2.log_widget.toPlainText() and w2.session.shown is None
    # drag and drop of a data file; it joins the recent files
    from PySide6 import QtCore, QtGui

    mime = QtCore.QMimeData()
    mime.setUrls([QtCore.QUrl.fromLocalFile(str(tmp_path / "moved.csv"))])
    ev = QtGui.QDropEvent(QtCore.QPointF(10, 10), QtCore.Qt.CopyAction, mime, QtCore.Qt.LeftButton,
                          QtCore.Qt.NoModifier)
    w2.dropEvent(ev)
    assert w2.session.shown.n == 2000
    assert w2.settings.value("recent")[0] == str(tmp_path / "moved.csv")


def test_exports(qtbot, tmp_path):
    from pointspro.core.io import read_cloud

    win = _example_window(qtbot, steps=7)
    win.session.run()
    win._ran(win.session.last_result)
    win.export_cloud(tmp_path / "cloud.csv")
    assert read_cloud(tmp_path / "cloud.csv").n == win.session.shown.n
    win.export_map(tmp_path / "map.png")
    win.export_map(tmp_path / "map.x3p")
    assert (tmp_path / "map.png").stat().st_size > 5000 and (tmp_path / "map.x3p").is_file()
    win.export_report(tmp_path / "rep")
    qtbot.waitUntil(lambda: not win.exporter.busy, timeout=60_000)
    assert (tmp_path / "rep" / "report.html").is_file() and (tmp_path / "rep" / "map.csv").is_file()
    # a folder of other files is never replaced by a report (the export is all or nothing)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep", encoding="utf-8")
    win.export_report(mine)
    assert not win.exporter.busy and "is not a PointsPro output folder" in win.log_widget.toPlainText()
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    # nor an earlier report's folder to which the user added a file (it was deleted with the folder)
    (tmp_path / "rep" / "notes.txt").write_text("keep", encoding="utf-8")
    win.export_report(tmp_path / "rep")
    assert not win.exporter.busy and "notes.txt: is not one of the files" in win.log_widget.toPlainText()
    assert (tmp_path / "rep" / "notes.txt").read_text(encoding="utf-8") == "keep"


def test_explain_panel_names_the_missing_effects(qtbot, tmp_path, run_cli):
    code, _, err = run_cli("simulate", EXAMPLE / "spiral_truth.yaml", "--out", tmp_path / "meas.csv")
    assert code == 0, err
    win = _window(qtbot, [tmp_path / "meas.csv"])
    win.explain.path.setText(str(EXAMPLE / "spiral_model.yaml"))
    win.explain.bootstrap.setValue(2)
    assert win.explain.start()
    qtbot.waitUntil(lambda: not win.explain.worker.busy, timeout=120_000)
    rep = win.explain.report
    found = {f["effect"] for f in rep["found"]}
    assert {"spindle_tilt", "vibration"} <= found
    assert rep["gap_after"]["rms_um"] < 0.5 * rep["gap_before"]["rms_um"]
    assert "Verdict" in win.explain.view.toHtml() and "explain:" in win.log_widget.toPlainText()
    win.explain.save_model(tmp_path / "updated.yaml")
    assert "spindle_tilt" in (tmp_path / "updated.yaml").read_text(encoding="utf-8")


def test_an_instrument_grid_map_has_no_empty_bins_and_a_micrometre_field_reads_in_um(qtbot):
    """A 256 × 256 map (matrix-3, a 10 µm field) was binned 307 across: every sixth bin empty, a
    white grid over the map; and its axes read 0.000 … 0.010 mm. Now the bins are never finer than
    the pixel, and the axes read µm (the data stay in mm: selections keep their coordinates)."""
    from .. import conftest

    win = _window(qtbot, [conftest.ROOT / "tests/data/realdata/matrix-3.txt"])
    img = np.asarray(win.map.im.get_array(), dtype=float)
    assert img.shape[0] <= 254 and not np.isnan(img).any()
    assert win.map.ax.get_xlabel() == "x (µm)" and win.map.ax.get_ylabel() == "y (µm)"
    lo, hi = win.map.ax.get_xlim()
    assert hi - lo < 0.02  # mm: the data's own unit
    assert win.map.ax.xaxis.get_major_formatter()(0.005, 0) == "5"


def test_the_opening_cut_lies_on_a_row_of_a_small_grid(qtbot):
    """xyz-1 (4 × 4 points, 1 mm apart): the opening cut through the middle y fell between rows and
    the profile said "no points near the cut"; it lies on the nearest row now."""
    from .. import conftest

    win = _window(qtbot, [conftest.ROOT / "tests/data/realdata/xyz-1.txt"])
    (x0, y0), (x1, y1) = win.map.profile_line
    assert y0 == y1 and np.min(np.abs(win.map.cloud.y - y0)) == 0
    assert win.map.profile[0].size >= 4


def test_the_map_colour_bar_shows_values_beyond_its_range(qtbot, tmp_path):
    """The robust limits saturate spikes; the bar's ends now say so (it showed no sign of them)."""
    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    rng = np.random.default_rng(1)
    x, y = rng.uniform(-50, 50, (2, 3000))
    r = 1e-4 * np.sign(np.sin(x / 10))  # ±0.1 µm and nothing else: the limits hold every value
    write_csv(PointCloud.from_xyz(x, y, (x * x + y * y) / 2000, residual=r), tmp_path / "a.csv")
    assert _window(qtbot, [tmp_path / "a.csv"]).map.cbar.extend == "neither"
    r = r.copy()
    r[:3] = 5e-3  # three 5 µm spikes beyond the robust limits
    write_csv(PointCloud.from_xyz(x, y, (x * x + y * y) / 2000, residual=r), tmp_path / "s.csv")
    assert _window(qtbot, [tmp_path / "s.csv"]).map.cbar.extend == "max"


def test_a_deletion_waits_for_the_running_pipeline(qtbot, monkeypatch):
    """A review: points deleted while a run was going reappeared when it finished (its result replaced
    the view) and the manual_edit stayed in the recipe, saying otherwise. Delete is refused then."""
    win = _example_window(qtbot)
    win.session.run()
    c = win.session.shown
    win.set_selection(np.abs(c.x) < 100)
    steps = len(win.session.steps)
    monkeypatch.setattr(type(win.runner), "busy", property(lambda self: True))
    win.delete_selection()
    assert len(win.session.steps) == steps and win.session.shown.n == c.n
    monkeypatch.undo()
    win.delete_selection()
    assert len(win.session.steps) == steps + 1 and win.session.shown.n < c.n


def test_the_report_says_when_it_no_longer_matches_the_recipe(qtbot):
    """A review: after a failed run (the bar left at "selecting 64%") or a deletion, the Report panel
    kept the last run's RMS and PV as if current. A banner says so until the next run."""
    win = _example_window(qtbot, steps=3)
    win.pipeline.run_all.click()
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    assert win.report.result is not None and win.report.stale.isHidden()
    c = win.session.shown
    win.set_selection(np.abs(c.x) < 100)
    win.delete_selection()
    assert not win.report.stale.isHidden() and "points were deleted" in win.report.stale.text()
    win.pipeline.run_all.click()
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    assert win.report.stale.isHidden()
    win.session.add_step("aperture", {"diameter": 0.5})  # no point inside: the run fails
    assert not win.report.stale.isHidden()
    win.pipeline.run_all.click()
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    assert win.pipeline.bar.format() == "failed" and "a run failed" in win.report.stale.text()


def test_a_run_whose_recipe_changed_meanwhile_is_not_shown(qtbot):
    """A review: Restore all (or an Undo, or an edit) during a run was undone on screen when the run,
    computed with the recipe as it was, replaced the view. Its result is discarded and said so."""
    win = _example_window(qtbot, steps=3)
    before = win.session.shown
    win.pipeline.run_all.click()
    assert win.runner.busy
    win.session.add_step("aperture", {"diameter": 1290})  # an edit while the steps run
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    assert win.session.shown is before and "residual" not in win.session.shown.channels
    assert "its result is discarded" in win.log_widget.toPlainText()
    assert win.pipeline.bar.format() == "discarded"
    win.pipeline.run_all.click()
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    assert "residual" in win.session.shown.channels and win.report.stale.isHidden()


def test_opening_another_file_drops_the_last_result_and_the_window_deletions(qtbot, tmp_path):
    """A review: after opening file B the window kept A's result — Export report wrote A's RMS under
    B's name — and A's deletions removed B's points at A's row numbers, without a word."""
    win = _example_window(qtbot, steps=7)
    win.session.run()
    win._ran(win.session.last_result)
    assert win.last_report is not None
    win.session.delete(np.arange(win.session.shown.n) < 30)
    assert any(st.get("manual_edit", {}).get("note") == "deleted in the window" for st in win.session.steps)
    win.open_any(str(_scattered(tmp_path)))
    assert win.last_report is None and not win.report.stale.isHidden()
    assert "another measurement was opened" in win.report.stale.text()
    assert not any(st.get("manual_edit", {}).get("note") == "deleted in the window" for st in win.session.steps)
    assert "deletion step(s) made in the window on the file open before were dropped" in win.log_widget.toPlainText()
    assert win.session.shown.n == 2000
    win.export_report(tmp_path / "rep")
    assert not (tmp_path / "rep").exists() and "run the pipeline first" in win.log_widget.toPlainText()
    # the same file again keeps its deletions
    win.session.delete(np.arange(win.session.shown.n) < 5)
    win.open_any(str(tmp_path / "c.csv"))
    assert win.session.shown.n == win.session.input_less_edits().n <= 2000 - 5  # the recipe's own edit too
    assert any(st.get("manual_edit", {}).get("note") == "deleted in the window" for st in win.session.steps)


def test_export_report_after_an_edit_is_the_last_runs_recipe_and_numbers(qtbot, tmp_path):
    """A review: deleting points after a run and exporting paired the new recipe (two manual_edit
    steps) with the numbers of the run (one)."""
    import json

    win = _example_window(qtbot, steps=7)
    win.session.run()
    win._ran(win.session.last_result)
    n_run = win.last_report.cloud.n
    edits_run = sum("manual_edit" in st for st in win.session.steps)
    win.session.delete(np.arange(win.session.shown.n) < 40)
    win.export_report(tmp_path / "rep")
    qtbot.waitUntil(lambda: not win.exporter.busy, timeout=60_000)
    rep = json.loads((tmp_path / "rep" / "report.json").read_text(encoding="utf-8"))
    assert sum("manual_edit" in st for st in rep["recipe"]["steps"]) == edits_run
    assert rep["summary"]["points_out"] == n_run
    assert "the recipe changed since the last run" in win.log_widget.toPlainText()


def test_export_failures_are_said_not_reported_as_done(qtbot, tmp_path):
    """A review: Export cloud logged "exported" after its error; Export map (.png) and Export mesh let
    an OSError out of the menu's slot with nothing said."""
    win = _example_window(qtbot, steps=7)
    win.session.run()
    win._ran(win.session.last_result)
    missing = tmp_path / "no" / "such"
    win.export_cloud(missing / "c.csv")
    log = win.log_widget.toPlainText()
    assert "error" in log and "exported the cloud" not in log
    win.export_map(missing / "m.png")  # no exception leaves the slot
    win.export_mesh(missing / "m.ply")
    log = win.log_widget.toPlainText()
    assert log.count("error") >= 3 and "exported the map" not in log


def test_a_crashed_session_is_kept_until_restored_or_discarded(qtbot, tmp_path):
    """A review: files opened before Restore was clicked autosaved over the crashed session, and
    Restore brought back the new one."""
    from pointspro.app.window import autosave_path, unsaved_session_path

    win = _window(qtbot, [_scattered(tmp_path)])
    win.session.add_step("aperture", {"diameter": 80})
    win.autosave_now()
    win._autosave_thread.join()
    w2 = _window(qtbot, [EXAMPLE / "asphere_cmm.csv"])  # the "crash": a new window with another file
    assert not w2.banner.isHidden()
    w2.autosave_now()
    w2._autosave_thread.join()
    assert unsaved_session_path().is_file() and autosave_path().is_file()
    w2.restore_autosave()
    assert w2.session.steps == [{"aperture": {"diameter": 80}}]
    assert w2.session.input_path.resolve() == (tmp_path / "c.csv").resolve()
    assert not unsaved_session_path().exists()


def test_explain_compares_the_points_kept(qtbot, tmp_path, monkeypatch):
    """A review: Explain read the file again, the spikes deleted in the window included (gap 5.6 µm
    for 2 nm). It is given the measurement less the deletions."""
    import pointspro.core.explain.workflow as wf

    seen = {}

    def fake(measured, out, model, sim, bootstrap=10, measured_cloud=None):
        seen["n"] = None if measured_cloud is None else measured_cloud.n
        raise wf.RecipeError("stop here")
    monkeypatch.setattr(wf, "explain", fake)
    win = _window(qtbot, [EXAMPLE / "asphere_cmm.csv"])
    n0 = win.session.input_cloud.n
    win.session.delete(np.arange(n0) < 25)
    win.explain.path.setText(str(EXAMPLE / "spiral_model.yaml"))
    assert win.explain.start()
    qtbot.waitUntil(lambda: not win.explain.worker.busy, timeout=60_000)
    assert seen["n"] == n0 - 25
    assert f"comparing the {n0 - 25:,} points kept (25 deleted" in win.log_widget.toPlainText()


def test_a_run_of_the_file_open_before_is_discarded(qtbot, tmp_path):
    """A review of this session's change: a file opened while the steps ran got the old file's result
    when the run ended, and Export report wrote it under the new name."""
    win = _example_window(qtbot, steps=7)
    win.start_run(None)
    assert win.runner.busy
    win.open_any(str(_scattered(tmp_path)))
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=120_000)
    assert win.last_report is None and win.session.shown.n == 2000
    assert "another measurement was opened while it ran" in win.log_widget.toPlainText()


def test_a_restore_that_fails_keeps_the_unsaved_session(qtbot, tmp_path):
    """A review: Restore deleted the kept session even when it could not be opened (its data file
    moved): putting the file back no longer helped."""
    from pointspro.app.window import unsaved_session_path

    win = _window(qtbot, [_scattered(tmp_path)])
    win.session.add_step("aperture", {"diameter": 80})
    win.autosave_now()
    win._autosave_thread.join()
    (tmp_path / "c.csv").rename(tmp_path / "moved.csv")
    w2 = _window(qtbot)
    w2.restore_autosave()
    assert "moved or deleted" in w2.log_widget.toPlainText() and unsaved_session_path().is_file()
    (tmp_path / "moved.csv").rename(tmp_path / "c.csv")
    w2.restore_autosave()
    assert w2.session.steps == [{"aperture": {"diameter": 80}}] and not unsaved_session_path().exists()


def test_an_explain_result_gets_room_to_be_read(qtbot, tmp_path, monkeypatch):
    """At 1280 × 800 the Explain dock (tabbed with the log and the report, ~190 px) left its result
    ~50–70 px under a four-row form and the page's own 1.5 em title. The form is two rows, a result
    gives the dock ~45 % of the window's height (never shrunk), and the title is a bold line."""
    from PySide6 import QtCore

    import pointspro.core.explain.workflow as wf

    def fake(measured, out, model, sim, bootstrap=10, measured_cloud=None):
        out.mkdir(parents=True)
        (out / "explain.html").write_text("<!doctype html><html><head><style>h1{font-size:1.5em}</style>"
                                          "</head><body><h1>Explain: where simulation and measurement "
                                          "disagree</h1><p>Verdict</p></body></html>", encoding="utf-8")
        return {"verdict": "explained", "found": [], "gap_before": {"rms_um": 0.01},
                "gap_after": {"rms_um": 0.002}}
    monkeypatch.setattr(wf, "explain", fake)
    win = _window(qtbot, [EXAMPLE / "asphere_cmm.csv"])
    win.show()
    qtbot.waitExposed(win)
    win.explain_dock.raise_()
    qtbot.waitUntil(lambda: win.explain_dock.isVisible(), timeout=5000)
    win.explain.path.setText(str(EXAMPLE / "spiral_model.yaml"))
    assert win.explain.start()
    qtbot.waitUntil(lambda: not win.explain.worker.busy, timeout=60_000)
    qtbot.waitUntil(lambda: win.explain_dock.height() >= 0.4 * win.height(), timeout=5000)
    assert win.explain.view.height() >= 200  # was 70 (a screenshot at 1280 × 800)
    assert "<h1" not in win.explain.view.toHtml() and "Explain: where simulation" in win.explain.view.toPlainText()
    # the user's own, larger size is kept
    win.resizeDocks([win.explain_dock], [int(0.6 * win.height())], QtCore.Qt.Vertical)
    qtbot.waitUntil(lambda: win.explain_dock.height() >= 0.55 * win.height(), timeout=5000)
    tall = win.explain_dock.height()
    win.explain._done({"verdict": "explained", "found": [], "gap_before": {"rms_um": 0.01},
                       "gap_after": {"rms_um": 0.002}})
    qtbot.wait(50)
    assert win.explain_dock.height() >= tall - 2
