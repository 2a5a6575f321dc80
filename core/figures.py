"""The figures of reports and of the window: matplotlib's object API (no pyplot, no global state).

Each function returns a ``matplotlib.figure.Figure``; ``save_png`` renders it with the Agg canvas
(batch, reports) and the window embeds the same Figure in a Qt canvas. Form errors are shown on a
diverging colour map centred on zero, limits at the 0.5 / 99.5 percentiles so one spike does not
wash the map out (the colour bar says when values are clipped), in the unit their size asks for
(``length_axis``: a 50 nm map reads in nm, a 2 µm one in µm — by the window's rule, core.units).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .units import format_length, superscript

DIVERGING = "RdBu_r"


def _figure(w=6.4, h=4.8):
    """Fixed margins, not constrained layout: the layout engine draws every figure twice and took
    40 % of a batch input's time (bench_batch)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), dpi=100)
    fig.subplots_adjust(left=0.75 / w, right=1 - 0.35 / w, bottom=0.55 / h, top=1 - 0.4 / h,
                        wspace=0.35)
    return fig


def _skip_property_docstrings() -> None:
    """matplotlib writes a table of every settable property into the docstring of each Artist
    subclass's ``set`` as the class is defined (``matplotlib.artist.kwdoc``): 0.3–0.4 s of its
    0.8–0.9 s import here, for text only ``help()`` shows. A batch process draws figures and never
    reads them, so ``preload`` has kwdoc return an empty table before the artist classes are defined
    (issue 17). Signatures, behaviour and the drawn pixels are unchanged (tests/test_speed_figures.py
    compares the PNG bytes with and without); the window and notebooks import matplotlib untouched."""
    import sys

    if "matplotlib.figure" in sys.modules:  # the classes exist already: nothing to save
        return
    import matplotlib.artist as artist

    if callable(getattr(artist, "kwdoc", None)):
        artist.kwdoc = lambda _artist: ""


def _resolve_cycle_colours() -> None:
    """Write matplotlib's style entries that name a colour of the property cycle ("C0": a patch's
    face, hence every spine's) as the colour itself. matplotlib resolves "Cn" anew each time (it
    cannot cache it: the cycle may change), walking the whole cycle — 1.3 ms, 119 times for a
    50,000-point input's 7 figures (0.16 s of 1.1 s). A batch process never changes the cycle: the
    same colours, the same pixels (tests/test_speed_figures.py); the window's matplotlib is left as is."""
    import re

    import matplotlib
    from matplotlib.colors import to_hex

    rc = matplotlib.rcParams
    # the stored values (dict's own items): RcParams' items() reads "backend" too, whose automatic
    # value imports pyplot to resolve it (0.11 s of a batch process's start)
    for key in [k for k, v in dict.items(rc) if isinstance(v, str) and re.fullmatch(r"C\d+", v)]:
        rc[key] = to_hex(rc[key], keep_alpha=True)


def preload() -> None:
    """Import matplotlib's figure and Agg canvas and draw one small figure (fonts, colour maps): a
    process about to fork figure workers pays this once for all of them (~1 s of imports each
    otherwise; core/batch.py), a pool worker as it starts. Only batch processes call it: it skips
    matplotlib's property docstrings (``_skip_property_docstrings``) and resolves the style's "Cn"
    colours once (``_resolve_cycle_colours``)."""
    import io

    _skip_property_docstrings()
    _resolve_cycle_colours()

    fig = _figure(2.0, 2.0)
    ax = fig.add_subplot()
    fig.colorbar(ax.imshow([[0.0, 1.0]], cmap=DIVERGING), ax=ax, label="nm")
    ax.set_title("x")
    save_png(fig, io.BytesIO())


#: zlib level of the report PNGs. Level 1 instead of Pillow's default 6: a 1100 × 460 map encodes
#: in 0.025 s instead of 0.053 s (an eighth of drawing it) and the files are ~8 % larger (8 report
#: figures of a 50,000-point input: 1144 → 1231 KiB); PNG is lossless, the pixels are the same.
PNG_COMPRESS_LEVEL = 1


