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
