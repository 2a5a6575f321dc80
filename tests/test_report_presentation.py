"""What report.html and the report's figures show people (an independent review of the example and of
real instrument files): units that follow the values, one number for one figure, no key names."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core.figures import zernike_bars
from pointspro.core.report import surface_for_people, table_html
from pointspro.core.units import format_length


def _bars(fig):
    ax = fig.axes[0]
    return ax, np.array([p.get_height() for p in ax.patches])


def test_zernike_bars_take_the_unit_and_the_scale_of_the_kept_terms():
    """A MetroPro map's removed 50.7 µm piston set the axis to 50,000 nm and hid 15 nm of power; a
    1.16 mm piston was drawn as "1e6" nm."""
    labels = ["F1", "F2", "F3", "F4"]
    coef_nm = [50_700.0, 80.0, 3.5, -15.0]  # piston, tilts removed; power kept
    ax, h = _bars(zernike_bars(labels, coef_nm, removed=["F1", "F2", "F3"]))
    assert ax.get_ylabel() == "coefficient (nm)"
    lo, hi = ax.get_ylim()
    assert hi == pytest.approx(1.15 * 15.0) and lo == pytest.approx(-1.15 * 15.0)
    assert h[3] == pytest.approx(-15.0) and h[2] == pytest.approx(3.5)  # inside the axis: as they are
    assert h[0] == pytest.approx(hi) and h[1] == pytest.approx(hi)  # cut at its end …
    texts = {t.get_text() for t in ax.texts}
    assert {format_length(50_700e-6), format_length(80e-6)} <= texts  # … with their values written
    # nothing removed: every bar as it is, in the unit of the largest (1.16 mm)
    ax, h = _bars(zernike_bars(labels, [1.16e6, -5.3e4, 0.0, -1.6e5], removed=[]))
    assert ax.get_ylabel() == "coefficient (mm)" and h[0] == pytest.approx(1.16) and not ax.texts
    # kept terms of 160 µm: µm, not 1.6e5 nm; the removed 1.16 mm piston cut, its value written
    ax, h = _bars(zernike_bars(labels, [1.16e6, -5.3e4, 0.0, -1.6e5], removed=["F1", "F2", "F3"],
                               normalization="rms"))
    assert ax.get_ylabel() == "coefficient (µm RMS)" and h[3] == pytest.approx(-160.0)
    assert [t.get_text() for t in ax.texts] == [format_length(1.16)]
    # the kept terms all zero: the removed ones set the unit and nothing is cut (it read "mm", 0.05)
    ax, h = _bars(zernike_bars(labels, [50_700.0, 80.0, 0.0, 0.0], removed=["F1", "F2", "F3"]))
    assert ax.get_ylabel() == "coefficient (µm)" and h[0] == pytest.approx(50.7) and not ax.texts
    ax, h = _bars(zernike_bars(labels, [0.0, 0.0, 0.0, 0.0]))
    assert ax.get_ylabel() == "coefficient (nm)"


def test_misalignment_figure_states_the_reports_residual_rms(monkeypatch):
    """The after panel's title said 953.6 nm (about the mean) beside the report's 953.7 nm (about
    zero: a held dz's piston counts): one figure, one number."""
    import pointspro.core.figures as figures
    from pointspro.core.cloud import PointCloud
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import parse_recipe

    rng = np.random.default_rng(4)
    x, y = rng.uniform(-20, 20, (2, 3000))
    c = 1 / 200.0
    z = c * (x**2 + y**2) / (1 + np.sqrt(1 - c**2 * (x**2 + y**2)))
    z = z + 0.002 + 3e-4 * np.sin(x / 3) + rng.normal(0, 5e-5, x.size)  # a piston the held dz leaves
    cloud = PointCloud.from_xyz(x, y, z)
    recipe = parse_recipe({"pointspro": 1, "surface": {"type": "even_asphere", "c": c, "k": 0.0},
                           "steps": [{"misalignment": {"dof": ["alpha", "beta", "dx", "dy"]}}]})
    res = run_pipeline(cloud, recipe)
    rep = res.steps[0].report
    drawn = []
    monkeypatch.setattr(figures, "save_png", lambda fig, path: drawn.append(fig))
    res.steps[0].artifacts["misalignment.png"](None)
    after = drawn[0].axes[1].get_title()  # axes: before, after (then their colour bars)
    assert after.endswith(f"RMS {format_length(rep['residual_rms_um'] * 1e-3, 4)}")


def test_a_length_given_bare_and_in_mm_stands_once():
    page = table_html({"norm_radius": 0.438532, "norm_radius_mm": 0.438532, "terms": 4})
    assert page.count("438.532 µm") == 1 and "norm_radius_mm" not in page and "<th>norm_radius</th>" in page
    different = table_html({"norm_radius": 0.438532, "norm_radius_mm": 0.5})
    assert "438.532 µm" in different and "500 µm" in different  # not the same number: both


def test_the_nominal_surface_states_its_units():
    shown = surface_for_people({"type": "even_asphere", "c": 1 / 3000.0, "k": -0.98,
                                "A": {"4": 7e-13, "6": 1e-19}, "aperture": 1300})
    assert shown["c"] == "0.000333333 mm⁻¹ (R = 3000 mm)"
    assert shown["A"] == "4: 7e-13 mm⁻³, 6: 1e-19 mm⁻⁵"
    assert shown["k"] == -0.98 and shown["aperture"] == 1300
    assert surface_for_people({"type": "plane", "c": 0.0})["c"] == "0 mm⁻¹ (flat)"
    assert surface_for_people({"type": "even_asphere", "R": 100.0})["R"] == "100 mm"  # given as R


def test_counts_have_separators_and_rows_in_a_list_do_not():
    """"points in 4680" beside "4,680" in the window; but a list of rows keeps its numbers whole —
    [447, 2,338] cannot be told from three numbers."""
    page = table_html({"points": 4680, "rows": [447, 2338, 4073], "small": 999})
    assert ">4,680<" in page and "[447, 2338, 4073]" in page and ">999<" in page