def save_png(fig, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.savefig(path, format="png", dpi=100, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})




def decade_label(v, _pos=None) -> str:
    """'10⁻²' at a power of ten, '' elsewhere: plain text (matplotlib's default log labels are
    mathtext, whose parser took 1.6 s of the PSD figure; issue 17)."""
    if not v > 0:
        return ""
    e = np.log10(v)
    k = int(round(e))
    return "10" + superscript(k) if abs(e - k) < 1e-9 else ""


def short_log_label(v) -> str:
    """A log axis's label between decades in plain text: "0.06", "300", "3×10⁻⁵" (not matplotlib's
    mathtext "6×10⁻²", which is wider — it pushed a PSD's axis title off the figure — and slower)."""
    if not (v > 0 and np.isfinite(v)):
        return ""
    if 1e-3 <= v < 1e4:
        return f"{v:.3g}"
    k = int(np.floor(np.log10(v)))
    m = v / 10.0 ** k
    if round(m, 2) >= 10:
        m, k = m / 10, k + 1
    return f"{m:.3g}×10" + superscript(k)


def _plain_text_formatter(inner):
    """A tick formatter that labels the ticks ``inner`` (matplotlib's log formatter) labels — its
    choice of which minor ticks need a label on a short range — in plain text (short_log_label)."""
    from matplotlib.ticker import Formatter

    class PlainLogLabels(Formatter):
        def set_axis(self, axis):
            super().set_axis(axis)
            inner.set_axis(axis)

        def format_ticks(self, values):
            return [short_log_label(v) if text else "" for v, text in zip(values, inner.format_ticks(values))]

        def __call__(self, x, pos=None):
            return self.format_ticks([x])[0]

    return PlainLogLabels()


def plain_log_ticks(axis) -> None:
    """Label a log axis in plain text, never mathtext: its decades ("10⁻²", ``decade_label``) and
    no minor tick when two powers of ten or more lie in its range; a shorter range needs labels
    between decades — those matplotlib would label, written by ``short_log_label``."""
    from matplotlib.ticker import FuncFormatter, NullFormatter

    lo, hi = sorted(axis.get_view_interval())
    if not (lo > 0 and np.floor(np.log10(hi) + 1e-9) - np.ceil(np.log10(lo) - 1e-9) >= 1):
        axis.set_major_formatter(_plain_text_formatter(axis.get_major_formatter()))
        axis.set_minor_formatter(_plain_text_formatter(axis.get_minor_formatter()))
        return
    axis.set_major_formatter(FuncFormatter(decade_label))
    axis.set_minor_formatter(NullFormatter())


def png_artifact(make, *args, **kwargs):
    """An artifact writer (core.step.Artifact) that draws the figure only when outputs are written."""
    def write(path: Path) -> None:
        save_png(make(*args, **kwargs), path)
    return write


