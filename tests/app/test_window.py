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
