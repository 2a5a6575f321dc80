"""report.json (README "A tour", the report; units by key suffix: docs/conventions.md "Units") and a readable report.html of one processed input."""
from __future__ import annotations

import html
import json
import math
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from . import __version__


def jsonable(o):
    """Plain JSON types from numpy scalars/arrays, paths, sets; non-finite floats become null."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, set)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return jsonable(o.tolist())
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating, float)):
        f = float(o)
        return f if math.isfinite(f) else None
    if isinstance(o, (np.bool_,)):
        return bool(o)
    if o is None or isinstance(o, (str, int, bool)):
        return o
    return str(o)


#: which figures (PNG files) a batch draws: all of them, only the summary's form-error map, or none
FIGURE_MODES = ("all", "summary", "none")
SUMMARY_FIGURE = "form_error.png"


def skipped_figures(names, mode: str = "all") -> list[str]:
    """The PNG artifacts among ``names`` that figure mode ``mode`` does not draw."""
    if mode not in FIGURE_MODES:
        raise ValueError(f"figures: {mode!r} is not one of {', '.join(FIGURE_MODES)}")
    if mode == "all":
        return []
    return sorted(n for n in names if n.endswith(".png") and (mode == "none" or n != SUMMARY_FIGURE))


def build_report(input_path: str, recipe, result, figures: str = "all", skipped=()) -> dict:
    """report.json's content; with ``figures`` other than "all" it says which figures were not
    drawn (``skipped``) and the steps list only the files written."""
    skipped = set(skipped)
    steps = [r.to_json() for r in result.steps]
    for st in steps:
        st["artifacts"] = [a for a in st["artifacts"] if a not in skipped]
    return jsonable({
        "pointspro": __version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "input": str(input_path),
        "recipe": recipe.to_dict(full=True),
        "input_file": input_description(result.input_cloud),
        "steps": steps,
        "summary": result.summary(),
        "figures": {"mode": figures, "skipped": sorted(skipped)},
    })


#: what the reader found, as the report states it (docs/formats.md): the format, the instrument's
#: unit and pixel, the grid, and how many invalid pixels or rows were dropped on reading
_INPUT_KEYS = ("format", "instrument_format", "instrument_reader", "instrument_unit", "pixel_mm",
               "grid", "channel", "delimiter", "decimal_comma", "header_line", "channel_units",
               "xyz_units_stated", "invalid_dropped", "invalid_columns", "invalid_first_line")


def input_description(cloud) -> dict:
    meta = getattr(cloud, "meta", {}) or {}
    return {k: meta[k] for k in _INPUT_KEYS if k in meta and meta[k] not in (None, {}, [])}


def dumps(report: dict) -> str:
    return json.dumps(jsonable(report), indent=2, allow_nan=False) + "\n"


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;margin:2em auto;max-width:60em;color:#222}
h1{font-size:1.5em} h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:.5em 0} td,th{padding:.2em .8em;border-bottom:1px solid #eee;
text-align:left;vertical-align:top} td.num{text-align:right;font-variant-numeric:tabular-nums}
.warn{color:#a45200} figure{margin:.5em 0} img{max-width:100%} figcaption{color:#777;font-size:.8em} .muted{color:#777} code,pre{background:#f6f6f6;padding:.1em .3em}
"""


def surface_for_people(surf: dict) -> dict:
    """The recipe's surface with the units its numbers are in (docs/conventions.md: lengths in mm):
    the vertex curvature c in mm⁻¹ with its radius, an even asphere's A_n in mm^(1−n) — the report
    read "c 0.000333333" and "A 4 = 7e-13" without a unit."""
    out = dict(surf)
    c = surf.get("c")
    if _is_number(c):
        out["c"] = f"{c:.6g} mm⁻¹" + (f" (R = {1.0 / c:.6g} mm)" if c else " (flat)")
    if _is_number(surf.get("R")):  # the vertex radius, given instead of c
        out["R"] = f"{surf['R']:.6g} mm"
    A = surf.get("A")
    if isinstance(A, dict) and all(_is_number(v) for v in A.values()):
        out["A"] = ", ".join(f"{n}: {v:.6g}{_coefficient_unit(n)}" for n, v in A.items())
    return out


def _coefficient_unit(n) -> str:
    """" mm⁻³" for A_4 (A_n r^n is a length: mm^(1−n)); "" where n is no whole number ≥ 2."""
    try:
        p = 1 - int(n)
    except (TypeError, ValueError):
        return ""
    if p > -1:
        return ""
    from .units import superscript

    return " mm" + superscript(p)