def limits_sample(v, keep=None) -> np.ndarray:
    """The values a map's colour limits are taken from: the points' own values (not the binned
    image's means, not the 3D view's level of detail), less the hidden ones (``keep``), every k-th of
    more than 2 × UNIT_SAMPLE (core.units, the unit's sample too). The report's form_error.png and the
    window's map and 3D view take their limits from it, so one residual gets one colour range
    everywhere (they differed by 5 %: ±1.70, ±1.76, ±1.67 µm)."""
    from .units import UNIT_SAMPLE

    v = np.asarray(v, dtype=np.float64).ravel()
    if keep is not None:
        v = v[np.asarray(keep, dtype=bool)]
    return v[:: v.size // UNIT_SAMPLE] if v.size > 2 * UNIT_SAMPLE else v


def colour_extend(v, lo: float, hi: float) -> str:
    """A colour bar's ``extend``: which ends the finite values ``v`` go beyond (the report's maps and
    the window's map say it alike)."""
    v = np.asarray(v, dtype=np.float64)
    v = v[np.isfinite(v)]
    if not v.size:
        return "neither"
    return {(False, False): "neither", (True, False): "min", (False, True): "max",
            (True, True): "both"}[(bool(v.min() < lo), bool(v.max() > hi))]


def robust_limits(v, symmetric=True):
    """(lo, hi): the 0.5 and 99.5 percentiles of the finite values (a few spikes saturate instead of
    washing the map out), symmetric about zero when ``symmetric``."""
    v = np.asarray(v)[np.isfinite(v)]
    if v.size == 0:
        return -1.0, 1.0
    lo, hi = np.percentile(v, [0.5, 99.5])
    if symmetric:
        m = max(abs(lo), abs(hi)) or 1e-12
        return -m, m
    return (lo, hi) if hi > lo else (lo - 1e-12, hi + 1e-12)


def default_bins(n: int, span_mm: float | None = None, pixel_mm=None) -> int:
    """Bins across a map of ``n`` points: ~1.2 √n (16…400), so sparse patterns still read as a
    surface — but never finer than an instrument grid's pixel (``pixel_mm``, the reader's
    meta["pixel_mm"], over a map ``span_mm`` wide): 307 bins over a 256-pixel map left every sixth
    bin empty, a white grid over the map. (The floor was 60: a 300-point cloud was drawn as 3,600
    bins, mostly empty — a review.)"""
    bins = int(np.clip(1.2 * np.sqrt(max(n, 1)), 16, 400))
    if pixel_mm is not None and span_mm is not None and span_mm > 0:
        pitch = float(np.max(np.asarray(pixel_mm, dtype=np.float64)))
        if pitch > 0:
            # a bin wider than the pitch holds a pixel wherever it lies (one as wide, by rounding, not)
            bins = min(bins, max(1, int(np.floor(span_mm / pitch * (1 - 1e-9)))))
    return bins


def raster_pitch(x, y, head: int = 200_000) -> float | None:
    """The larger of the smallest steps between distinct x and distinct y of the first ``head`` points:
    a raster's pitch (a CSV raster has no reader's pixel_mm: its map was drawn with empty bins between
    its rows, white stripes — a review); scattered points give a step far below any bin (no effect)."""
    steps = []
    for a in (np.asarray(x[:head], dtype=np.float64), np.asarray(y[:head], dtype=np.float64)):
        u = np.unique(a[np.isfinite(a)])
        d = np.diff(u)
        d = d[d > 1e-9 * max(float(np.ptp(u)) if u.size else 0.0, 1e-300)]
        if not d.size:
            return None
        steps.append(float(d.min()))
    return max(steps)


def binned_image(x, y, v, bins=None, ext=None, return_bins: bool = True):
    """Mean of v in square bins: the image of a scattered map (fast for millions of points). By
    default ~1.2 √N bins across (16…400), so sparse patterns still read as a surface. Returns
    (image bins×bins with NaN where empty, extent (x0, x1, y0, y1), flat bin of each point — None
    with ``return_bins=False``). Counted in chunks of 2²⁰ points: no full-length temporaries
    (12.6 M points 1.4 → ~0.3 s; issue 26)."""
    x, y, v = (np.asarray(a, dtype=np.float64) for a in (x, y, v))
    if bins is None:
        bins = default_bins(len(x))
    if ext is None:
        span = (max(np.ptp(x), np.ptp(y)) or 1.0) if len(x) else 1.0
        cx, cy = (0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())) if len(x) else (0.0, 0.0)
        ext = (cx - span / 2, cx + span / 2, cy - span / 2, cy + span / 2)
    span = ext[1] - ext[0]
    nb = bins * bins
    n = np.zeros(nb, dtype=np.int64)
    s = np.zeros(nb)
    k_all = np.empty(len(x), dtype=np.intp) if return_bins else None
    step = 1 << 20
    for a in range(0, len(x), step):
        c = slice(a, a + step)
        ix = np.clip(((x[c] - ext[0]) / span * bins).astype(np.intp), 0, bins - 1)
        k = np.clip(((y[c] - ext[2]) / span * bins).astype(np.intp), 0, bins - 1)
        k *= bins
        k += ix
        n += np.bincount(k, minlength=nb)
        s += np.bincount(k, weights=v[c], minlength=nb)
        if k_all is not None:
            k_all[c] = k
    with np.errstate(invalid="ignore", divide="ignore"):
        img = np.where(n > 0, s / n, np.nan).reshape(bins, bins)
    return img, ext, k_all


