"""File → Export correction…: the correction step's form, preview and export (pytest-qt, offscreen)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("pytestqt")


def _last_run():
    """What a run leaves: a cloud in the part frame with a residual (astigmatism and a zone, µm
    scale) over Ø 40 mm, and the recipe's nominal."""
    from pointspro.core import PointCloud
    from pointspro.core.surfaces import EvenAsphere

    rng = np.random.default_rng(3)
    g = np.arange(-21, 21.01, 0.5)  # a raster at 0.5 mm, measured a little past the Ø 40 mm aperture
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = np.hypot(x, y) <= 21
    x, y = x[keep], y[keep]
    r, t = np.hypot(x, y), np.arctan2(y, x)
    surf = EvenAsphere(1 / 200.0, -0.5, {}, aperture=40.0)
    res = 1e-4 * (r / 20) ** 2 * np.cos(2 * t) + 5e-5 * np.cos(np.pi * r / 10) + rng.normal(0, 2e-6, r.size)
    cloud = PointCloud.from_xyz(x, y, surf.sag(x, y) + res, residual=res).replace(meta={"frame": "part"})
    return SimpleNamespace(cloud=cloud, surface=surf, artifacts={})


def test_export_correction_previews_and_writes(qtbot, tmp_path):
    from pointspro.app.main import build_window

    win = build_window([])
    qtbot.addWidget(win)
    assert "Export correction…" in [a.text() for a in win.menuBar().actions()[0].menu().actions()]
    assert win.export_correction() is None  # no run yet: one line, no dialog
    assert "run the pipeline first" in win.log_widget.toPlainText()

    win.last_report = _last_run()
    dlg = win.export_correction()
    qtbot.waitUntil(lambda: dlg.result is not None or bool(dlg.message.text()), timeout=60000)
    qtbot.waitUntil(lambda: not dlg.worker.busy, timeout=10000)
    assert dlg.result is not None, dlg.message.text()
    text = dlg.summary.text()
    assert "ADD to the programmed surface" in text and "predicted after correction" in text
    assert "corrected surface" in text and "removal (polishing)" in text
    assert not dlg.picture.pixmap().isNull()
    full = dlg.result.report["predicted_rms_um"]

    # a value outside the bounds is refused where it is typed; nothing recomputed
    dlg.widgets["gain"].enter(5.0)
    assert dlg.widgets["gain"].problem and dlg.values.get("gain") is None
    # gain 0.5 corrects half: the predicted error after it is about half the error
    with qtbot.waitSignal(dlg.computed, timeout=60000):
        dlg.widgets["gain"].enter(0.5)
    rep = dlg.result.report
    assert rep["predicted_rms_um"] == pytest.approx(0.5 * rep["error_rms_um"], rel=0.15)
    assert rep["predicted_rms_um"] > 2 * full

    out = dlg.export(tmp_path)
    assert out == tmp_path / "correction"
    names = {p.name for p in out.iterdir()}
    assert {"correction.csv", "correction.x3p", "correction_radial.csv", "corrected_surface.yaml",
            "removal.csv", "correction.png"} <= names
    head = (out / "correction.csv").read_text(encoding="utf-8").splitlines()[:8]
    assert any("ADD to the programmed surface" in line for line in head)
    assert dlg.export(tmp_path) == out  # a second export replaces its own folder
    (out / "notes.txt").write_text("mine", encoding="utf-8")
    assert dlg.export(tmp_path) is None and "holds other files" in dlg.message.text()
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"
    assert not list(tmp_path.glob(".*partial"))


def test_export_correction_takes_heights_that_are_the_error(qtbot):
    """A recipe `correction: {channel: z}` on an instrument's error map makes no residual: Export
    correction… refused the run that had just made the correction ("run the pipeline first", a
    review of the window). It opens with channel z; a run without either is still refused."""
    from pointspro.app.main import build_window
    from pointspro.core.recipe import parse_recipe

    win = build_window([])
    qtbot.addWidget(win)
    run = _last_run()
    from pointspro.core import PointCloud

    heights = PointCloud.from_xyz(run.cloud.x, run.cloud.y, run.cloud["residual"])  # the error map
    win.last_report = SimpleNamespace(cloud=heights, surface=None, artifacts={})
    assert win.export_correction() is None
    assert "channel: z" in win.log_widget.toPlainText()
    win.session.recipe = parse_recipe({"pointspro": 1, "steps": [{"correction": {"channel": "z", "diameter": 40}}]})
    dlg = win.export_correction()
    assert dlg is not None
    qtbot.waitUntil(lambda: dlg.result is not None or bool(dlg.message.text()), timeout=60000)
    qtbot.waitUntil(lambda: not dlg.worker.busy, timeout=10000)
    assert dlg.result is not None, dlg.message.text()
