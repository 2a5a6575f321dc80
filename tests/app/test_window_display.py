"""What the window shows, checked without looking at pixels (pytest-qt, offscreen): the step tables
show each number once, the 3D view's count of drawn points is true, and the map's labels stay inside
its canvas and the window when the autosave banner is shown. (Lengths in the parameter forms:
test_param_widgets.py.)"""
from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("pytestqt")


def _disc(n_side=41, radius=20.0, seed=3):
    rng = np.random.default_rng(seed)
    x, y = (a.ravel() for a in np.meshgrid(np.linspace(-radius, radius, n_side), np.linspace(-radius, radius, n_side)))
    keep = np.hypot(x, y) <= radius
    x, y = x[keep], y[keep]
    return x, y, 2e-4 * (x * x + y * y) / radius ** 2 + rng.normal(0, 2e-5, x.size)


def test_zernike_table_shows_the_radius_once_with_its_unit(qtbot):
    """zernike reports ``norm_radius`` (its parameter's name) and ``norm_radius_mm`` (the pupil's):
    the same number, which the step's table showed twice ("norm_radius 20 mm", "norm_radius_mm 20
    mm"). The panel shows it once, named without the suffix and with its unit; report.json keeps
    both keys."""
    from pointspro.app.report_panel import ReportPanel
    from pointspro.core import api as pp
    from pointspro.core.cloud import PointCloud

    x, y, z = _disc()
    res = pp.run({"pointspro": 1, "steps": [{"zernike": {"terms": 10}}]}, PointCloud(np.column_stack([x, y, z])))
    panel = ReportPanel()
    qtbot.addWidget(panel)
    panel.set_result(res._run)
    rec = res._run.steps[0]
    assert rec.report["norm_radius"] == rec.report["norm_radius_mm"] == 20.0  # both in the report
    page = panel.html_for(1)
    rows = re.findall(r"<tr><th>([^<]*radius[^<]*)</th><td[^>]*>([^<]*)</td>", page)
    assert rows == [("norm_radius", "20 mm")]
    assert "centre_from" in page and "ordering" in page  # the rest of the table is there


def test_report_table_keeps_a_bare_key_whose_number_differs():
    from pointspro.app.report_panel import shown_report

    r = {"norm_radius": 20.0, "norm_radius_mm": 20.0, "window": 15.0, "window_um": 15.0,
         "spacing": 2.0, "spacing_um": 2000.0, "terms": 10}
    # the same length in another unit is a duplicate too; a different number is not
    assert shown_report(r) == {"norm_radius_mm": 20.0, "window": 15.0, "window_um": 15.0, "spacing_um": 2000.0,
                               "terms": 10}
    assert shown_report({"a": 1}) == {"a": 1}


def test_3d_view_draws_at_most_its_budget_and_says_how_many_of_how_many(qtbot, tmp_path):
    """The level of detail's hash takes the budget's share on average: 150,001 of 200,000 rows for a
    budget of 150,000 (a few more than the budget at times). Never more than the budget now, and the
    count is that of the measurement's points drawn (the mesh), never above the points shown."""
    from pointspro.app import display
    from pointspro.app.main import build_window
    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    for n, budget in ((200_000, 150_000), (6000, 163), (5000, 102), (4680, 195), (12_345, 12_344)):
        rows = display.display_subset(np.arange(n), n, budget)
        assert rows.size <= budget and np.all(np.diff(rows) > 0), (n, budget, rows.size)
        assert rows.size >= 0.97 * budget
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-50, 50, (2, 6000))
    write_csv(PointCloud.from_xyz(x, y, (x * x + y * y) / 2000, residual=1e-4 * np.sin(x / 10)), tmp_path / "c.csv")
    win = build_window([tmp_path / "c.csv"])
    qtbot.addWidget(win)
    v3 = win.view3d
    assert v3.info.text() == "6,000 points" and v3.mesh.n_points == 6000
    v3.budget = 163  # the hash alone took 165 of these 6000 rows
    v3.set_cloud(win.map.cloud, "residual", new_input=True)
    drawn = v3.mesh.n_points
    assert drawn <= 163 and v3.info.text() == f"{drawn:,} of 6,000 points drawn"
    v3.highlight(np.ones(6000, dtype=bool))  # the selection's highlight is not counted
    assert v3.info.text() == f"{drawn:,} of 6,000 points drawn"
    keep = x < 0  # points hidden (deleted): drawn of those shown
    v3.set_cloud(win.map.cloud, "residual", keep=keep)
    shown = int(keep.sum())
    assert v3.mesh.n_points <= min(163, shown) and v3.info.text() == f"{v3.mesh.n_points:,} of {shown:,} points drawn"
    from pointspro.app.view3d import drawn_text

    assert drawn_text(150_000, 150_000) == "150,000 points" and drawn_text(10, 4680) == "10 of 4,680 points drawn"


def _label_extents(m):
    m.canvas.draw()
    r = m.canvas.get_renderer()
    return {name: lab.get_window_extent(r) for name, lab in
            (("y", m.ax.yaxis.label), ("colour bar", m.cax.yaxis.label), ("profile y", m.pax.yaxis.label),
             ("profile x", m.pax.xaxis.label))}


def test_map_labels_stay_inside_a_narrow_canvas(qtbot):
    """At the canvas' minimum width (320 px: the map dock squeezed) the fixed 15 % left of the map
    put "y (mm)" wholly left of the canvas (x from -15 to -1 px) and the colour bar's label off its
    right edge. The margins widen where the labels need it, and are the usual ones where there is
    room."""
    from pointspro.app.mapview import MapView
    from pointspro.core import PointCloud

    rng = np.random.default_rng(0)
    x, y = rng.uniform(-650, 650, (2, 5000))
    m = MapView()
    qtbot.addWidget(m)
    m.resize(324, 700)
    m.show()
    qtbot.waitExposed(m)
    m.set_cloud(PointCloud.from_xyz(x, y, (x * x + y * y) / 2000, residual=1e-3 * np.sin(x / 100)), "residual",
                new_input=True)
    assert m.canvas.width() == 320
    w, h = m.figure.bbox.width, m.figure.bbox.height
    for name, e in _label_extents(m).items():
        assert 0 <= e.x0 and e.x1 <= w and 0 <= e.y0 and e.y1 <= h, (name, e)
    from pointspro.app.mapview import MARGINS

    assert m.figure.subplotpars.left > MARGINS["left"] and m.figure.subplotpars.right < MARGINS["right"]
    m.resize(700, 700)  # room again: the usual margins
    qtbot.waitUntil(lambda: m.canvas.width() > 600)
    _label_extents(m)
    assert m.figure.subplotpars.left == MARGINS["left"] and m.figure.subplotpars.right == MARGINS["right"]


def test_autosave_banner_keeps_the_window_and_the_map_their_width(qtbot, tmp_path, monkeypatch):
    """The banner's one line of text (~800 px) set the centre's minimum width: shown, it made the
    window wider than its 1280 px and squeezed the map dock to 320 px, its y label cut off. Wrapped,
    it takes the width the centre has."""
    from pointspro.app.main import build_window

    monkeypatch.setenv("POINTSPRO_AUTOSAVE_DIR", str(tmp_path))
    (tmp_path / "autosave.pointspro.yaml").write_text("pointspro: 1\nsteps: []\n", encoding="utf-8")
    win = build_window([])
    qtbot.addWidget(win)
    assert not win.banner.isHidden() and "unsaved session" in win.banner_text.text()
    central = win.centralWidget()
    assert central.minimumSizeHint().width() < 500
    win.show()
    qtbot.waitExposed(win)
    assert win.width() <= 1280
