"""uncertainty.png (a histogram per summary figure) and uncertainty_samples.csv (one row per sample)."""
from __future__ import annotations

import math

import numpy as np

HISTOGRAM_FIGURES = ("rms_um", "pv_um", "pvr_um", "slope_rms_urad")
def _unit(name: str) -> str:
    from ..units import unit_of_key

    return unit_of_key(name)


def placed(res, name: str) -> np.ndarray:
    """The samples placed about the corrected value, as the interval is built (core.uncertainty.estimate)."""
    return res.entries[name]["_placed"]


def figure_name(name: str) -> str:
    """A Monte Carlo figure's name for people: the summary's ("RMS", "PVr (Evans)"), else its key
    without the unit suffix ("rms_after_um" → "rms_after")."""
    from ..report import _label
    from ..statement import SUMMARY_FIGURES

    return next((shown for key, shown, _ in SUMMARY_FIGURES if key == name), None) or _label(name, 0.0)


def histogram_figure(res):
    from matplotlib.ticker import MaxNLocator

    from ..figures import _figure
    from ..statement import _unit_for, with_uncertainty

    names = [n for n in HISTOGRAM_FIGURES if n in res.names]
    names += [n for n in res.names if n not in names and n not in ("pvr_fit_pv_um", "pvr_rest_rms_um")
              and "zernike." not in n and "pose." not in n]
    cols = min(len(names), 3) or 1
    rows = max(1, math.ceil(len(names) / cols))
    fig = _figure(4.2 * cols, 3.3 * rows)
    fig.subplots_adjust(hspace=0.55, wspace=0.3)
    for k, name in enumerate(names):
        ax = fig.add_subplot(rows, cols, k + 1)
        e = res.entries[name]
        unit = _unit(name)
        # a length's axis in the unit of its title (core.statement.with_uncertainty: that of the larger
        # of the value and U95): "rms_um (µm)" ran 0.566 … 0.590 under a title of "577 nm"
        scale, shown = 1.0, unit
        if unit == "µm":
            size_um, shown = _unit_for(max(abs(e["value"]), abs(e.get("U95") or 0.0)))
            scale = 1.0 / size_um
        ax.hist(placed(res, name) * scale, bins=30, color="#7aa6c2", edgecolor="white")
        lo, hi = e["interval95"]
        ax.axvspan(lo * scale, hi * scale, color="#f4c542", alpha=0.25, label="95 % interval")
        ax.axvline(e["value"] * scale, color="#1b5e20", lw=2, label="corrected value")
        ax.axvline(e["measured"] * scale, color="#b71c1c", lw=1.2, ls="--", label="as measured")
        ax.set_xlabel(f"{figure_name(name)} ({shown})" if shown else figure_name(name))
        ax.set_ylabel("samples")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts: no 2.5 samples
        # stated as report.html and the window state it (core/statement.py: GUM §7.2.6 rounding)
        ax.set_title(f"{figure_name(name)}: "
                     f"{with_uncertainty(e['value'], e['U95'], unit, e.get('k') or 2.0, e.get('interval95'))}",
                     fontsize=9)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
    return fig


def histogram_writer(res):
    from ..figures import png_artifact

    return png_artifact(histogram_figure, res)


def samples_csv(res) -> str:
    """One row per sample: every figure (unit in its name) and each type-B draw in its unit."""
    heads = ["sample"] + list(res.names)
    draw_cols = []
    for s in res.sources:
        if s.name == "probe_radius":
            draw_cols.append(("probe_radius_shift_um", s.u * 1e3))
        elif s.name == "temperature":
            draw_cols.append(("temperature_dT_K", s.u))
        else:
            draw_cols.append((f"{s.name}_ppm", s.u * 1e6))
    heads += [c for c, _ in draw_cols]
    lines = ["# PointsPro Monte Carlo samples (docs/uncertainty.md): figures as the pipeline computes "
             "them on each sample, before any bias correction; units in the column names "
             "(_um µm, _nm nm, _urad µrad, _deg degrees, _mm mm, _ppm 1e-6, _K kelvin); empty: the sample failed",
             ",".join(heads)]
    for i in range(res.samples.shape[0]):
        row = [str(i)] + ["" if not np.isfinite(v) else repr(float(v)) for v in res.samples[i]]
        row += [repr(float(res.draws[i, j] * scale)) for j, (_, scale) in enumerate(draw_cols)]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"