def _fmt_keyed(key, v) -> str:
    """``v`` under report key ``key``: a number with the unit the key names (core.units.format_keyed:
    "797.536 µm" for a pose's dx in mm, "297.595 nm" for robust_sigma_um), anything else as ``_fmt``."""
    from .units import format_keyed, unit_of_key

    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
        if unit_of_key(str(key)):
            return html.escape(format_keyed(str(key), v))
    if (isinstance(v, list) and v and len(v) <= 12 and unit_of_key(str(key))
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
        # a pair or triple of lengths (pixel_mm, centre_mm) as each alone: "[78.125 nm, 78.125 nm]",
        # not "[7.8125e-05, 7.8125e-05]" (a review)
        return "[" + ", ".join(html.escape(format_keyed(str(key), x)) for x in v) + "]"
    return _fmt(v)


def _label(key, v) -> str:
    """A table's key as shown: without its unit suffix where the number beside it says the unit
    ("rms_after 13.335 nm", not "rms_after_um 13.335 nm")."""
    k = str(key)
    if isinstance(v, list) and v and len(v) <= 12 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
        v = v[0]  # a short list of lengths is shown with its unit too (_fmt_keyed)
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
        from .units import KEY_UNITS

        for suffix, _ in KEY_UNITS:
            if k.endswith(suffix) and len(k) > len(suffix):
                return k[: -len(suffix)]
    return k


def _fmt(v) -> str:
    if v is None:  # a value not given or not computed ("diameter None" read as if a value, a review)
        return "—"
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 1_000:
        return f"{v:,}"  # "307,200 points", as the step list writes them
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list) and len(v) > 12:  # the items are escaped by _fmt already
        return f"[{len(v)} values: {', '.join(_item(x) for x in v[:6])}, …]"
    if isinstance(v, list) and v and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        return "[" + ", ".join(_item(x) for x in v) + "]"  # 6 digits, as a number alone (not 17)
    if isinstance(v, (list, dict)):
        return html.escape(json.dumps(v))
    return html.escape(str(v))


def _item(x) -> str:
    """An item of a list: a whole number without separators — rows [447, 801, 2338], not the
    "2,338" that a comma-separated list cannot tell from two numbers."""
    if isinstance(x, int) and not isinstance(x, bool):
        return str(x)
    return _fmt(x)