def _binned(x, y, v, bins=None):
    img, ext, _ = binned_image(x, y, v, bins, return_bins=False)
    return img, ext


def _map_axes(fig, ax, img_mm, ext, quantity, title, symmetric=True, cmap=DIVERGING, points_mm=None):
    """A map of lengths (``img_mm``, mm) with its colour bar labelled "quantity (unit)" in the unit
    their size asks for (``length_axis``). ``points_mm``: the values the image was binned from — the
    unit and the colour limits are then theirs (``limits_sample``), as in the window's views."""
    own = img_mm if points_mm is None else points_mm
    scale, unit = length_axis(own)
    img = np.asarray(img_mm, dtype=np.float64) * scale
    label = f"{quantity} ({unit})" if quantity else unit
    lo, hi = robust_limits(limits_sample(own) * scale, symmetric)
    if hi - lo <= 2e-12:  # all values equal (a flat map): one unit either side, not ±1e-12
        mid = 0.0 if symmetric else 0.5 * (lo + hi)
        lo, hi = mid - 1.0, mid + 1.0
    im = ax.imshow(img, origin="lower", extent=ext, cmap=cmap, vmin=lo, vmax=hi,
                   interpolation="nearest")
    span = max(ext[1] - ext[0], ext[3] - ext[2])
    position_axis(ax, "x", "x", span, 0.5 * (ext[0] + ext[1]))
    position_axis(ax, "y", "y", span, 0.5 * (ext[2] + ext[3]))
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=10)
    extend = colour_extend(img, lo, hi)
    fig.colorbar(im, ax=ax, label=label, extend=extend)


def scattered_map(x, y, r_mm, title="Form error", pixel_mm=None):
    """Residual (mm) at scattered points, binned, in the unit its size asks for; ``pixel_mm``: an
    instrument grid's pixel, which the bins are never finer than (``default_bins``)."""
    fig = _figure()
    ax = fig.add_subplot()
    bins = None
    if pixel_mm is None and len(x):
        pixel_mm = raster_pitch(x, y)
    if pixel_mm is not None and len(x):
        bins = default_bins(len(x), max(np.ptp(x), np.ptp(y)), pixel_mm)
    img, ext = _binned(x, y, np.asarray(r_mm), bins)
    _map_axes(fig, ax, img, ext, "", title, points_mm=r_mm)
    return fig


def grid_map_figure(grid, title="Form-error map"):
    fig = _figure()
    ax = fig.add_subplot()
    h = grid.spacing / 2
    ext = (grid.xs[0] - h, grid.xs[-1] + h, grid.ys[0] - h, grid.ys[-1] + h)
    _map_axes(fig, ax, grid.z, ext, "", title)
    return fig


