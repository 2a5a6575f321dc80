"""Statements of results (core/statement.py): value ± U95 rounded as GUM §7.2.6 asks, in the unit
the size asks for; the verdict banner and line; the batch table's verdict column."""
from pointspro.core.statement import figure_rows, verdict_banner_html, verdict_line, with_uncertainty
from pointspro.core.summary import table


def test_two_significant_digits_of_U_and_the_value_to_the_same_place():
    assert with_uncertainty(0.547503, 0.0041) == "547.5 ± 4.1 nm (k = 2)"
    assert with_uncertainty(4.0267, 0.212) == "4.03 ± 0.21 µm (k = 2)"
    assert with_uncertainty(1234.5, 12.0) == "1.234 ± 0.012 mm (k = 2)"
    assert with_uncertainty(5.908, 0.31, "µrad") == "5.91 ± 0.31 µrad (k = 2)"


def test_a_figure_without_uncertainty_reads_in_its_own_unit():
    assert with_uncertainty(0.0439, None) == "43.9 nm"
    assert with_uncertainty(None, 0.1) == "—"


def test_figure_rows_use_the_corrected_value_and_say_the_measured_one():
    s = {"rms_um": 0.2014, "pv_um": 1.1, "pvr_um": None, "slope_rms_urad": None,
         "uncertainty": {"rms_um": {"value": 0.1951, "measured": 0.2014, "bias": 0.0063, "u": 0.0012,
                                    "U95": 0.0024, "interval95": [0.1927, 0.1975], "k": 2}}}
    rows = figure_rows(s)
    assert rows["RMS"].startswith("195.1 ± 2.4 nm (k = 2)")
    assert "as measured 201.4 nm" in rows["RMS"]
    assert rows["PV"] == "1.1 µm"  # no uncertainty entry: the plain figure


def test_verdict_banner_colours_and_line():
    tol = {"verdict": "does not conform", "rule": "ISO 14253-1 guarded",
           "items": [{"name": "irregularity", "value": 0.62, "U95": 0.05, "limit": 0.5,
                      "unit": "fr", "verdict": "does not conform"},
                     {"name": "RMSi", "value": 0.01, "U95": 0.002, "limit": 0.05, "unit": "fr",
                      "verdict": "conforms"}]}
    html = verdict_banner_html(tol)
    assert "#b3261e" in html and "DOES NOT CONFORM" in html and "irregularity" in html
    assert verdict_line(tol) == "does not conform: irregularity 0.620 ± 0.050 fr > 0.5 fr"  # as decision.item_text
    assert "95 % interval" not in html and "<th>note</th>" not in html  # none given: no empty columns
    full = dict(tol, rule_text="… the 95 % coverage interval …", form="3/2(0.5)", wavelength_nm=546.07,
                fringe_um=0.273035,
                items=[dict(tol["items"][0], interval95=[0.57, 0.70]),
                       dict(tol["items"][1], verdict="undecided", note="the 95 % interval holds the limit")])
    page = verdict_banner_html(full)  # what the verdict compares and why, readable without report.json
    # U95 to two significant digits, the value and the interval to its place (GUM §7.2.6), the
    # drawing's limit as written (the table read 0.62 ± 0.05 and 0.57 … 0.7 beside the line's 0.620)
    assert "<th>95 % interval</th>" in page and "0.570 … 0.700 fr" in page
    assert ">0.620 fr<" in page and ">0.050 fr<" in page and ">0.5 fr<" in page
    assert "the 95 % interval holds the limit" in page and "drawing: 3/2(0.5)" in page
    assert "273 nm at λ 546.07 nm" in page and "coverage interval" in page
    # plain limits in µm: no fringe to define (the banner said "1 fr = λ/2 = 273 nm" beside µm limits)
    plain = dict(tol, wavelength_nm=546.07, fringe_um=0.273035,
                 items=[{"name": "RMS", "value": 0.57693, "U95": 0.01172, "limit": 0.25, "unit": "µm",
                         "verdict": "does not conform", "interval95": [0.56614, 0.58951]}])
    page = verdict_banner_html(plain)
    assert ">0.577 µm<" in page and ">0.012 µm<" in page and "0.566 … 0.590 µm" in page
    assert ">0.25 µm<" in page and "λ" not in page
    assert verdict_banner_html(None) == "" and verdict_line(None) is None
    ok = dict(tol, verdict="conforms")
    assert "#1b7f3b" in verdict_banner_html(ok)


