"""The window opens the example, colours by every channel, and renders a screenshot (pytest-qt)."""
from __future__ import annotations

import pytest

from ..conftest import EXAMPLE

pytest.importorskip("pytestqt")


def test_window_shows_example_and_switches_channels(qtbot):
    from PySide6.QtWidgets import QComboBox

    from pointspro.app.main import build_window

    win = build_window([EXAMPLE / "asphere_cmm.csv"])
    qtbot.addWidget(win)
    combo = win.findChild(QComboBox)
    items = [combo.itemText(i) for i in range(combo.count())]
    assert items[0] == "z" and "line" in items
    combo.setCurrentText("line")
    assert "line" in win.plotter.mesh.array_names
    win.plotter.close()


def test_screenshot_command_writes_png(tmp_path, run_cli):
    png = tmp_path / "shot.png"
    code, _, err = run_cli("--screenshot", png, EXAMPLE / "asphere_cmm.csv")
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000


def test_residual_map_dock_shows_the_report_figure(qtbot, tmp_path):
    """A processed cloud opens on its residual, with the report's form-error figure beside the 3D view
    (the same core.figures function the batch report uses); z has no such figure."""
    import numpy as np
    from PySide6.QtWidgets import QComboBox, QDockWidget

    from pointspro.app.main import build_window
    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    rng = np.random.default_rng(0)
    x, y = rng.uniform(-50, 50, (2, 2000))
    write_csv(PointCloud.from_xyz(x, y, np.zeros(2000), residual=1e-4 * np.sin(x / 10)), tmp_path / "c.csv")
    win = build_window([tmp_path / "c.csv"])
    qtbot.addWidget(win)
    win.show()
    dock = [d for d in win.findChildren(QDockWidget) if d.windowTitle().startswith("Form-error map")][0]
    assert dock.isVisible()
    ax = win.figure_canvas.figure.axes[0]
    assert ax.get_xlabel() == "x (mm)" and "µm" in win.figure_canvas.figure.axes[1].get_ylabel()
    img = ax.images[0].get_array()
    assert np.nanmax(np.abs(img)) == pytest.approx(0.1, rel=0.05)  # 1e-4 mm·sin → ±0.1 µm
    win.findChild(QComboBox).setCurrentText("z")
    assert not dock.isVisible()
    win.plotter.close()


def _example_window(qtbot):
    from pointspro.app.main import build_window
    from pointspro.core.recipe import load_yaml

    win = build_window([EXAMPLE / "asphere_cmm.csv"])
    qtbot.addWidget(win)
    data = load_yaml((EXAMPLE / "recipe.yaml").read_text(), "recipe")
    win.session.set_recipe({**data, "steps": list(data["steps"])[:5]})
    return win


def test_run_in_worker_keeps_the_window_responsive(qtbot):
    """The pipeline runs in a thread: the event loop never stalls above 100 ms meanwhile."""
    import time

    from PySide6 import QtCore

    win = _example_window(qtbot)
    gaps, last = [], [time.perf_counter()]

    def tick():
        now = time.perf_counter()
        gaps.append(now - last[0])
        last[0] = now

    timer = QtCore.QTimer()
    timer.setInterval(10)
    timer.timeout.connect(tick)
    timer.start()
    win.pipeline.run_all.click()
    assert win._thread is not None
    qtbot.waitUntil(lambda: win._thread is None, timeout=120_000)
    timer.stop()
    assert "residual" in win.session.shown.channels and win.session.shown.n == 4640
    assert max(gaps[1:]) < 0.1, max(gaps)
    assert win.pipeline.list.count() == 5 and win.pipeline.bar.value() == 1000
    win.plotter.close()


def test_select_delete_undo_redo_and_project(qtbot, tmp_path):
    win = _example_window(qtbot)
    win.session.run()
    n0 = win.session.shown.n
    win.map.set_mask(win.session.select_rectangle(-150, 150, -150, 150))
    k = int(win.map.mask.sum())
    win.delete_selection()
    assert win.session.shown.n == n0 - k and "manual_edit" in win.session.steps[-1]
    assert "residual" in win.plotter.mesh.array_names[0] or win.plotter.mesh.n_points == n0 - k
    win.undo_action.trigger()
    assert win.session.shown.n == n0
    win.redo_action.trigger()
    assert win.session.shown.n == n0 - k
    # the pipeline form marks an invalid value and keeps the old one
    win.pipeline.list.setCurrentRow(4)
    win.pipeline.fields["diameter"].setText("-5")
    win.pipeline._apply()
    assert "ffd6d6" in win.pipeline.fields["diameter"].styleSheet()
    assert win.session.steps[4] == {"aperture": {"diameter": 1290}}
    # save, reopen in a new window: the same cloud
    win.session.save_project(tmp_path / "p.pointspro.yaml")
    from pointspro.app.main import build_window

    w2 = build_window([])
    qtbot.addWidget(w2)
    w2.open_any(str(tmp_path / "p.pointspro.yaml"))
    assert w2.session.shown.equals(win.session.shown)
    # a corrupt file: a message, and the window keeps what it had
    (tmp_path / "bad.csv").write_text("x,y,z\n1,2\n")
    w2.open_any(str(tmp_path / "bad.csv"))
    assert "error:" in w2.log_widget.toPlainText() and w2.session.shown.equals(win.session.shown)
    win.plotter.close()
    w2.plotter.close()