def before_after(x, y, before_mm, after_mm, what="correction", x2=None, y2=None, weights=None,
                 after_rms_mm=None):
    """Two maps side by side on their own scales (each about its mean: piston is not shown, each in
    the unit its size asks for); x2, y2 when the point sets differ. ``weights``: the points' areas
    (core.metrics.area_weights; one per point, both panels) for the RMS in the titles — over the area
    (docs/conventions.md, Summary figures); None: the points' plain RMS (an even sampling).
    ``after_rms_mm``: the after panel's RMS as the step reports it, where that is not about the mean
    (misalignment's residual RMS is about zero: a held dz's piston counts) — the title and the report
    then say one number (953.6 nm stood beside the report's 953.7 nm)."""
    from .metrics.area_weights import weighted_rms

    fig = _figure(11, 4.6)
    ax1, ax2 = fig.subplots(1, 2)
    # binned in mm, then about the mean: the bins' means are linear in the values, so no full-length
    # copies are made (12.6 M points)
    for ax, px, py, vals, when in ((ax1, x, y, before_mm, "before"),
                                   (ax2, x if x2 is None else x2, y if y2 is None else y2, after_mm, "after")):
        vals = np.asarray(vals, dtype=np.float64)
        mean = float(vals.mean())
        img, ext = _binned(px, py, vals)
        img = img - mean
        rms = np.std(vals) if weights is None else weighted_rms(vals, weights)
        if when == "after" and after_rms_mm is not None:
            rms = after_rms_mm
        _map_axes(fig, ax, img, ext, "", f"{when} {what}: RMS {format_length(rms, 4)}")
    return fig


def zernike_bars(labels, coef_nm, removed=(), title="Zernike coefficients", normalization=None):
    """The coefficients (nm) as bars, the removed ones grey, in the unit the largest kept one asks
    for (core.units.length_unit: a 1 mm sag's terms in µm or mm, not 1e6 nm). The axis is the kept
    terms': a removed term beyond it (an interferometer's piston of 50 µm beside 15 nm of power) is
    cut at the axis's end with its value written there — it hid every kept term."""
    from .units import length_unit

    fig = _figure(max(6.4, 0.22 * len(labels) + 2), 4.2)
    ax = fig.add_subplot()
    coef_mm = np.asarray(coef_nm, dtype=np.float64) * 1e-6
    gone = np.array([lab in removed for lab in labels], dtype=bool)
    finite = np.isfinite(coef_mm)
    basis = coef_mm[~gone & finite & (coef_mm != 0)]
    own = basis.size > 0  # kept terms that are not all zero set the unit and the axis
    if not own:  # every term removed, or the kept ones zero: all the terms set them, nothing is cut
        basis = coef_mm[finite & (coef_mm != 0)]
    big = float(np.max(np.abs(basis))) if basis.size else 0.0
    scale, unit = length_unit(big) if big > 0 else (1e-6, "nm")
    if unit == "m":
        scale, unit = 1.0, "mm"
    shown = coef_mm / scale
    lim = 1.15 * big / scale
    cut = gone & finite & (np.abs(shown) > lim) if own else np.zeros(len(shown), dtype=bool)
    colors = ["#bbbbbb" if g else "#2c6fbb" for g in gone]
    ax.bar(np.arange(len(labels)), np.clip(shown, -lim, lim) if cut.any() else shown, color=colors)
    if cut.any():
        ax.set_ylim(-lim, lim)
        for k in np.flatnonzero(cut):
            ax.text(k, np.sign(shown[k]) * lim * 0.97, format_length(coef_mm[k]), rotation=90, fontsize=7,
                    ha="center", va="top" if shown[k] > 0 else "bottom", color="#555555")
    ax.set_xticks(np.arange(len(labels)), labels, rotation=90, fontsize=7)
    ax.set_ylabel(f"coefficient ({unit} RMS)" if normalization == "rms" else f"coefficient ({unit})")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_title(title + (" (grey: removed)" if removed else ""), fontsize=10)
    return fig


