"""The window with millions of points (issue 26): the 3D view draws a level of detail, selections
and deletions are at full resolution (every point, exactly the mask testing every point gives),
the map's bins follow deletions and undo, the undo history keeps masks, not copies of the cloud.
Behaviour only: the timings are benchmarks/bench_window_large.py's."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")


def _ply(path, n, seed):
    """A scattered circular map of n points, binary PLY (x, y, z float64, mm), rows in random order."""
    from pointspro.core import PointCloud
    from pointspro.core.io import write_cloud

    rng = np.random.default_rng(seed)
    r = 50 * np.sqrt(rng.random(n))
    t = 2 * np.pi * rng.random(n)
    x, y = r * np.cos(t), r * np.sin(t)
    z = 1e-4 * (x * x - y * y) / 2500 + 2e-6 * rng.standard_normal(n)
    write_cloud(PointCloud.from_xyz(x, y, z), path)
    return path


def _removed_rows(params) -> np.ndarray:
    """The input rows a manual_edit step removes (``remove`` and the ``remove_ranges`` runs)."""
    parts = [np.asarray(params.remove, dtype=np.int64)]
    parts += [np.arange(a, b + 1) for a, b in params.remove_ranges]
    return np.unique(np.concatenate(parts))


def _reference_map(m, cloud):
    """The map image of ``cloud`` (rows of the view's cloud) computed from scratch with the view's
    extent, bins and values (z about the mean of the view's cloud, kept through edits)."""
    from pointspro.app import display
    from pointspro.core.figures import binned_image

    v, _, _, _ = display.channel_display(m.cloud, m.channel, m._unit, rows=cloud.index)
    img, _, _ = binned_image(cloud.x, cloud.y, v, ext=m.ext, bins=m._bins)
    return img


def _same_image(a, b):
    a, b = (np.ma.filled(np.ma.asarray(x, dtype=np.float64), np.nan) for x in (a, b))
    return np.array_equal(np.isnan(a), np.isnan(b)) and np.allclose(a[~np.isnan(a)], b[~np.isnan(b)],
                                                                    rtol=1e-9, atol=1e-12)


def test_two_million_points_draw_a_lod_and_delete_exactly(qtbot, tmp_path):
    from pointspro.app import display
    from pointspro.app.main import build_window
    from pointspro.core.geometry.polygon import points_in_polygon

    n = 2_000_000
    path = _ply(tmp_path / "map.ply", n, seed=3)
    win = build_window([path])
    qtbot.addWidget(win)
    s, v3, m = win.session, win.view3d, win.map
    inp = s.input_cloud
    assert s.n_shown == n
    # level of detail for drawing: a share of the points, by input row
    drawn = v3.mesh.n_points
    assert 0.9 * v3.budget < drawn < 1.1 * v3.budget and f"of {n:,} points drawn" in v3.info.text()
    # a lasso through the 3D view: the same mask as projecting and testing every point
    w = v3.plotter.interactor
    W, H = w.width(), w.height()
    t = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    rr = 0.15 * min(W, H) * (1 + 0.3 * np.sin(3 * t))
    poly = np.column_stack([0.45 * W + rr * np.cos(t), 0.5 * H + rr * np.sin(t)])
    mask = v3.select_lasso(poly)
    matrix, width, height = v3._camera()
    sx, sy = display.to_screen(inp.xyz - v3.origin, matrix, width, height)
    assert np.array_equal(mask, points_in_polygon(sx, sy, poly)) and 1000 < mask.sum() < n // 2
    win.set_selection(mask)
    k = int(mask.sum())
    assert f"{k:,} point(s) selected" in win.sel_label.text()
    win.delete_selection()
    # full resolution for computing: exactly those input rows gone, recorded by manual_edit
    assert s.n_shown == n - k and s.shown.n == n - k
    assert np.array_equal(s.shown.index, np.flatnonzero(~mask))
    assert np.array_equal(_removed_rows(s.recipe.steps[-1].params), np.flatnonzero(mask))
    assert s.view[0] is inp and s.history._undo[-1].shown is inp  # a mask, not a copy of the cloud
    # both views follow: the map's bins equal a map drawn from scratch, the 3D view drops the rows
    assert _same_image(m.im.get_array(), _reference_map(m, s.shown))
    lod = display.display_subset(inp.index, n, v3.budget)
    assert v3.mesh.n_points == int(np.count_nonzero(~mask[lod]))
    # a second selection, a lasso on the map in mm: hidden points are never selected
    one = s.shown
    m._on_lasso([(-40.0, -40.0), (10.0, -30.0), (0.0, 20.0), (-45.0, 5.0)])
    expect = points_in_polygon(inp.x, inp.y, np.array([(-40.0, -40.0), (10.0, -30.0), (0.0, 20.0),
                                                       (-45.0, 5.0)])) & ~mask
    assert np.array_equal(win._sel, expect)
    assert np.array_equal(win.selection, expect[~mask])  # over the shown cloud
    win.delete_selection()
    assert s.n_shown == n - k - int(expect.sum())
    assert _same_image(m.im.get_array(), _reference_map(m, s.shown))
    # undo restores, twice; redo deletes again
    win.undo_action.trigger()
    assert s.shown.equals(one) and _same_image(m.im.get_array(), _reference_map(m, one))
    win.undo_action.trigger()
    assert s.n_shown == n and s.shown is inp and v3.mesh.n_points == drawn
    assert _same_image(m.im.get_array(), _reference_map(m, inp))
    win.redo_action.trigger()
    assert s.shown.equals(one)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_cell_index_selects_as_testing_every_point(seed):
    """Cells decided whole from their boxes give the same mask as every point tested: oblique
    cameras, a camera with points behind it, lassos and rectangles of several sizes, hidden points."""
    from pointspro.app import display
    from pointspro.core.geometry.polygon import in_rectangle, points_in_polygon

    rng = np.random.default_rng(seed)
    n = 300_000
    x, y = rng.uniform(-50, 50, (2, n))
    if seed % 2:  # a raster, rows in order
        g = np.linspace(-50, 50, 548)
        x, y = (a.ravel()[:n] for a in np.meshgrid(g, g))
    xyz = np.column_stack([x, y, (x * x + y * y) / 400 + 1e-3 * rng.standard_normal(x.size)])
    ix = display.CellIndex(xyz, g=64 if seed == 2 else 256)
    keep = rng.random(x.size) > 0.2
    origin = xyz.mean(0)
    a = rng.uniform(0, 1.2)
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    mat = np.eye(4)
    mat[:3, :3] = rot / 60
    mat[3, :3] = rot[2] * (0.05 if seed == 3 else 0.002)  # seed 3: some points behind the camera
    mat[2, 3] = 0.1
    W, H = 800, 600
    sx, sy = display.to_screen(xyz - origin, mat, W, H)
    for scale in (30, 150, 500):
        t = np.linspace(0, 2 * np.pi, 41)[:-1]
        r = scale * (1 + 0.4 * np.sin(3 * t) * rng.random())
        poly = np.column_stack([400 + r * np.cos(t), 300 + r * np.sin(t)])

        def boxes(cells, cls_of):
            bx0, bx1, by0, by1, front = display.screen_boxes(cells.corners(origin), mat, W, H)
            c = cls_of(bx0, bx1, by0, by1)
            c[~front] = -1
            return c

        def exact(test):
            return lambda pos: test(*display.to_screen(xyz[pos] - origin, mat, W, H))
        got = ix.select(lambda c: boxes(c, lambda *b: display.polygon_class(*b, poly)),
                        exact(lambda u, v: points_in_polygon(u, v, poly)), keep)
        assert np.array_equal(got, points_in_polygon(sx, sy, poly) & keep)
        rect = (400 - scale, 400 + scale / 2, 300 + scale, 300 - scale / 3)
        got = ix.select(lambda c: boxes(c, lambda *b: display.rectangle_class(*b, *rect)),
                        exact(lambda u, v: in_rectangle(u, v, *rect)))
        assert np.array_equal(got, in_rectangle(sx, sy, *rect))
    # in the plane (the 2D map): a lasso in mm
    poly = np.array([(-40.0, -40.0), (30.0, -20.0), (-5.0, 0.0), (20.0, 35.0), (-45.0, 10.0)])
    got = ix.select(lambda c: display.polygon_class(*c.xy_boxes(), poly),
                    lambda pos: points_in_polygon(xyz[pos, 0], xyz[pos, 1], poly), keep)
    assert np.array_equal(got, points_in_polygon(xyz[:, 0], xyz[:, 1], poly) & keep)


def test_session_deletes_by_mask_over_either_cloud_and_keeps_bits_for_undo():
    from pointspro.core import PointCloud
    from pointspro.core.session import Session

    rng = np.random.default_rng(5)
    c = PointCloud.from_xyz(*rng.uniform(-1, 1, (3, 1000)))
    s = Session()
    s.input_cloud = c
    s.shown = c
    first = c.x > 0.5
    assert s.delete(first) == first.sum() and s.n_shown == 1000 - first.sum()
    assert isinstance(s.history._undo[-1].shown, PointCloud) and s.history._undo[-1].keep is None
    over_shown = s.shown.y > 0  # a mask over the shown cloud
    assert s.delete(over_shown) == over_shown.sum()
    gone = first | ((c.y > 0) & ~first)
    assert np.array_equal(s.shown.index, np.flatnonzero(~gone))
    assert s.history._undo[-1].keep.dtype == np.uint8  # packed bits, 1/8 byte a point
    over_view = c.z > 0.9  # over the view's cloud: the deleted ones are not counted again
    assert s.delete(over_view) == int((over_view & ~gone).sum())
    assert np.array_equal(_removed_rows(s.recipe.steps[-1].params), np.flatnonzero(over_view & ~gone))
    s.undo()
    s.undo()
    assert np.array_equal(s.shown.index, np.flatnonzero(~first))
    with pytest.raises(Exception, match="selection holds 3 points"):
        s.delete(np.ones(3, dtype=bool))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_profile_dots_keep_every_interval_s_lowest_and_highest_point(seed):
    """The profile's dots above the budget: per interval along the cut the minimum and the maximum
    of all points (a one-point spike or dig among 10^5 stays drawn), within the budget."""
    from pointspro.app import display

    rng = np.random.default_rng(seed)
    n = 100_000 + 1_000 * seed
    s = np.sort(rng.uniform(0, 80, n))
    v = 1e-4 * np.sin(s) + 2e-6 * rng.standard_normal(n)
    spike, dig = rng.integers(0, n, 2)
    v[spike], v[dig] = 5e-3, -5e-3
    rows = display.envelope_rows(s, v, budget=4_000)
    assert rows is not None and rows.size <= 4_000 and np.all(np.diff(rows) > 0)
    assert spike in rows and dig in rows
    nb = 2_000
    j = np.minimum(((s - s[0]) * (nb / (s[-1] - s[0]))).astype(int), nb - 1)
    for b in rng.integers(0, nb, 50):  # each interval's extremes are among the drawn rows
        in_b = np.flatnonzero(j == b)
        if in_b.size:
            assert v[in_b].min() in v[rows[j[rows] == b]]
            assert v[in_b].max() in v[rows[j[rows] == b]]
    assert display.envelope_rows(s[:3_000], v[:3_000], budget=4_000) is None  # few: all drawn


def test_an_edit_shows_on_the_map_without_a_full_redraw(qtbot):
    """The map's fast redraw restores a background taken at the last full draw: it must not hold
    the map image itself (the lasso selector draws the axes' animated artists in its own draw_event
    handler), or a deletion's hole and an old highlight stay on screen until something redraws."""
    from pointspro.app.mapview import MapView
    from pointspro.core import PointCloud

    rng = np.random.default_rng(0)
    n = 200_000
    x, y = rng.uniform(-50, 50, n), rng.uniform(-50, 50, n)
    cloud = PointCloud.from_xyz(x, y, 1e-4 * (x * x + y * y) / 2500)
    m = MapView()
    qtbot.addWidget(m)
    m.resize(700, 900)
    m.show()
    m.set_cloud(cloud, "z", new_input=True)
    m.canvas.draw()  # a full draw: the selectors' handlers run too
    hole = np.hypot(x - 5, y - 8) < 15

    def white(px, py, r=6):
        """The fraction of white pixels in a (2r+1)² patch of the canvas around data point (px, py)."""
        buf = np.asarray(m.canvas.buffer_rgba())
        dx, dy = m.ax.transData.transform((px, py))
        row, col = int(buf.shape[0] - dy), int(dx)
        patch = buf[row - r:row + r + 1, col - r:col + r + 1, :3]
        return float(np.mean(np.all(patch == 255, axis=-1)))

    assert white(5, 8) < 0.8 and white(-35, -30) < 0.8  # the map is drawn there (some bins empty)
    m.highlight(hole)
    m.set_cloud(cloud, "z", keep=~hole, keep_limits=True)  # the deletion: a blit, not a full draw
    assert white(5, 8) == 1.0  # the axes' background shows through the emptied bins
    assert white(-35, -30) < 0.8  # the rest still drawn
