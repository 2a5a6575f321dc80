"""Statements of results for people: a figure with its expanded uncertainty, and the verdict
against the drawing (docs/uncertainty.md, docs/tolerance.md).

    547.5 ± 4.1 nm (k = 2)        (an RMS of 0.5475 µm with U95 = 0.0041 µm)

The expanded uncertainty is rounded to two significant digits and the value to the same decimal
place (GUM, JCGM 100:2008 §7.2.6); the unit is the one the uncertainty's size asks for, so a 44 nm
figure reads "43.9 ± 2.1 nm", never "4.39e-05 mm". Shared by report.html, the window's summary and
the batch's table, so the three say the same thing.
"""
from __future__ import annotations

import html
import math

#: the summary's figures with a readable name and the unit of their key
SUMMARY_FIGURES = (("rms_um", "RMS", "µm"), ("pv_um", "PV", "µm"),
                   ("pvr_um", "PVr (Evans)", "µm"),
                   ("slope_rms_urad", "slope RMS (tilt removed)", "µrad"))

#: what PVr is, said once beside the figures (the table's label was too long for the window's panel)
PVR_DEFINITION = "; PVr (Evans) = PV of the Z1–Z36 Zernike fit + 3·RMS of the rest"

#: verdicts (core.tolerance, ISO 14253-1) and their banner colours
VERDICT_COLOURS = {"conforms": "#1b7f3b", "does not conform": "#b3261e", "undecided": "#a45200"}

_SCALES_UM = ((1e3, "mm"), (1.0, "µm"), (1e-3, "nm"))


def _unit_for(size_um: float) -> tuple[float, str]:
    """(scale in µm, unit) so that ``size_um`` reads between 1 and 1000 — nm below 1 µm, also below
    1 nm ("0.72 nm", as core.units.format_length and docs/conventions.md say; it read "720 pm")."""
    a = abs(size_um)
    for scale, unit in _SCALES_UM:
        if a >= scale:
            return scale, unit
    return 1e-3, "nm"


def _decimals(u: float) -> int:
    """Decimal places that show ``u`` with two significant digits."""
    if not (u > 0 and math.isfinite(u)):
        return 3
    u = float(f"{u:.2g}")  # as rounded: 9.96 is "10", not "10.0" (three digits — a review)
    return max(0, 1 - int(math.floor(math.log10(u))))


def _asymmetric(value: float, U: float, interval, d: int) -> bool:
    """Whether the 95 % interval ``interval`` differs from value ± U by more than half the last digit
    shown (``d`` decimals): a figure near zero (an RMS or PV at the noise: [0, 2U] about a value of 0)
    or a skewed Monte Carlo distribution."""
    if not (isinstance(interval, (list, tuple)) and len(interval) == 2):
        return False
    lo, hi = interval
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (lo, hi)):
        return False
    half = 0.5 * 10.0 ** -d
    return abs(lo - (value - U)) > half or abs(hi - (value + U)) > half


def value_and_uncertainty(value: float, U: float, interval=None, d: int | None = None,
                          unit: str = "", k: float | None = None) -> str:
    """"0.5475 ± 0.0041", or "0.0000 (95 % 0.0000 … 0.0066)" where the 95 % interval is not value ± U
    (a review: an RMS at the noise read "0.0 ± 3.3 nm" for the interval 0 … 6.6 nm — its upper end,
    what a drawing's limit is compared with, is twice that), in the units of its arguments; ``d``
    decimals (default: U to two significant digits, GUM §7.2.6). With ``unit`` (and the coverage
    factor ``k``) the sentence form: "547.5 ± 4.1 nm (k = 2)", "0.0 nm (95 % interval 0.0 … 6.6 nm)"."""
    d = _decimals(U) if d is None else d
    u = f" {unit}" if unit else ""
    if _asymmetric(value, U, interval, d):
        lo, hi = interval
        return f"{value:.{d}f}{u} ({'95 % interval' if unit else '95 %'} {lo:.{d}f} … {hi:.{d}f}{u})"
    return f"{value:.{d}f} ± {U:.{d}f}{u}" + (f" (k = {k:.3g})" if k is not None else "")