def profiles_figure(grid, angles=(0.0, 90.0), center=(0.0, 0.0), quantity="form error"):
    """Profiles through ``center`` at ``angles`` and the radial profile of the map; ``quantity`` names
    the values on the y axes (bspline_map on heights: "z, piston and tilt removed")."""
    from .metrics.profiles import profile, radial_profile

    fig = _figure(11, 4.2)
    ax1, ax2 = fig.subplots(1, 2)
    scale, unit = length_axis(grid.z)  # the map's unit: both panels and map.png read alike
    for a in angles:
        s, z = profile(grid, a, center)
        ax1.plot(s, z * scale, lw=1, label=f"{a:g}°")
    span = max(np.ptp(grid.xs) if grid.xs.size else 0.0, np.ptp(grid.ys) if grid.ys.size else 0.0)
    position_axis(ax1, "x", "position along the cut", span)
    ax1.set_ylabel(f"{quantity} ({unit})")
    ax1.legend(fontsize=8)
    ax1.set_title("profiles through the centre", fontsize=10)
    r, m, sd = radial_profile(grid, center)
    ax2.plot(r, m * scale, color="#2c6fbb", lw=1)
    ax2.fill_between(r, (m - sd) * scale, (m + sd) * scale, color="#2c6fbb", alpha=0.2, lw=0)
    position_axis(ax2, "x", "radius", span)
    ax2.set_ylabel(f"{quantity} ({unit})")
    ax2.set_title("radial profile: ring mean ± std", fontsize=10)
    return fig


def psd_figure(grid):
    from matplotlib.colors import LogNorm

    from .metrics.profiles import psd_1d, psd_2d

    fig = _figure(11, 4.2)
    ax1, ax2 = fig.subplots(1, 2)
    drawn = 0
    for axis in ("x", "y"):
        f, p = psd_1d(grid, axis)
        ok = (f > 0) & (p > 0)  # a flat map's PSD is 0: no log axis (matplotlib warned in the batch)
        if ok.any():
            ax1.loglog(f[ok], p[ok] * 1e12, lw=1, label=f"along {axis}")  # mm³ → nm²·mm
            drawn += 1
    ax1.set_xlabel("spatial frequency (1/mm)")
    ax1.set_ylabel("PSD (nm²·mm)")
    ax1.set_title("1-D PSD", fontsize=10)
    if drawn:
        ax1.legend(fontsize=8)
        plain_log_ticks(ax1.xaxis)
        plain_log_ticks(ax1.yaxis)
    else:
        ax1.text(0.5, 0.5, "the PSD is zero (a flat map)", ha="center", va="center", transform=ax1.transAxes)
    fx, fy, p = psd_2d(grid)
    p = p * 1e12  # mm⁴ → nm²·mm²
    pos = p[p > 0]
    norm = LogNorm(vmin=max(pos.max() * 1e-8, pos.min()), vmax=pos.max()) if pos.size else None
    im = ax2.imshow(p, origin="lower", extent=(fx[0], fx[-1], fy[0], fy[-1]), norm=norm,
                    cmap="viridis")
    ax2.set_xlabel("fx (1/mm)")
    ax2.set_ylabel("fy (1/mm)")
    ax2.set_title("2-D PSD", fontsize=10)
    cb = fig.colorbar(im, ax=ax2, label="nm²·mm²")
    if norm is not None:
        plain_log_ticks(cb.ax.yaxis)
    return fig


def omega_map(x, y, omega_mm, removed_mask, title="ω after denoising"):
    """ω at the kept points (in the unit its size asks for) and the removed points marked."""
    fig = _figure()
    ax = fig.add_subplot()
    keep = ~np.asarray(removed_mask, bool)
    img, ext = _binned(np.asarray(x)[keep], np.asarray(y)[keep], np.asarray(omega_mm)[keep])
    _map_axes(fig, ax, img, ext, "ω", title, symmetric=False, cmap="viridis")
    if (~keep).any():
        ax.plot(np.asarray(x)[~keep], np.asarray(y)[~keep], "x", color="red", ms=6,
                label=f"removed ({int((~keep).sum())})")
        ax.legend(fontsize=8, loc="upper right")
    return fig


