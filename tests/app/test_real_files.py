"""Issue 15: the window opens every real instrument file of tests/data/realdata (made by real
instruments; see its README), shows all its valid points, and a map's figures read in nm/µm."""
from __future__ import annotations

from pathlib import Path

import pytest

from pointspro.core.io import read_cloud

REAL = Path(__file__).resolve().parents[1] / "data" / "realdata"
FILES = ["metropro-1.dat", "sur-2.sur", "opd-1.opd", "mi-1.mi", "matrix-3.txt",
         "gwyddion-export-english.txt", "sdf-1.sdf", "xyz-1.txt"]


@pytest.mark.parametrize("name", FILES)
def test_window_opens_each_real_file(qtbot, name):
    from pointspro.app.main import build_window

    win = build_window([REAL / name])
    qtbot.addWidget(win)
    shown = win.session.shown
    assert shown is not None and shown.n == read_cloud(REAL / name).n
    assert win.map.info.text() == f"{shown.n:,} points"
    assert win.map.cbar.ax.get_ylabel().startswith("z − mean (")
    assert "read " in win.log_widget.toPlainText() and "error" not in win.log_widget.toPlainText()
