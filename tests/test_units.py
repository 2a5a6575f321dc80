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


def _colour_bar_label(fig):
    return [ax.get_ylabel() for ax in fig.axes if ax.get_label() == "<colorbar>"]


def test_report_figures_read_in_the_unit_of_their_size():
    """map.png, profiles.png and the binned maps label nm for a 50 nm form error and µm for a 2 µm
    one (issue 17's note: profiles.png read "0.02 µm" on a real 50 nm interferogram); a single spike
    does not decide the unit; the values drawn are the map's, scaled exactly."""
    from pointspro.core.figures import grid_map_figure, length_axis, profiles_figure, scattered_map
    from pointspro.core.maps.grid import MapGrid

    xs = ys = np.linspace(-10.0, 10.0, 81)
    X, Y = np.meshgrid(xs, ys)
    for amp, unit, scale in [(5e-5, "nm", 1e6), (2e-3, "µm", 1e3), (3.0, "mm", 1.0)]:
        z = amp * np.sin(X / 3.0) * np.cos(Y / 4.0)
        grid = MapGrid(xs, ys, z, 0.25)
        assert length_axis(z) == (scale, unit)
        fig = grid_map_figure(grid)
        assert _colour_bar_label(fig) == [unit]
        img = fig.axes[0].get_images()[0].get_array()
        np.testing.assert_allclose(np.asarray(img), z * scale, rtol=1e-15)
        prof = profiles_figure(grid)
        assert [ax.get_ylabel() for ax in prof.axes] == [f"form error ({unit})"] * 2
        assert _colour_bar_label(scattered_map(X.ravel(), Y.ravel(), z.ravel())) == [unit]
    spiky = 5e-5 * np.sin(X / 3.0)
    spiky[40, 40] = 2e-3  # one 2 µm spike in a 50 nm map
    assert length_axis(spiky) == (1e6, "nm")


def test_format_length_rolls_over_to_the_next_unit_when_rounding_reaches_it():
    from pointspro.core.units import format_length

    assert format_length(9.9996e-4) == "1 µm"  # was "1e+03 nm"
    assert format_length(0.99996) == "1 mm"  # was "1e+03 µm"
    assert format_length(-9.9996e-4) == "-1 µm"
    assert format_length(9.99e-4) == "999 nm"
    assert format_length(4.39e-5) == "43.9 nm"
    assert format_length(1300.0) == "1300 mm"


def test_report_keys_read_with_their_unit():
    """A step's table (report.html and the window's Report panel) shows every number with the unit
    its key names: a suffix's, or mm for a bare length (docs/conventions.md, Units) — it printed
    "dx 0.797536", "robust_sigma_um 0.297595", "knot_spacing 86.5599" with no unit."""
    from pointspro.core.report import table_html
    from pointspro.core.units import format_keyed, unit_of_key

    assert unit_of_key("dx") == "mm" and unit_of_key("pose.dz") == "mm" and unit_of_key("rms_um") == "µm"
    assert unit_of_key("removed") == "" and unit_of_key("condition_number") == ""
    assert format_keyed("dx", 0.7975361802253842) == "797.536 µm"
    assert format_keyed("robust_sigma_um", 0.2975945255098518) == "297.595 nm"
    assert format_keyed("knot_spacing", 86.55986824) == "86.5599 mm"
    assert format_keyed("alpha_deg", 0.1682747) == "0.168275°"
    assert format_keyed("normal_correction_rms_urad", 3.869497) == "3.8695 µrad"
    assert format_keyed("removed", 5) == "5" and format_keyed("separation", 9.895604) == "9.8956"
    page = table_html({"dx": 0.7975361802253842, "removed": 5, "side": 1, "normals": "refined",
                       "uncertainty": {"dx": 2.82933e-5, "alpha_deg": 5.335e-4}, "flag": True,
                       "floor_um": float("nan")})
    assert "<td class=\"num\">797.536 µm</td>" in page and "<td class=\"num\">5</td>" in page
    # the unit said once; standard uncertainties to two significant digits (GUM §7.2.6)
    assert "dx = 28 nm" in page and "alpha = 0.00053°" in page
    assert ">True<" in page and ">nan<" in page  # not numbers with a unit
    page = table_html({"rms_after_um": 0.013335, "points": 307200, "centre_mm": [0.35, 0.26]})
    assert "<th>rms_after</th><td class=\"num\">13.335 nm</td>" in page  # not "rms_after_um 13.335 nm"
    assert ">307,200<" in page and "<th>centre</th>" in page  # a short list of lengths: each with its unit
    assert ">[350 µm, 260 µm]<" in table_html({"centre_mm": [0.3500000000000001, 0.26]})  # not 17 digits
    # a 78 nm pixel read "[7.8125e-05, 7.8125e-05]" (a review)
    assert ">[78.125 nm, 78.125 nm]<" in table_html({"pixel_mm": [7.8125e-05, 7.8125e-05]})
    page = table_html({"norm_radius": 0.0140869, "norm_radius_mm": 0.0140869})
    # one length under two keys (zernike's and the pupil's) stands once, never as two rows alike
    assert "<th>norm_radius</th>" in page and "norm_radius_mm" not in page and page.count("14.0869 µm") == 1


