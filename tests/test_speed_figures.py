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


def test_short_log_range_labels_matplotlibs_ticks_in_plain_text(tmp_path):
    """Less than two decades in range: labels between decades are needed. They stand at the ticks
    matplotlib labels, in plain text ("0.06", not mathtext "6×10⁻²" — wider: the PSD's axis title
    of a 7 × 4-pixel map was pushed off the figure)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.mathtext import MathTextParser

    def drawn(plain: bool):
        fig = Figure()
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        ax.loglog([1.0, 2.0], [0.015, 0.3])
        if plain:
            figures.plain_log_ticks(ax.xaxis)
            figures.plain_log_ticks(ax.yaxis)
            with mock.patch.object(MathTextParser, "parse", side_effect=AssertionError("mathtext used")):
                figures.save_png(fig, tmp_path / "short.png")
        else:
            fig.canvas.draw()
        return {round(t.get_loc(), 12): t.label1.get_text()
                for t in [*ax.yaxis.get_major_ticks(), *ax.yaxis.get_minor_ticks()] if t.label1.get_text()}

    mpl, plain = drawn(False), drawn(True)
    assert mpl.keys() == plain.keys() and len(plain) >= 4  # the same ticks labelled
    assert all(t.startswith("$") for t in mpl.values())  # matplotlib's: mathtext
    assert plain[0.1] == "0.1" and plain[0.02] == "0.02"
    assert not any("$" in t for t in plain.values())


def test_short_log_label():
    assert figures.short_log_label(0.06) == "0.06" and figures.short_log_label(300.0) == "300"
    assert figures.short_log_label(3e-5) == "3×10⁻⁵" and figures.short_log_label(2e6) == "2×10⁶"
    assert figures.short_log_label(9.999e-6) == "1×10⁻⁵" and figures.short_log_label(0.0) == ""


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
print(h.hexdigest(), "Properties" in (Line2D.set.__doc__ or ""), "matplotlib.pyplot" in sys.modules)
"""


def test_preload_skips_property_docstrings_and_draws_the_same_pixels():
    """A batch process's preload leaves out matplotlib's generated property docstrings (0.3–0.4 s of
    its import) and does not import pyplot (0.11 s); the same four report figures are drawn byte for
    byte as in a process without it."""
    import subprocess
    import sys

    runs = {how: subprocess.run([sys.executable, "-c", _DRAW, how], capture_output=True, text=True,
                                check=True, encoding="utf-8").stdout.split()
            for how in ("preload", "plain")}
    assert runs["preload"][0] == runs["plain"][0]
    assert runs["preload"][1] == "False" and runs["plain"][1] == "True"
    assert runs["preload"][2] == "False"  # reading the style's colours must not resolve the backend