def test_batch_table_gets_a_verdict_column_only_when_a_tolerance_was_asked():
    base = {"input": "a.csv", "status": "done", "points_in": 10, "points_out": 9, "rms_um": 0.5,
            "pv_um": 2.0, "seconds": 1.0}
    plain = table([base])
    assert "verdict" not in plain
    with_v = table([dict(base, verdict="undecided", rms_U95_um=0.004, rms_corrected_um=0.49),
                    dict(base, input="b.csv", status="failed", points_in=None)])
    head, _, first, second = with_v.splitlines()
    assert head.split()[-1] == "verdict"
    assert first.split()[-1] == "undecided" and "0.4900 ± 0.0040" in first
    assert second.split()[-1] == "—"


def test_the_batch_table_says_its_rms_is_corrected_when_it_is_and_the_uncertainty_table_has_units():
    from pointspro.core.summary import table
    from pointspro.core.units import unit_of_key

    plain = {"input": "a.csv", "status": "ok", "points_in": 10, "points_out": 10, "rms_um": 0.0754,
             "pv_um": 0.39, "seconds": 1.0}
    assert "RMS µm  " in table([plain]).splitlines()[0] + "  "
    corrected = plain | {"rms_U95_um": 0.00286, "rms_corrected_um": 0.07298}
    head, _, row = table([corrected]).splitlines()
    assert "RMS µm (corrected ± U95" in head and "0.0730 ± 0.0029" in row
    # an interval that is value ± U95 to the digit shown: the ± form
    row = table([corrected | {"rms_interval95_um": [0.07012, 0.07584]}]).splitlines()[2]
    assert "0.0730 ± 0.0029" in row
    assert [unit_of_key(k) for k in ("rms_um", "slope_rms_urad", "alpha_deg", "Z4_nm", "n")] == \
        ["µm", "µrad", "°", "nm", ""]


def test_a_figure_at_the_noise_states_its_interval_not_value_plus_minus_u():
    """A review: a flat of pure noise read "RMS 0.0 ± 3.3 nm" for the 95 % interval 0 … 6.6 nm — its
    upper end, what a limit is compared with, twice the stated one — and a PV "54 ± 141 nm" (a
    negative PV implied). Where the interval is not value ± U95 to the digit shown, it is given."""
    from pointspro.core.statement import figure_rows, with_uncertainty
    from pointspro.core.summary import table

    assert with_uncertainty(0.0, 0.00332, "µm", 1.47, [0.0, 0.00664]) == "0.0 nm (95 % interval 0.0 … 6.6 nm)"
    assert with_uncertainty(0.054, 0.141, "µm", 2.0, [0.0, 0.31]) == "54 nm (95 % interval 0 … 310 nm)"
    # symmetric to the digit shown: unchanged
    assert with_uncertainty(0.5475, 0.0041, "µm", 2.0, [0.54341, 0.55159]) == "547.5 ± 4.1 nm (k = 2)"
    assert with_uncertainty(0.5475, 0.0041, "µm", 2.0) == "547.5 ± 4.1 nm (k = 2)"
    rows = figure_rows({"rms_um": 0.0199, "pv_um": 0.132, "uncertainty": {
        "rms_um": {"value": 0.0, "U95": 0.00332, "k": 1.47, "interval95": [0.0, 0.00664], "bias": 0.0199}}})
    assert rows["RMS"].startswith("0.0 nm (95 % interval 0.0 … 6.6 nm)")
    e = {"input": "a.csv", "status": "ok", "points_in": 9, "points_out": 9, "rms_um": 0.0199, "pv_um": 0.13,
         "seconds": 1.0, "rms_U95_um": 0.00332, "rms_corrected_um": 0.0, "rms_interval95_um": [0.0, 0.00664]}
    assert "0.0000 (95 % 0.0000 … 0.0066)" in table([e]).splitlines()[2]


def test_the_uncertainty_table_rounds_every_column_to_u95_s_place():
    """GUM §7.2.6: u, U95, bias to two significant digits, value and interval to U95's decimal place
    — a pose's dz read '12.4998, u 2.50919e-05, interval [12.4997, 12.4998]'."""
    from pointspro.core.report import uncertainty_html

    block = {"pose.dz_mm": {"value": 12.49981234, "measured": 12.49981234, "bias": 0.0, "u": 2.50919e-05,
                            "U95": 5.75013e-05, "interval95": [12.4997548, 12.4998698], "k": 2.3}}
    page = "".join(p for p in uncertainty_html(block) if p)
    assert "<td>12.499812</td>" in page and "<td>0.000025</td>" in page and "<td>0.000058</td>" in page
    assert "[12.499755, 12.499870]" in page and "e-05" not in page


def test_a_u95_larger_than_its_value_picks_the_unit_and_keeps_two_digits():
    """'463 ± 1002 nm (k = 1.7)' showed U95 with four digits (the unit was the value's); the unit of
    the larger of the two keeps GUM's two: '0.5 ± 1.0 µm'."""
    from pointspro.core.statement import with_uncertainty

    assert with_uncertainty(0.4629, 1.0016, "µm", 1.7) == "0.5 ± 1.0 µm (k = 1.7)"
    assert with_uncertainty(0.4643, 0.0112, "µm", 2.06) == "464 ± 11 nm (k = 2.06)"


