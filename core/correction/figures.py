"""The correction's figures (matplotlib object API, drawn only when outputs are written)."""
from __future__ import annotations

import numpy as np

from ..figures import _figure, _map_axes, length_axis
from ..units import format_length


def _thin(xs, ys, Z, most=400):
    k = max(1, int(np.ceil(max(len(xs), len(ys)) / most)))
    return xs[::k], ys[::k], Z[::k, ::k]


def _ext(xs, ys):
    h = (xs[1] - xs[0]) / 2 if len(xs) > 1 else 0.5
    return (xs[0] - h, xs[-1] + h, ys[0] - h, ys[-1] + h)


def correction_figure(cor, rep):
    """The correction (µm, the height to add) and the error predicted after it, side by side."""
    fig = _figure(11, 4.6)
    ax1, ax2 = fig.subplots(1, 2)
    xs, ys, dz = _thin(cor.xs, cor.ys, cor.dz)
    _map_axes(fig, ax1, dz, _ext(xs, ys), "dz",
              f"correction dz (add to program): PV {format_length(rep['correction_pv_um'] * 1e-3, 4)}")
    th = np.linspace(0, 2 * np.pi, 200)
    for a in (ax1, ax2):
        a.plot(cor.center[0] + cor.radius * np.cos(th), cor.center[1] + cor.radius * np.sin(th),
               "k--", lw=0.6)
    xs, ys, p = _thin(cor.xs, cor.ys, cor.predicted)
    _map_axes(fig, ax2, p, _ext(xs, ys), "",
              f"predicted after: RMS {format_length(rep['predicted_rms_um'] * 1e-3)} "
              f"(before {format_length(rep['error_rms_um'] * 1e-3)})")
    return fig


def radial_figure(r, dz, radius, fit=None, fit_label=""):
    fig = _figure(6.4, 4.2)
    ax = fig.add_subplot()
    scale, unit = length_axis(dz)
    ax.plot(r, dz * scale, "-", color="#2c6fbb", label="azimuthal mean of dz")
    if fit is not None:
        ax.plot(r, fit * scale, ":", color="#c0392b", label=fit_label)
    for i, edge in enumerate(np.atleast_1d(radius)):  # an off-axis part: its two edges about the axis
        ax.axvline(edge, color="k", lw=0.6, ls="--", label="clear aperture" if i == 0 else None)
    ax.set_xlabel("r (mm)")
    ax.set_ylabel(f"dz ({unit}, add to program)")
    ax.legend(fontsize=8)
    ax.set_title("radial correction (turning program)", fontsize=10)
    return fig


def history_figure(runs_um, predicted_um=None):
    """RMS form error run by run (µm), with the prediction for the next run."""
    fig = _figure(6.4, 4.2)
    ax = fig.add_subplot()
    n = np.arange(1, len(runs_um) + 1)
    ax.semilogy(n, runs_um, "o-", color="#2c6fbb", label="measured (clear aperture)")
    if predicted_um is not None:
        ax.semilogy([n[-1] + 1], [max(predicted_um, 1e-9)], "s", mfc="none", color="#c0392b",
                    label="predicted after this correction")
    ax.set_xlabel("run")
    ax.set_ylabel("RMS form error (µm)")
    ax.set_xticks(np.arange(1, len(runs_um) + 2))
    ax.legend(fontsize=8)
    ax.set_title("correction loop: form error by run", fontsize=10)
    return fig