def with_uncertainty(value: float | None, U: float | None, unit: str = "µm", k: float = 2.0,
                     interval=None) -> str:
    """"547.5 ± 4.1 nm (k = 2)" for 0.5475 ± 0.0041 µm: a length in µm is shown in the unit its
    value's size asks for; other units as given. "—" for no value. ``interval``: the 95 % interval
    (in the unit of ``value``); where it is not value ± U the statement gives it instead — "0.0 nm
    (95 % interval 0.0 … 6.6 nm)" — since value ± U would understate its upper end."""
    if value is None or not math.isfinite(value):
        return "—"
    if U is None or not math.isfinite(U):
        value = float(f"{value:.4g}")  # the unit of the value as shown: 0.99996 µm is "1 µm"
    scale = 1.0
    if unit == "µm":  # the unit of the larger of the two: "0.46 ± 1.00 µm", not "463 ± 1002 nm"
        scale, unit = _unit_for(max(abs(value), abs(U)) if U is not None and math.isfinite(U) else value
                                if value else (U or 0.0))
        value, U = value / scale, (None if U is None else U / scale)
    elif unit == "µrad":  # a slope of 1.4e4 µrad reads "14.01 mrad" (an interferometer's steep map)
        big = max(abs(value), abs(U)) if U is not None and math.isfinite(U) else abs(value)
        scale, unit = (1e6, "rad") if big >= 1e6 else (1e3, "mrad") if big >= 1e3 else (1.0, "µrad")
        value, U = value / scale, (None if U is None else U / scale)
    if U is None or not math.isfinite(U):
        return f"{_four_digits(value)} {unit}"
    if isinstance(interval, (list, tuple)) and len(interval) == 2 and all(
            isinstance(v, (int, float)) for v in interval):
        interval = (interval[0] / scale, interval[1] / scale)
    return value_and_uncertainty(value, U, interval, unit=unit, k=k)


def _four_digits(v: float) -> str:
    """At most four significant digits ("43.9 nm", "3.978 µm")."""
    return f"{v:.4g}"


#: a summary figure the points cannot give (PVr needs more than 72 points, slope RMS 50 and an area)
NOT_COMPUTED = "not computed on these points"


def figure_rows(summary: dict) -> dict[str, str]:
    """The summary's figures as display strings in the unit their size asks for ("547.5 nm"): with
    ``summary['uncertainty']`` each is the bias-corrected value ± U95 and says the plain pipeline
    figure beside it; {} when the summary has none (no residual), NOT_COMPUTED for one it lacks."""
    if all(summary.get(key) is None for key, _, _ in SUMMARY_FIGURES):
        return {}
    unc = summary.get("uncertainty") or {}
    rows = {}
    for key, name, unit in SUMMARY_FIGURES:
        e = unc.get(key)
        plain = summary.get(key)
        if isinstance(e, dict) and e.get("value") is not None:
            text = with_uncertainty(e["value"], e.get("U95"), unit, e.get("k") or 2.0,  # k None: u = 0
                                    e.get("interval95"))
            if plain is not None and e.get("bias"):
                text += f" (as measured {with_uncertainty(plain, None, unit)}, noise bias removed)"
            rows[name] = text
        elif plain is not None:
            rows[name] = with_uncertainty(plain, None, unit)
        else:
            rows[name] = NOT_COMPUTED
    return rows


def verdict_line(tolerance: dict | None) -> str | None:
    """One line for a terminal or a status bar: the overall verdict and the items that decided it."""
    if not tolerance:
        return None
    if tolerance.get("text"):
        return str(tolerance["text"])
    from .tolerance.decision import summary_text  # a report written before "text" existed

    return summary_text(tolerance.get("verdict", "undecided"), tolerance.get("items") or [])