def test_slopes_read_in_mrad_when_steep():
    """An interferometer's steep map: slope RMS "1.401e+04 µrad" reads "14.01 mrad"."""
    from pointspro.core.statement import with_uncertainty

    assert with_uncertainty(14010.0, None, "µrad") == "14.01 mrad"
    assert with_uncertainty(5.908, None, "µrad") == "5.908 µrad"
    assert with_uncertainty(1331.0, 12.0, "µrad") == "1.331 ± 0.012 mrad (k = 2)"


def test_uncertainty_table_names_the_pose_units():
    """The report's uncertainty table: a pose's dz in mm (its unit column was empty)."""
    from pointspro.core.report import uncertainty_html

    block = {"pose.dz": {"value": 12.4998, "measured": 12.4998, "bias": 0.0, "u": 4.2e-5, "U95": 8.4e-5,
                         "k": 2.0, "interval95": [12.49972, 12.49988]}}
    page = "".join(p for p in uncertainty_html(block) if p)
    assert "<td>pose.dz</td><td>mm</td>" in page


def test_format_length_of_absurd_sizes_stays_short():
    """`pointspro info` on 1e300 mm coordinates printed a span of 298 digits of metres."""
    from pointspro.core.units import format_length

    assert format_length(1e300) == "1e+297 m" and format_length(2.5e7) == "25000 m"
    assert format_length(1300.0) == "1300 mm"


def test_a_column_of_lengths_reads_in_the_unit_of_its_largest_value():
    """A column of lengths reads in the unit of its largest value ("50.7318" under "coefficient (µm)",
    not 50731.8 nm) — or, beside its uncertainty, in the uncertainties' unit; a column of a few nm
    stays in nm; report.json keeps coefficient_nm."""
    from pointspro.core.report import table_html
    from pointspro.core.units import column_unit

    rows = [{"j": 1, "name": "piston", "coefficient_nm": 50731.8, "uncertainty_nm": 5.5},
            {"j": 2, "name": "tilt x", "coefficient_nm": -12.3456789, "uncertainty_nm": 0.25}]
    page = table_html({"coefficients": rows})
    # beside an uncertainty, value and uncertainty in the unit the uncertainties ask for (a 50.7 µm
    # piston set µm for every coefficient: "-0.000566 ± 0.000019" — a review), each row to the decimal
    # place of its uncertainty's two significant digits, trailing zeros kept (GUM §7.2.6)
    assert "<th>coefficient (nm)</th>" in page and "<th>uncertainty (nm)</th>" in page
    assert "<td>50731.8</td><td>5.5</td>" in page and "<td>-12.35</td><td>0.25</td>" in page
    tiny = table_html({"coefficients": [*rows, {"j": 3, "name": "tilt y", "coefficient_nm": 0.0478859,
                                                 "uncertainty_nm": 0.1}]})
    assert "e-0" not in tiny and "<td>0.05</td><td>0.10</td>" in tiny  # not 4.78859e-05
    # a column without uncertainties: the unit of its largest value (50731.8 nm reads 50.7318 µm)
    big = table_html({"coefficients": [{"j": 1, "coefficient_nm": 50731.8}, {"j": 2, "coefficient_nm": -12.3}]})
    assert "<th>coefficient (µm)</th>" in big and "<td>50.7318</td>" in big
    small = table_html({"coefficients": [{"j": 4, "coefficient_nm": 3.2}, {"j": 5, "coefficient_nm": -0.4}]})
    assert "<th>coefficient (nm)</th>" in small and "<td>3.2</td>" in small
    assert column_unit([0.0, float("nan")], default="nm") == "nm"
    assert column_unit([2e-3, 5e-7]) == "µm" and column_unit([1500.0]) == "mm"


def test_the_uncertainty_of_a_bare_length_is_a_length():
    """``u_dz`` beside ``dz`` in a stylus profile's table read "1.58193e-06" with no unit (a review)."""
    from pointspro.core.units import format_keyed, unit_of_key

    assert unit_of_key("u_dz") == "mm" and unit_of_key("pose.u_dx") == "mm"
    assert format_keyed("u_dz", 1.58193e-06) == "1.58193 nm"
    assert unit_of_key("u_count") == ""


def test_a_reports_table_shows_bare_lengths_in_a_unit():
    """A stylus profile's per-profile table: ``dz`` and ``u_dz`` (mm) under "dz (nm)", not raw
    "4.9975e-08" beside a "decentre (nm)" column (a review)."""
    from pointspro.core.report import _records

    html = _records([{"label": "a", "dz": 4.9975e-08, "u_dz": 1.58193e-6},
                     {"label": "b", "dz": -2e-7, "u_dz": 1.6e-6}])
    assert "<th>dz (nm)</th>" in html and "<th>u_dz (nm)</th>" in html
    assert "<td>1.6</td>" in html and "e-0" not in html  # u to two significant digits (GUM)
    assert "<td>0.0</td>" in html and "<td>-0.2</td>" in html  # dz to u's decimal place, −0.0 as 0.0


