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


def test_the_steps_error_and_position_channels_are_shown_as_lengths():
    """kinematic_error / dynamic_error (signed, diverging), u_x (an uncertainty) and z_raw, xd
    (positions, about their mean) in the unit their spread asks for — they were shown raw in mm
    ("PV 9.996e-05", a 3D bar of "1" five times for z_raw around 1 mm)."""
    import numpy as np

    from pointspro.app import display
    from pointspro.core import PointCloud

    rng = np.random.default_rng(0)
    n = 500
    e = 5e-4 * rng.standard_normal(n)
    c = PointCloud.from_xyz(rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), np.zeros(n),
                            kinematic_error=e, dynamic_error=e, u_x=np.abs(e), z_raw=1.0 + e, xd=2.0 + e)
    for name, diverging in (("kinematic_error", True), ("dynamic_error", True), ("u_x", False),
                            ("z_raw", False), ("xd", False)):
        v, title, unit, div = display.channel_display(c, name)
        assert unit == "µm" and title.endswith("(µm)") and div == diverging, (name, title)
        assert abs(np.mean(v)) < 50  # positions about their mean, in µm


def test_readouts_show_a_length_in_the_unit_its_own_size_asks_for():
    """The profile's PV and the threshold read "1.001 mm", not "1001 µm" (the colour bar's unit)."""
    from pointspro.app.display import shown_length

    assert shown_length(1001.0, "µm") == "1.001 mm"
    assert shown_length(2.53, "µm") == "2.53 µm"
    assert shown_length(43.9, "nm") == "43.9 nm"
    assert shown_length(5.0, "Hz") == "5 Hz" and shown_length(3.0, "") == "3"
