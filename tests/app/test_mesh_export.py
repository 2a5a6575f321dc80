"""File → Export mesh…: the last run's bspline_map map written as a mesh (pytest-qt, offscreen)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("pytestqt")


def test_export_mesh_writes_the_last_map(qtbot, tmp_path):
    from pointspro.app.main import build_window
    from pointspro.core import PointCloud
    from pointspro.core.io.mesh import read_mesh
    from pointspro.core.step import Context
    from pointspro.plugins.bspline_map import BSplineMapStep

    win = build_window([])
    qtbot.addWidget(win)
    assert "Export mesh…" in [a.text() for a in win.menuBar().actions()[0].menu().actions()]
    win.export_mesh(tmp_path / "none.ply")  # no run yet: one line, nothing written
    assert "add one and run" in win.log_widget.toPlainText() and not (tmp_path / "none.ply").exists()
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-20, 20, (2, 3000))
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(x), residual=1e-3 * np.sin(x / 5))
    res = BSplineMapStep().run(cloud, BSplineMapStep.Params(spacing=1.0), Context())
    win.last_report = SimpleNamespace(artifacts=res.artifacts)  # what a run leaves
    grid = res.artifacts["map.csv"].__self__
    ok = np.isfinite(grid.z)
    for fmt in ("ply", "obj", "stl"):
        win.export_mesh(tmp_path / f"map.{fmt}")
        v, f = read_mesh(tmp_path / f"map.{fmt}")
        assert len(f) > 0 and len(v) <= ok.sum()
    v, f = read_mesh(tmp_path / "map.ply")
    assert np.array_equal(v[:, 2], grid.z[ok])
    assert "exported the map as a mesh" in win.log_widget.toPlainText()
    assert not list(tmp_path.glob(".*partial"))
