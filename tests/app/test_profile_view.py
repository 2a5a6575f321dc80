"""Stylus profiles in the window's 2D panel: each profile drawn as a curve along its own line
(pytest-qt, offscreen)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")


def _two_profiles():
    from pointspro.core import PointCloud

    s = np.linspace(-20, 20, 401)
    xs, ys, zs, ang = [], [], [], []
    for theta, amp in ((0.0, 50e-6), (90.0, 20e-6)):
        t = np.radians(theta)
        xs.append(s * np.cos(t))
        ys.append(s * np.sin(t))
        zs.append(amp * np.cos(2 * np.pi * s / 20))
        ang.append(np.full(s.size, theta))
    return PointCloud.from_xyz(np.concatenate(xs), np.concatenate(ys), np.concatenate(zs),
                               angle=np.concatenate(ang), residual=np.concatenate(zs))


def test_stylus_profiles_are_drawn_as_curves(qtbot):
    from pointspro.app.mapview import MapView

    m = MapView()
    qtbot.addWidget(m)
    cloud = _two_profiles()
    m.set_cloud(cloud, "residual", new_input=True)
    assert m.stylus is not None and [p.angle_deg for p in m.stylus] == [0.0, 90.0]
    assert len(m._profile_artists) == 2
    s0, v0 = m._profile_artists[0].get_data()
    assert np.all(np.diff(s0) > 0) and s0[0] == pytest.approx(-20) and s0[-1] == pytest.approx(20)
    # shown in the channel's display unit (nm here): PV 100 nm and 40 nm
    assert np.ptp(v0) == pytest.approx(100, rel=1e-6)
    assert np.ptp(m._profile_artists[1].get_data()[1]) == pytest.approx(40, rel=1e-6)
    assert "2 stylus profile(s)" in m.profile_info.text() and "90°" in m.profile_info.text()
    assert m.pax.get_xlabel() == "along the profile (mm)"
    # an edit (a deletion) of the same input keeps the curves, with the new data
    keep = np.ones(cloud.n, bool)
    keep[:10] = False
    m.set_cloud(cloud.select(keep), "residual", keep_limits=True)
    assert m._profile_artists[0].get_data()[0].size == 391
    # an areal cloud goes back to the map's cut along x
    from pointspro.core import PointCloud

    g = np.linspace(-10, 10, 30)
    X, Y = np.meshgrid(g, g)
    m.set_cloud(PointCloud.from_xyz(X.ravel(), Y.ravel(), 0 * X.ravel()), "z", new_input=True)
    assert m.stylus is None and m.pax.get_xlabel() == "along the cut (mm)"
    qtbot.wait(20)  # let the canvas's pending draw run before the widget is deleted