def _records(v: list) -> str:
    """A list of same-keyed mappings (e.g. Zernike coefficients) as a table of its own. A column of
    lengths (its key names the unit: ``coefficient_nm``) is shown in one unit, the one its largest
    value asks for (core.units.column_unit): "coefficient (µm)" with 50.7318 for a 50731.8 nm
    piston. report.json keeps the key's own unit."""
    from .units import SHOWN_LENGTH_MM, column_unit, unit_of_key

    keys = list(v[0])
    heads, scales = [], []
    for k in keys:
        unit = unit_of_key(str(k))
        if unit in SHOWN_LENGTH_MM:  # a suffixed key (coefficient_nm) or a bare length (dz, u_dz)
            shown = column_unit([r.get(k) * SHOWN_LENGTH_MM[unit] for r in v
                                 if isinstance(r.get(k), (int, float)) and not isinstance(r.get(k), bool)],
                                default=unit)
            heads.append(f"{_label(k, 1.0)} ({shown})")
            scales.append(SHOWN_LENGTH_MM[unit] / SHOWN_LENGTH_MM[shown])
        else:
            heads.append(str(k))
            scales.append(None)

    # a length column is printed with the decimals its largest value's 6 significant digits ask for,
    # so that every row reads in the column's unit: a 0.048 nm coefficient under "coefficient (µm)"
    # beside 50.7318 read "4.78859e-05" (a review); now 0.0000
    decimals = []
    for k, scale in zip(keys, scales):
        vals = [abs(float(r.get(k)) * scale) for r in v if scale is not None
                and isinstance(r.get(k), (int, float)) and not isinstance(r.get(k), bool)
                and math.isfinite(r.get(k))]
        top = max(vals, default=0.0)
        decimals.append(None if not top else int(min(max(5 - math.floor(math.log10(top)), 0), 12)))
    # a value column beside its uncertainty's (coefficient_nm, uncertainty_nm; dz, u_dz): both in the
    # value's unit, each row to the decimal place of its own uncertainty's two significant digits (GUM
    # §7.2.6; "piston −17.698 nm" beside "5.54153 nm" — a review), trailing zeros kept
    from .statement import _decimals

    u_col = {}  # value column → its uncertainty's column
    for i, k in enumerate(map(str, keys)):
        for j, u in enumerate(map(str, keys)):
            if scales[i] is None or scales[j] is None or not (
                    u == f"u_{k}" or ("_" in k and u == "uncertainty_" + k.rsplit("_", 1)[1])):
                continue
            if unit_of_key(u) != unit_of_key(k):
                continue
            # both in the unit the uncertainties ask for: a 50.7 µm piston set "µm" for every
            # coefficient, which then read "-0.000566 ± 0.000019" (a review); in nm "-0.566 ± 0.019"
            unit = unit_of_key(k)
            shown = column_unit([r.get(u) * SHOWN_LENGTH_MM[unit] for r in v
                                 if isinstance(r.get(u), (int, float)) and not isinstance(r.get(u), bool)],
                                default=unit)
            scales[i] = scales[j] = SHOWN_LENGTH_MM[unit] / SHOWN_LENGTH_MM[shown]
            heads[i] = f"{_label(k, 1.0)} ({shown})"
            heads[j] = f"{_label(u, 1.0)} ({shown})"
            u_col[i] = j

    def row_decimals(r):
        """(decimals, trailing zeros kept) of each column in row ``r``."""
        out = [(d, False) for d in decimals]
        for i, j in u_col.items():
            u = r.get(keys[j])
            if isinstance(u, (int, float)) and not isinstance(u, bool) and math.isfinite(u) and u != 0:
                d = min(_decimals(abs(float(u)) * scales[i]), 15)
                out[i] = out[j] = (d, True)
        return out

    def cell(x, scale, dec, keep):
        if scale is not None and isinstance(x, (int, float)) and not isinstance(x, bool):
            if dec is not None and math.isfinite(x):
                t = f"{float(x) * scale:.{dec}f}"
                if not keep:
                    t = t.rstrip("0").rstrip(".") if "." in t else t
                t = _no_minus_zero(t)  # −0.0 reads 0.0
                return "0" if t in ("-0", "") else t
            return _fmt(float(x) * scale)
        return _fmt(x)

    head = "".join(f"<th>{html.escape(h)}</th>" for h in heads)
    body = "".join("<tr>" + "".join(f"<td>{cell(r.get(k), s, d, f)}</td>"
                                    for k, s, (d, f) in zip(keys, scales, row_decimals(r)))
                   + "</tr>" for r in v)
    return f"<table><tr>{head}</tr>{body}</table>"


def _fmt_with_u(key, v, u) -> str:
    """``v`` under report key ``key`` to the decimal place of its standard uncertainty ``u``'s two
    significant digits (GUM §7.2.6), in the unit the value's size asks for: a pose's dz of 12.500028 mm
    with u = 4.2 nm reads "12.5000285 mm" (it read "12.5000 mm", 100 nm steps for a 4 nm u — a review)."""
    from .statement import _decimals
    from .units import SHOWN_LENGTH_MM, length_unit, unit_of_key

    unit = unit_of_key(str(key))
    if unit in SHOWN_LENGTH_MM:
        v_mm, u_mm = float(v) * SHOWN_LENGTH_MM[unit], float(u) * SHOWN_LENGTH_MM[unit]
        scale, shown = length_unit(v_mm if v_mm else u_mm)
        return f"{_no_minus_zero(f'{v_mm / scale:.{min(_decimals(u_mm / scale), 15)}f}')} {shown}"
    text = _no_minus_zero(f"{float(v):.{min(_decimals(float(u)), 15)}f}")
    return text + ("" if not unit else unit if unit in ("°", "″") else f" {unit}")


def _fmt_u(key, u) -> str:
    """A standard uncertainty under report key ``key`` to two significant digits, trailing zeros kept,
    in the unit its size asks for ("5.0 nm", "0.000026°")."""
    return _fmt_with_u(key, u, u)