def test_a_step_tables_values_are_given_to_their_uncertaintys_decimal_place():
    """A pose's dz of 12.500028 mm with u = 4.2 nm read "12.5000 mm" (100 nm steps), a Zernike piston
    "−17.698 nm" beside an uncertainty of "5.54153 nm" (a review): GUM §7.2.6, u to two significant
    digits and the value to the same decimal place."""
    from pointspro.core.report import _records, table_html

    html = table_html({"alpha_deg": 0.17000067958, "dz": 12.500028525132285,
                       "uncertainty": {"alpha_deg": 2.62e-05, "dz": 4.1861e-06}, "iterations": 2})
    assert "12.5000285 mm" in html and "0.170001°" in html
    assert "dz = 4.2 nm" in html and "alpha = 0.000026°" in html
    # each row to its own uncertainty's decimal place (one setting per column gave "341.6963" beside
    # "48.3000" — a review)
    rec = _records([{"j": 1, "coefficient_nm": -17.698123, "uncertainty_nm": 5.54153},
                    {"j": 2, "coefficient_nm": 341.69625, "uncertainty_nm": 0.3259},
                    {"j": 3, "coefficient_nm": -12.3456, "uncertainty_nm": 51.7}])
    assert "<td>-17.7</td><td>5.5</td>" in rec and "<td>341.70</td><td>0.33</td>" in rec
    assert "<td>-12</td><td>52</td>" in rec
    # a value that rounds to zero reads 0.0, not −0.0; u keeps its two digits ("5.0 nm", not "5 nm")
    html = table_html({"dz": -1e-9, "uncertainty": {"dz": 5e-6}})
    assert ">0.0 nm<" in html and "dz = 5.0 nm" in html


def test_a_flat_maps_figures_read_in_nm_without_warnings():
    """An all-zero height map: its colour bar read ±1e-12 mm and the PSD figure warned "Data has no
    positive values, and therefore cannot be log-scaled" in the batch's output (a review)."""
    import warnings

    from pointspro.core.figures import grid_map_figure, psd_figure
    from pointspro.core.maps.grid import MapGrid
    from pointspro.core.units import display_unit

    g = np.arange(-5.0, 5.01, 0.5)
    grid = MapGrid(g, g, np.zeros((g.size, g.size)), 0.5)
    assert display_unit(grid.z) == "nm"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        psd_figure(grid)
        mfig = grid_map_figure(grid)
    cbar = mfig.axes[-1]
    assert cbar.get_ylabel() == "nm" and cbar.get_ylim() == (-1.0, 1.0)


def test_a_reports_nested_tables_and_zeros_keep_their_units():
    """A correction's removal read "min_depth = 0 mm, bias = 0 mm" (µm keys), its radial program raw
    JSON with 16-digit floats, its empty `skipped` "{}" (a review of the window)."""
    from pointspro.core.report import table_html

    html = table_html({"removal": {"min_depth_um": 0.0, "bias_um": -0.0, "max_depth_um": 0.3457},
                       "radial": {"non_symmetric_rms_um": 0.5270702927522589, "r_range_mm": [0.0, 25.0]},
                       "skipped": {}})
    assert "min_depth = 0 µm, bias = 0 µm, max_depth = 345.7 nm" in html
    assert "527.07 nm" in html and "0.5270702927522589" not in html
    assert "<th>skipped</th><td>—</td>" in html


def test_a_csv_rasters_map_has_no_empty_stripes():
    """A 0.5 mm x, y, z raster read from CSV (no reader's pixel_mm) was binned 85 across its 40 mm:
    500 empty bins inside it, white stripes in the window's map and the report's figures (a review).
    Its pitch from its coordinates caps the bins; scattered points are binned as before."""
    from pointspro.core.figures import binned_image, default_bins, raster_pitch

    g = np.arange(-20, 20.001, 0.5)
    X, Y = np.meshgrid(g, g)
    keep = np.hypot(X, Y) <= 20
    x, y = X[keep], Y[keep]
    bins = default_bins(x.size, np.ptp(x), raster_pitch(x, y))
    img, _, _ = binned_image(x, y, np.ones_like(x), bins=bins)
    c = np.linspace(-20, 20, bins)
    inside = np.hypot(*np.meshgrid(c, c)) < 18
    assert not np.isnan(img[inside]).any()
    rng = np.random.default_rng(0)
    xs, ys = rng.uniform(-20, 20, 5000), rng.uniform(-20, 20, 5000)
    assert default_bins(5000, 40.0, raster_pitch(xs, ys)) == default_bins(5000)