def verdict_banner_html(tolerance: dict | None) -> str:
    """A coloured banner (green conforms, red does not conform, amber undecided) and the items'
    table, for report.html and the window."""
    if not tolerance:
        return ""
    verdict = tolerance.get("verdict", "undecided")
    colour = VERDICT_COLOURS.get(verdict, "#a45200")
    rule = tolerance.get("rule", "")
    head = (f"<div style='background:{colour};color:white;padding:.5em 1em;font-weight:bold;"
            f"font-size:1.2em'>{html.escape(verdict.upper())}"
            f"<span style='font-weight:normal;font-size:.8em'> — decision rule: "
            f"{html.escape(str(rule))}</span></div>")
    items = tolerance.get("items") or []
    # what the verdicts compare (the 95 % interval's ends: an RMS's is not value ± U95) and why an
    # item is undecided: a reader could not reproduce "undecided" for 0.4642 ± 0.0105 < 0.475 before
    intervals = any(i.get("interval95") for i in items)
    notes = any(i.get("note") for i in items)
    nowrap = "class='num' nowrap style='white-space:nowrap'"  # "0.1548 fr" broke into "0.15 / 48 / fr"
    rows = ["<tr><th>quantity</th><th>value</th><th>U95</th>"
            + ("<th>95 % interval</th>" if intervals else "") + "<th>limit</th><th>verdict</th>"
            + ("<th>note</th>" if notes else "") + "</tr>"]
    for i in items:
        unit = html.escape(str(i.get("unit", "")))
        u = i.get("U95")
        c = VERDICT_COLOURS.get(i.get("verdict"), "#777")
        iv = i.get("interval95")
        # U95 to two significant digits, the value and the interval to the same place (GUM §7.2.6), as
        # the verdict's line (core.tolerance.decision.item_text): the table read "0.5769 ± 0.0117"
        num = _num if u is None or not math.isfinite(u) else (lambda v, d=_decimals(u): _fixed(v, d))
        rows.append(
            f"<tr><td>{html.escape(str(i.get('name')))}</td>"
            f"<td {nowrap}>{num(i.get('value'))} {unit}</td>"
            f"<td {nowrap}>{'—' if u is None else num(u) + ' ' + unit}</td>"
            + (f"<td {nowrap}>{'—' if not iv else f'{num(iv[0])} … {num(iv[1])} {unit}'}</td>" if intervals else "")
            + f"<td {nowrap}>{_limit_text(i.get('limit'))} {unit}</td>"
            f"<td style='color:{c};font-weight:bold'>{html.escape(str(i.get('verdict')))}</td>"
            + (f"<td>{html.escape(str(i.get('note') or ''))}</td>" if notes else "") + "</tr>")
    basis = []
    if tolerance.get("form"):
        basis.append(f"drawing: {html.escape(str(tolerance['form']))}")
    if tolerance.get("wavelength_nm") and any(i.get("unit") == "fr" for i in items):
        basis.append(f"1 fr = λ/2 = {tolerance.get('fringe_um', 0) * 1e3:.4g} nm at λ {tolerance['wavelength_nm']:g} nm")
    if tolerance.get("rule_text"):
        basis.append(html.escape(str(tolerance["rule_text"])))
    foot = f"<p class='muted'>{'; '.join(basis)}</p>" if basis else ""
    return head + "<table>" + "".join(rows) + "</table>" + foot


def _num(v) -> str:
    return "—" if v is None else f"{v:.4g}"


def _fixed(v, d: int) -> str:
    return "—" if v is None else f"{v:.{d}f}"


def _limit_text(v) -> str:
    """A drawing's limit as the verdict's line writes it (core.tolerance.decision._limit: 0.25, not
    0.2500; a limit converted from fringes with its 10 digits)."""
    from .tolerance.decision import _limit

    return "—" if v is None else _limit(float(v))


def weighting_text(summary: dict) -> str:
    """"; RMS and slope RMS over the area (…)" when the summary weighted its points by area (a star or
    spiral scan, core/metrics/area_weights.py); "" on an even sampling, where the points' mean is the
    area's."""
    over = str(summary.get("rms_over") or "")
    if not over.startswith("area"):
        return ""
    return ("; RMS and slope RMS over the area: the points are unevenly spread (a star or spiral scan), "
            "each weighted by the area it stands for")


def pupil_text(pupil: dict | None) -> str:
    """"; PVr's pupil: centre (1.5 mm, -2 mm), radius 650 mm" for the report and the window, each
    length in the unit its size asks for; "" without a pupil; a number the report could not hold
    (non-finite: None in report.json) reads "—"."""
    if not pupil:
        return ""

    from .units import format_length

    def num(v):  # a length in the unit its size asks for: a 20 µm field's pupil is "14.0869 µm"
        return "—" if v is None else format_length(v, 6)

    c = pupil.get("centre_mm") or [None, None]
    radius = pupil.get("norm_radius_mm")
    if isinstance(radius, (int, float)) and radius > 0:  # a centre at rounding's distance from 0 is 0:
        c = [0.0 if isinstance(v, (int, float)) and abs(v) < 1e-9 * radius else v for v in c]  # not "-3.55271e-08 nm"
    return f"; PVr's pupil: centre ({num(c[0])}, {num(c[1])}), radius {num(radius)}"