def _no_minus_zero(text: str) -> str:
    """"-0.00" (a value that rounds to zero) as "0.00"."""
    return text[1:] if text.startswith("-") and not any(c in "123456789" for c in text) else text


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def table_html(d: dict) -> str:
    from .units import format_keyed

    rows = []
    # a bare length key beside the same value under its _mm name (zernike's norm_radius and the pupil's
    # norm_radius_mm) is shown once, as "norm_radius" — it stood twice, once as "norm_radius_mm 438.5 µm"
    same = {str(k) for k, v in d.items() if _is_number(v) and d.get(f"{k}_mm") == v}
    keys = set(map(str, d)) - same
    unc = d.get("uncertainty") if isinstance(d.get("uncertainty"), dict) else {}
    for k, v in d.items():
        if k in ("warnings",) or str(k) in same:
            continue
        if k == "uncertainty" and unc and all(_is_number(x) for x in unc.values()):
            # standard uncertainties to two significant digits, each with its unit
            inner = ", ".join(f"{html.escape(_label(a, b))} = "
                              f"{html.escape(_fmt_u(a, b) if b > 0 else format_keyed(str(a), b, 2))}"
                              for a, b in unc.items())
            rows.append(f"<tr><th>{html.escape(k)}</th><td>{inner}</td></tr>")
            continue
        if _is_number(v) and _is_number(unc.get(k)) and unc.get(k) > 0:
            label = _label(k, v)
            label = str(k) if label != str(k) and label in keys else label
            rows.append(f'<tr><th>{html.escape(label)}</th><td class="num">'
                        f"{html.escape(_fmt_with_u(k, v, unc[k]))}</td></tr>")
            continue
        if (isinstance(v, list) and v and all(isinstance(r, dict) for r in v)
                and all(r.keys() == v[0].keys() for r in v)
                and all(not isinstance(x, (dict, list)) for r in v for x in r.values())):
            rows.append(f"<tr><th>{html.escape(k)}</th><td>{_records(v)}</td></tr>")
            continue
        if isinstance(v, dict) and v and all(not isinstance(x, (dict, list)) for x in v.values()):
            inner = ", ".join(f"{html.escape(_label(a, b))} = {_fmt_keyed(a, b)}" for a, b in v.items())
            rows.append(f"<tr><th>{html.escape(k)}</th><td>{inner}</td></tr>")
        elif isinstance(v, dict):  # nested (a correction's radial program): its own table, units and
            # all, not raw JSON with 16-digit floats (a review); an empty one as a dash
            rows.append(f"<tr><th>{html.escape(k)}</th><td>{table_html(v) if v else '—'}</td></tr>")
        else:
            cls = ' class="num"' if isinstance(v, (int, float)) else ""
            label = _label(k, v)
            label = str(k) if label != str(k) and label in keys else label  # norm_radius beside norm_radius_mm
            rows.append(f"<tr><th>{html.escape(label)}</th><td{cls}>{_fmt_keyed(k, v)}</td></tr>")
    return "<table>" + "".join(rows) + "</table>"


def _img(folder, name: str) -> str:
    """An <img> with the PNG embedded (data URI), so report.html is one self-contained file."""
    import base64

    if folder is None:
        return ""
    p = Path(folder) / name
    if not p.is_file():
        return ""
    data = base64.b64encode(p.read_bytes()).decode("ascii")
    return (f"<figure><img alt='{html.escape(name)}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{html.escape(name)}</figcaption></figure>")


