"""Issue 17: the PSD figures label their log axes in plain text (matplotlib's mathtext parser took
1.6 s of the PSD figure); the data drawn are unchanged."""
from __future__ import annotations

from unittest import mock

import numpy as np
import pytest

from pointspro.core import figures
from pointspro.core.maps.grid import MapGrid


def _grid(seed):
    rng = np.random.default_rng(seed)
    xs = np.arange(-300.0, 301.0, 6.0)
    X, Y = np.meshgrid(xs, xs)
    z = 1e-4 * np.sin(X / (60 + 10 * seed)) * np.cos(Y / 45) + 1e-6 * rng.standard_normal(X.shape)
    z[X ** 2 + Y ** 2 > 300.0 ** 2] = np.nan
    return MapGrid(xs, xs, z, 6.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_psd_figure_draws_without_mathtext(tmp_path, seed):
    from matplotlib.mathtext import MathTextParser

    fig = figures.psd_figure(_grid(seed))
    with mock.patch.object(MathTextParser, "parse", side_effect=AssertionError("mathtext used")):
        figures.save_png(fig, tmp_path / "psd.png")
    assert (tmp_path / "psd.png").stat().st_size > 1000
    labels = [t.get_text() for t in fig.axes[0].get_yticklabels() if t.get_text()]
    assert labels and all(lab.startswith("10") for lab in labels)


def test_stylus_psd_figure_draws_without_mathtext(tmp_path):
    from matplotlib.mathtext import MathTextParser

    f = np.linspace(0.01, 10.0, 200)
    fig = figures.stylus_psd_figure([{"label": "p1", "f": f, "psd": 1e-9 / f ** 2}])
    with mock.patch.object(MathTextParser, "parse", side_effect=AssertionError("mathtext used")):
        figures.save_png(fig, tmp_path / "s.png")


def test_decade_label():
    assert figures.decade_label(1e-3) == "10⁻³"
    assert figures.decade_label(1.0) == "10⁰"
    assert figures.decade_label(1e12) == "10¹²"
    assert figures.decade_label(3e-3) == ""
    assert figures.decade_label(0.0) == ""


def test_short_log_range_keeps_matplotlib_labels():
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    ax = Figure().add_subplot()
    ax.loglog([2.0, 8.0], [2.0, 8.0])  # no two powers of ten in range: minor labels are needed
    figures.plain_log_ticks(ax.xaxis)
    assert not isinstance(ax.xaxis.get_major_formatter(), FuncFormatter)


def test_psd_image_data_unchanged():
    """What the figure draws is psd_2d's array, as before."""
    from pointspro.core.metrics.profiles import psd_2d

    g = _grid(2)
    fig = figures.psd_figure(g)
    _, _, p = psd_2d(g)
    assert np.array_equal(fig.axes[1].images[0].get_array(), p * 1e12)


_DRAW = """
import hashlib, io, sys
import numpy as np
from pointspro.core import figures
from pointspro.core.maps.grid import MapGrid
if sys.argv[1] == "preload":
    figures.preload()
xs = np.arange(-30.0, 31.0, 1.0)
X, Y = np.meshgrid(xs, xs)
g = MapGrid(xs, xs, 2e-5 * np.sin(X / 7) * np.cos(Y / 5), 1.0)
h = hashlib.sha256()
for fig in (figures.grid_map_figure(g), figures.profiles_figure(g), figures.psd_figure(g),
            figures.before_after(X.ravel(), Y.ravel(), g.z.ravel(), 0.5 * g.z.ravel())):
    buf = io.BytesIO()
    figures.save_png(fig, buf)
    h.update(buf.getvalue())
from matplotlib.lines import Line2D
print(h.hexdigest(), "Properties" in (Line2D.set.__doc__ or ""))
"""


def test_preload_skips_property_docstrings_and_draws_the_same_pixels():
    """A batch process's preload leaves out matplotlib's generated property docstrings (0.3–0.4 s of
    its import); the same four report figures are drawn byte for byte as in a process without it."""
    import subprocess
    import sys

    runs = {how: subprocess.run([sys.executable, "-c", _DRAW, how], capture_output=True, text=True,
                                check=True, encoding="utf-8").stdout.split()
            for how in ("preload", "plain")}
    assert runs["preload"][0] == runs["plain"][0]
    assert runs["preload"][1] == "False" and runs["plain"][1] == "True"
