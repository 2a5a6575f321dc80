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


def histogram_figure(res):
    from ..figures import _figure
    from ..statement import with_uncertainty

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
        ax.hist(placed(res, name), bins=30, color="#7aa6c2", edgecolor="white")
        lo, hi = e["interval95"]
        ax.axvspan(lo, hi, color="#f4c542", alpha=0.25, label="95 % interval")
        ax.axvline(e["value"], color="#1b5e20", lw=2, label="corrected value")
        ax.axvline(e["measured"], color="#b71c1c", lw=1.2, ls="--", label="as measured")
        ax.set_xlabel(f"{name} ({_unit(name)})")
        ax.set_ylabel("samples")
        # stated as report.html and the window state it (core/statement.py: GUM §7.2.6 rounding)
        unit = _unit(name)
        ax.set_title(f"{name}: {with_uncertainty(e['value'], e['U95'], unit, e.get('k') or 2.0, e.get('interval95'))}",
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