def render_html(report: dict, folder=None) -> str:
    """The report as one HTML page; figures (PNG artifacts in ``folder``) are embedded."""
    s = report.get("summary", {})
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>PointsPro — "
             f"{html.escape(report['input'])}</title><style>{_CSS}</style></head><body>",
             f"<h1>PointsPro report</h1><p class='muted'>PointsPro {html.escape(report['pointspro'])}, "
             f"{html.escape(report.get('created', ''))}</p>",
             "<h2>Input</h2>", table_html({"file": report["input"], "points in": s.get("points_in"),
                                       "points out": s.get("points_out"),
                                       **report.get("input_file", {})})]
    from .statement import figure_rows, verdict_banner_html

    if s.get("tolerance"):  # the verdict against the drawing first: what a quality engineer signs
        parts.insert(2, "<h2>Verdict against the drawing</h2>" + verdict_banner_html(s["tolerance"]))
    # in the unit their size asks for ("547.5 nm"; report.json keeps the µm numbers)
    summary = figure_rows(s)
    if summary:
        what = s.get("figures_of") or "residual"
        pupil = s.get("pupil") or {}
        from .statement import PVR_DEFINITION, pupil_text, weighting_text

        note = (f"<p class='muted'>Figures of the {html.escape(what)}" + html.escape(pupil_text(pupil))
                + (f" — {html.escape(str(pupil.get('centre_from', '')))}" if pupil else "")
                + (html.escape(PVR_DEFINITION) if s.get("pvr_um") is not None else "")
                + html.escape(weighting_text(s)) + ".</p>")
        parts += ["<h2>Form error</h2>", note, table_html(summary), _img(folder, "form_error.png")]
    if s.get("uncertainty"):
        parts += uncertainty_html(s["uncertainty"], folder)
    surf = report.get("recipe", {}).get("surface")
    if surf:
        parts += ["<h2>Nominal surface</h2>", table_html(surface_for_people(surf))]
    fig = report.get("figures") or {}
    if fig.get("skipped"):
        parts.append(f"<p class='muted'>Figures: {html.escape(fig['mode'])} — not drawn: "
                     f"{html.escape(', '.join(fig['skipped']))} (pointspro --batch --figures all draws "
                     "them).</p>")
    parts.append("<h2>Steps</h2>")
    if not report["steps"]:
        parts.append("<p class='muted'>The recipe has no steps: the cloud was read and written.</p>")
    for i, st in enumerate(report["steps"], 1):
        parts.append(f"<h3>{i}. {html.escape(st['title'])} <code>{html.escape(st['id'])}</code></h3>"
                     f"<p class='muted'>{st['seconds']:.3f} s · {st['points_in']} → {st['points_out']} "
                     "points</p>")
        for w in st["report"].get("warnings", []) or []:
            parts.append(f"<p class='warn'>⚠ {html.escape(str(w))}</p>")
        parts.append(table_html(st["report"]))
        for a in st.get("artifacts", []):
            if a.endswith(".png"):
                parts.append(_img(folder, a))
        if st.get("artifacts"):
            links = ", ".join(f"<a href='{html.escape(a)}'>{html.escape(a)}</a>" for a in st["artifacts"])
            parts.append(f"<p>Files: {links}</p>")
    import yaml

    recipe_text = yaml.safe_dump(report.get("recipe"), sort_keys=False, default_flow_style=None)
    parts.append("<h2>Recipe (every parameter, defaults included)</h2><pre>" + html.escape(recipe_text)
                 + "</pre></body></html>\n")
    return "".join(parts)


def uncertainty_html(block: dict, folder=None) -> list[str]:
    """report.html's uncertainty section: how it was obtained, every figure's value ± U95 with its
    95 % interval, and the Monte Carlo histograms (uncertainty.png)."""
    from .statement import _decimals, with_uncertainty
    from .units import unit_of_key

    meta = {k: v for k, v in block.items() if not _is_figure(v)}
    rows = []
    for name, e in block.items():
        if not _is_figure(e):
            continue
        lo, hi = (e.get("interval95") or [None, None])[:2]
        # GUM §7.2.6: u and U95 to two significant digits, the value, the measured value and the
        # interval's ends to the same decimal place — a pose's dz read "12.4998, u 2.50919e-05,
        # interval [12.4997, 12.4998]" (six digits cannot show a 0.1 µm interval)
        dec = min(_decimals(e.get("U95") or 0.0), 12)

        def fixed(v):
            return "—" if v is None else f"{v:.{dec}f}"

        def two(v):  # two significant digits, trailing zeros kept ("0.050", "1.0")
            return "—" if v is None else f"{v:.{min(_decimals(abs(v)), 12)}f}" if v else "0"
        rows.append({"figure": name, "unit": unit_of_key(name), "value": fixed(e.get("value")),
                     "as measured": fixed(e.get("measured")), "bias": two(e.get("bias")),
                     "u": two(e.get("u")), "U95": two(e.get("U95")),
                     "95 % interval": "—" if lo is None else f"[{fixed(lo)}, {fixed(hi)}]"})
    out = ["<h2>Uncertainty (Monte Carlo through the steps, JCGM 101)</h2>",
           "<p class='muted'>Each figure: the value with the noise's bias removed, its standard "
           "uncertainty u, the expanded uncertainty U95 and the 95 % coverage interval of the Monte "
           "Carlo samples about it. What the interval includes and what it does not: "
           "docs/uncertainty.md.</p>"]
    from .uncertainty.artifacts import figure_name

    for name, e in block.items():
        if _is_figure(e) and name in ("rms_um", "pv_um", "pvr_um"):
            out.append(f"<p><b>{html.escape(figure_name(name))}</b>: "
                       f"{html.escape(with_uncertainty(e.get('value'), e.get('U95'), 'µm', e.get('k') or 2.0, e.get('interval95')))}</p>")
    if meta:
        out.append(table_html({k: v for m in meta.values() if isinstance(m, dict) for k, v in m.items()}
                              if len(meta) == 1 and isinstance(next(iter(meta.values())), dict) else meta))
    if rows:
        out.append(_records(rows))
    out.append(_img(folder, "uncertainty.png"))
    return out


def _is_figure(e) -> bool:
    return isinstance(e, dict) and "U95" in e and "value" in e
