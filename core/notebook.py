"""Rich display in Jupyter: a short HTML summary of a PointCloud, a Result and the installed steps,
with the form-error figure (the report's own figure function, embedded as a PNG).

Only called by a notebook's display hook (``_repr_html_``); matplotlib is imported then.
"""
from __future__ import annotations

import base64
import html
import io

import numpy as np

from .units import format_length

#: above this many points the figure is drawn from an even subsample (the binned image looks the
#: same; a notebook cell should not take seconds)
FIGURE_POINTS = 200_000


def _rows(pairs) -> str:
    return "".join(f"<tr><th style='text-align:left'>{html.escape(str(k))}</th>"
                   f"<td style='text-align:left'>{v}</td></tr>" for k, v in pairs)


def _table(pairs) -> str:
    return f"<table>{_rows(pairs)}</table>"


def _png(fig) -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=72)
    return ("<img style='max-width:32em' src='data:image/png;base64,"
            + base64.b64encode(buf.getvalue()).decode("ascii") + "'/>")


def _subsample(n: int) -> slice:
    return slice(None, None, max(1, -(-n // FIGURE_POINTS)))


def _map_of(cloud):
    """(values mm, what) for the figure and the RMS/PV: the residual, else the heights after a
    least-squares plane (piston and tilt), as the batch's summary does for a map."""
    from .pipeline import remove_piston_tilt

    if "residual" in cloud.channels:
        return cloud["residual"], "residual"
    if cloud.n >= 3:
        return remove_piston_tilt(cloud.x, cloud.y, cloud.z), "heights, piston and tilt removed"
    return None, None


def _extent(cloud) -> str:
    lo, hi = cloud.xyz.min(axis=0), cloud.xyz.max(axis=0)
    return " × ".join(format_length(float(h - lo_)) for lo_, h in zip(lo, hi))


def cloud_html(cloud) -> str:
    """Points, frame, units, channels (with their units when the file said), extent, RMS/PV and the
    map of the residual (or of the heights after piston/tilt)."""
    from .figures import scattered_map

    units = dict(cloud.meta.get("channel_units") or {})
    chans = ", ".join(html.escape(c + (f" [{units[c]}]" if c in units else "")) for c in cloud.channels)
    pairs = [("points", f"{cloud.n:,}"), ("frame", html.escape(cloud.frame)),
             ("units", html.escape(str(cloud.meta.get("units", "mm")))), ("channels", chans)]
    if cloud.meta.get("source"):
        pairs.insert(0, ("source", html.escape(str(cloud.meta["source"]))))
    fig = ""
    if cloud.n:
        pairs.append(("extent x × y × z", _extent(cloud)))
        v, what = _map_of(cloud)
        if v is not None:
            from .metrics.area_weights import weighted_rms
            from .pipeline import area_weights_of

            # over the area, as the summary (docs/conventions.md, Summary figures): a star scan's
            # points crowd its centre; an even sampling and stylus profiles: the points' plain RMS
            w = area_weights_of(cloud)
            pairs.append((f"RMS / PV of the {what}",
                          f"{format_length(weighted_rms(v, w))} / {format_length(float(np.ptp(v)))}"))
            s = _subsample(cloud.n)
            fig = _png(scattered_map(cloud.x[s], cloud.y[s], v[s], title=what.capitalize()))
    return f"<div><b>PointCloud</b>{_table(pairs)}{fig}</div>"


def result_html(result) -> str:
    """The summary (RMS, PV, PVr, slope RMS), each step with its seconds and points, the map."""
    from .figures import scattered_map

    s = result.summary
    pairs = [("input", html.escape(result.input)), ("points in → out", f"{s['points_in']:,} → {s['points_out']:,}")]
    for key, label, unit in (("rms_um", "RMS", "µm"), ("pv_um", "PV", "µm"), ("pvr_um", "PVr", "µm")):
        if s.get(key) is not None:
            pairs.append((label, format_length(s[key] * 1e-3)))
    if s.get("slope_rms_urad") is not None:
        pairs.append(("slope RMS", f"{s['slope_rms_urad']:.3g} µrad"))
    if s.get("figures_of"):
        pairs.append(("figures of", html.escape(s["figures_of"])))
    steps = "".join(f"<tr><td>{i}</td><td>{html.escape(r.id)}</td><td>{r.seconds:.2f} s</td>"
                    f"<td>{r.points_in:,} → {r.points_out:,}</td></tr>"
                    for i, r in enumerate(result.steps, 1))
    steps = f"<table><tr><th>#</th><th>step</th><th>time</th><th>points</th></tr>{steps}</table>"
    fig = ""
    c = result.cloud
    if "residual" in c.channels and c.n:
        sub = _subsample(c.n)
        fig = _png(scattered_map(c.x[sub], c.y[sub], c["residual"][sub],
                                 title="Form error (residual) after all steps"))
    warn = ""
    if result.warnings:
        warn = "<p>library warnings: " + "; ".join(html.escape(w) for w in result.warnings) + "</p>"
    return f"<div><b>Result</b>{_table(pairs)}{steps}{warn}{fig}</div>"


def steps_html(catalog) -> str:
    rows = "".join(f"<tr><td><code>{html.escape(s.id)}</code></td><td>{html.escape(s.title)}</td>"
                   f"<td>{html.escape(', '.join(f.key for f in s.fields))}</td></tr>"
                   for s in catalog.values())
    return f"<table><tr><th>step</th><th>title</th><th>parameters</th></tr>{rows}</table>"
