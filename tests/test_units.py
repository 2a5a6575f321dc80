"""Numbers for people: a length in the unit its size asks for (core.units, app.display)."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.app.display import channel_display, display_unit
from pointspro.core.cloud import PointCloud
from pointspro.core.units import format_length


@pytest.mark.parametrize("mm, text", [(4.39e-5, "43.9 nm"), (1.3634e-3, "1.36 µm"), (0.0, "0 mm"),
                                      (2.5, "2.5 mm"), (1300.0, "1300 mm"), (1292.7, "1293 mm"), (15000.0, "15 m"),
                                      (-7.2e-7, "-0.72 nm"), (3e-10, "0.0003 nm")])
def test_format_length(mm, text):
    assert format_length(mm) == text


def test_display_unit_follows_the_spread_and_is_kept_when_asked():
    x = np.linspace(0, 10, 1000)
    for amp, unit, scale in [(2e-5, "nm", 1e-6), (3e-3, "µm", 1e-3), (2.0, "mm", 1.0)]:
        c = PointCloud.from_xyz(x, x, amp * np.sin(x), residual=amp * np.cos(x))
        assert display_unit(c["residual"]) == unit
        v, title, u, diverging = channel_display(c, "residual")
        assert (title, u, diverging) == (f"residual ({unit})", unit, True)
        np.testing.assert_allclose(v, c["residual"] / scale, rtol=1e-15)
        v, title, u, _ = channel_display(c, "z")
        assert title == f"z − mean ({unit})" and u == unit
    # a view editing one input keeps its unit (and so its colour limits' meaning)
    v, title, u, _ = channel_display(c, "residual", unit="µm")
    assert u == "µm" and title == "residual (µm)"
    np.testing.assert_allclose(v, c["residual"] * 1e3)