def test_pupil_note_survives_numbers_report_json_cannot_hold():
    """A centre report.json could not hold (non-finite: null there) ended the whole input in
    "writing the outputs: internal error TypeError … please report"; it reads "—" now."""
    from pointspro.core.statement import pupil_text

    assert pupil_text({"centre_mm": [None, 0.0], "norm_radius_mm": None}) == \
        "; PVr's pupil: centre (—, 0 mm), radius —"
    assert pupil_text({"centre_mm": [1.5, -2.0], "norm_radius_mm": 650.0}) == \
        "; PVr's pupil: centre (1.5 mm, -2 mm), radius 650 mm"
    assert pupil_text({"centre_mm": [0.00996094, 0.00996094], "norm_radius_mm": 0.0140869}) == \
        "; PVr's pupil: centre (9.96094 µm, 9.96094 µm), radius 14.0869 µm"  # a 20 µm field
    assert pupil_text(None) == "" and pupil_text({}) == ""


def test_an_aperture_of_any_finite_size_selects_instead_of_overflowing():
    """`aperture: {diameter: 1e300}` ended in "internal error OverflowError … please report"."""
    import numpy as np

    from pointspro.core import PointCloud
    from pointspro.core.step import Context
    from pointspro.plugins.aperture import ApertureStep

    c = PointCloud.from_xyz(np.arange(5.0), np.zeros(5), np.zeros(5))
    r = ApertureStep().run(c, ApertureStep.Params(diameter=1e300), Context())
    assert r.cloud.n == 5


def test_a_figure_with_no_k_still_reads():
    """u = 0 leaves k None (report.json null): report.html failed with 'unsupported format string
    passed to NoneType' and the input failed."""
    summary = {"rms_um": 0.5, "pv_um": None, "pvr_um": None, "slope_rms_urad": None,
               "uncertainty": {"rms_um": {"value": 0.46, "U95": 0.0, "k": None, "bias": 0.04}}}
    assert figure_rows(summary)["RMS"].startswith("460")


def test_a_verdict_line_never_reads_as_a_contradiction():
    """A review: "irregularity B 0.172 µm > 0.172 µm" (value and limit each rounded to 3 digits); the
    limit is shown as written, the value with the digits it takes to stand on its side of it."""
    from pointspro.core.tolerance.decision import item_text

    item = {"name": "irregularity B", "unit": "um", "value": 0.1723069343673833, "limit": 0.17225,
            "verdict": "does not conform"}
    assert item_text(item) == "irregularity B 0.1723 µm > 0.17225 µm"
    assert item_text(item | {"limit": 0.17235, "verdict": "conforms"}) == "irregularity B 0.172 µm ≤ 0.17235 µm"
    assert item_text(item | {"unit": "nm", "value": 172.30693, "limit": 172.25}) == \
        "irregularity B 172.3 nm > 172.25 nm"
    assert item_text(item | {"value": 0.62, "limit": 0.5}) == "irregularity B 0.62 µm > 0.5 µm"
    assert item_text(item | {"value": 0.1234567, "limit": 0.1234566}) == \
        "irregularity B 0.1235 µm > 0.1234566 µm"


def test_a_figure_reads_in_the_unit_of_its_rounded_value_and_never_in_pm():
    """Below 1 nm still nm, as core.units.format_length and docs/conventions.md say ("720 pm" read
    beside "0.72 nm"); the unit chosen for the value as shown ("1000 nm" for 0.99996 µm; a review)."""
    assert with_uncertainty(0.00072, None) == "0.72 nm"
    assert with_uncertainty(0.99996, None) == "1 µm"
    assert with_uncertainty(999.96, None) == "1 mm"
    assert with_uncertainty(0.00099996, None) == "1 nm"
    assert with_uncertainty(999.96, None, "µrad") == "1 mrad"
    assert with_uncertainty(0.00072, 0.0002) == "0.72 ± 0.20 nm (k = 2)"


def test_pupil_centre_at_roundings_distance_from_zero_reads_zero():
    from pointspro.core.statement import pupil_text

    text = pupil_text({"centre_mm": [-3.55271e-14, 1.5], "norm_radius_mm": 10.0})
    assert text == "; PVr's pupil: centre (0 mm, 1.5 mm), radius 10 mm"


def test_an_uncertainty_that_rounds_up_to_a_power_of_ten_keeps_two_digits():
    """u = 9.96 nm read "10.0 nm" (three significant digits; a review): rounded first, it is "10"."""
    assert with_uncertainty(0.12345, 0.00996) == "123 ± 10 nm (k = 2)"