def position_axis(ax, which: str, label: str, span_mm: float, centre_mm: float | None = None) -> None:
    """Label axis ``which`` ("x" or "y") of positions in mm: "label (mm)", or "label (µm)" with the
    tick labels × 1000 where the field is under 1 mm across (a 20 µm field read 0.000 … 0.020 mm, its
    ticks running together). Only the labels change: the data stay in mm, so the window's
    selections and cuts keep their coordinates. ``centre_mm``: the field's centre on that axis —
    a small field far from the origin is labelled from a round offset, "y − 2000 mm (µm)", its ticks
    the µm from there (a 3 µm field at y = 2000 mm read "2e+06" at every tick: a review)."""
    from matplotlib.ticker import FuncFormatter, ScalarFormatter

    axis = ax.xaxis if which == "x" else ax.yaxis
    if np.isfinite(span_mm) and 0 < span_mm < 1.0:
        off = 0.0
        if centre_mm is not None and np.isfinite(centre_mm) and abs(centre_mm) > 100.0 * span_mm:
            step = 10.0 ** np.floor(np.log10(span_mm))  # a round offset, to the field's own scale
            off = float(np.round(centre_mm / step) * step)
        axis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{(v - off) * 1e3:.6g}"))
        axis.set_label_text(f"{label} − {off:g} mm (µm)" if off else f"{label} (µm)")
    else:
        axis.set_major_formatter(ScalarFormatter())
        axis.set_label_text(f"{label} (mm)")


def length_axis(values_mm) -> tuple[float, str]:
    """(factor mm → shown unit, unit) for lengths of this size: ``core.units.display_unit`` (the
    unit of their robust spread: nm below 1 µm, µm below 1 mm, mm above), the window's rule too."""
    from .units import display_unit

    unit = display_unit(values_mm)
    return {"nm": (1e6, "nm"), "µm": (1e3, "µm")}.get(unit, (1.0, "mm"))


def stylus_profile_figure(items, title="Form error along the profile"):
    """Residual against the position along the profile, and the slope error (µrad); ``items`` are
    dicts with label, u (mm, part frame), residual (mm), slope (rad)."""
    fig = _figure(11, 4.2)
    ax1, ax2 = fig.subplots(1, 2)
    scale, unit = length_axis(np.concatenate([np.asarray(it["residual"]) for it in items]))
    for it in items:
        o = np.argsort(it["u"])
        u = np.asarray(it["u"])[o]
        r = np.asarray(it["residual"])[o]
        rms = np.sqrt(np.mean((r - r.mean()) ** 2)) * scale
        ax1.plot(u, r * scale, lw=0.8, label=f"{it['label']}: PV {np.ptp(r) * scale:.4g}, RMS {rms:.4g} {unit}")
        ax2.plot(u, np.asarray(it["slope"])[o] * 1e6, lw=0.8, label=it["label"])
    ax1.set_xlabel("position along the profile, part frame (mm)")
    ax1.set_ylabel(f"form error ({unit})")
    ax1.axhline(0, color="k", lw=0.5)
    ax1.legend(fontsize=7)
    ax1.set_title(title, fontsize=10)
    ax2.set_xlabel("position along the profile, part frame (mm)")
    ax2.set_ylabel("slope error (µrad)")
    ax2.axhline(0, color="k", lw=0.5)
    ax2.legend(fontsize=7)
    ax2.set_title("slope error (local line fit)", fontsize=10)
    return fig


def stylus_psd_figure(items):
    """1-D PSD of each profile's residual (nm²·mm); ``items``: dicts with label, f (1/mm), psd (mm³)."""
    fig = _figure()
    ax = fig.add_subplot()
    for it in items:
        f, p = np.asarray(it["f"]), np.asarray(it["psd"])
        ok = (f > 0) & (p > 0)
        ax.loglog(f[ok], p[ok] * 1e12, lw=0.8, label=it["label"])
    ax.set_xlabel("spatial frequency (1/mm)")
    ax.set_ylabel("PSD (nm²·mm)")
    ax.legend(fontsize=8)
    ax.set_title("1-D PSD of the form error along the profile", fontsize=10)
    if items:
        plain_log_ticks(ax.xaxis)
        plain_log_ticks(ax.yaxis)
    return fig
