"""The 2D map: the channel binned on a square grid (the reports' figure, core.figures.binned_image),
rectangle and lasso selection, profile cuts, and selection by threshold with a slider.

The figure is built once and updated in place. While the optician edits one input in one channel
(deletions, undo, redo) the colour limits stay fixed — the same colour means the same height before
and after a deletion — and only the image is redrawn over a cached background (matplotlib blitting):
~20 ms on a million points instead of ~100 ms for a full figure draw.

The view is given the session's ``view`` (a cloud and the mask of its points shown). The bin of
every point is computed once per cloud; a deletion (or its undo) only takes the changed points out
of (or back into) the bins' counts and sums, and the profile cut keeps the points near its line, so
an edit of 12.6 million points costs a few passes over a mask, not a new image from all points.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from . import display

MODES = ("select rectangle", "select lasso", "profile cut")

#: the figure's margins (fractions of the canvas) where it has room for its labels
MARGINS = {"left": 0.15, "right": 0.8, "bottom": 0.1, "top": 0.95}
_PAD_PX = 3  # pixels kept between a label and the canvas' edge


def _labels_engine():
    """A matplotlib layout engine (run at each full draw, before anything is drawn — so the blitting
    background holds the laid-out figure) that puts the subplots at ``MARGINS`` and widens a margin where
    the axes' tick labels, axis labels or titles would leave the canvas. In a narrow map dock (320 px
    when the autosave banner's one line of text held the centre of the window 808 px wide) the fixed
    15 % left of the map cut "y (mm)" off, and the colour bar's unit was cut off on the right."""
    from matplotlib.layout_engine import LayoutEngine

    class _KeepLabels(LayoutEngine):
        _adjust_compatible = True
        _colorbar_gridspec = False

        _last = (None, MARGINS)  # (what the labels' extents depend on, the margins found for it)

        def execute(self, fig):
            w, h = fig.bbox.width, fig.bbox.height
            # measuring costs ~40 ms a draw: not again while the size, limits and labels are the same
            key = (w, h, tuple((a.get_xlim(), a.get_ylim(), a.get_xlabel(), a.get_ylabel(), a.get_title(),
                                a.get_visible(), a.xaxis.get_major_formatter(), a.yaxis.get_major_formatter())
                               for a in fig.axes))
            if key == self._last[0]:
                fig.subplots_adjust(**self._last[1])
                return
            self._last = (None, MARGINS)
            renderer = fig._get_renderer()
            m = dict(MARGINS)
            fig.subplots_adjust(**m)
            for _ in range(4):  # the map keeps its aspect: moving its slot's edge may move it less
                boxes = [a.get_tightbbox(renderer, bbox_extra_artists=[]) for a in fig.axes if a.get_visible()]
                boxes = [b for b in boxes if b is not None and np.all(np.isfinite(b.extents))]
                if not boxes or w <= 0 or h <= 0:
                    break
                x0, x1 = min(b.x0 for b in boxes), max(b.x1 for b in boxes)
                y0, y1 = min(b.y0 for b in boxes), max(b.y1 for b in boxes)
                new = dict(m)
                if x0 < _PAD_PX:
                    new["left"] += (_PAD_PX - x0) / w
                if x1 > w - _PAD_PX:
                    new["right"] -= (x1 - w + _PAD_PX) / w
                if y0 < _PAD_PX:
                    new["bottom"] += (_PAD_PX - y0) / h
                if y1 > h - _PAD_PX:
                    new["top"] -= (y1 - h + _PAD_PX) / h
                if new == m or new["right"] - new["left"] < 0.2 or new["top"] - new["bottom"] < 0.2:
                    break  # all inside, or a canvas too small to hold them: as far as it goes
                m = new
                fig.subplots_adjust(**m)
            self._last = (key, m)

    return _KeepLabels()


class MapView(QtWidgets.QWidget):
    """``selected(mask)`` is emitted with a boolean mask over the shown cloud."""

    selected = QtCore.Signal(object)

    def __init__(self, parent=None):
        super().__init__(parent)
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
        from matplotlib.figure import Figure
        from matplotlib.widgets import LassoSelector, RectangleSelector

        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        tools = QtWidgets.QHBoxLayout()
        tools.addWidget(QtWidgets.QLabel("2D:"))
        self.mode = QtWidgets.QComboBox()
        self.mode.addItems(MODES)
        self.mode.currentTextChanged.connect(self._mode_changed)
        tools.addWidget(self.mode)
        self.info = QtWidgets.QLabel("")
        tools.addWidget(self.info, 1)
        lay.addLayout(tools)
        self.figure = Figure(figsize=(5.2, 6.0), dpi=90)
        gs = self.figure.add_gridspec(2, 2, height_ratios=(3.2, 1), width_ratios=(1, 0.04),
                                      hspace=0.35, wspace=0.05)
        self.figure.subplots_adjust(**MARGINS)  # the grid's margins: the figure's
        self.figure.set_layout_engine(_labels_engine())  # widened where the labels need it
        self.ax = self.figure.add_subplot(gs[0, 0])
        self.cax = self.figure.add_subplot(gs[0, 1])
        self.pax = self.figure.add_subplot(gs[1, :])
        self.ax.set_xlabel("x (mm)")
        self.ax.set_ylabel("y (mm)")
        self.pax.set_xlabel("along the cut (mm)")
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.canvas.setMinimumSize(320, 360)
        lay.addWidget(self.canvas, 1)
        self.profile_info = QtWidgets.QLabel("")
        lay.addWidget(self.profile_info)
        th = QtWidgets.QHBoxLayout()
        th.addWidget(QtWidgets.QLabel("Select above"))
        self.th_channel = QtWidgets.QComboBox()
        self.th_channel.setToolTip("select the points whose value of this channel is above the slider's")
        th.addWidget(self.th_channel)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.slider.setRange(0, 1000)
        self.slider.setValue(1000)
        self.slider.setToolTip("quantile of the channel: move left to select more points")
        self.slider.valueChanged.connect(self._threshold)
        # another channel re-selects at the slider's position (the box did nothing until it moved)
        self.th_channel.currentTextChanged.connect(lambda _name: self._threshold(self.slider.value()))
        th.addWidget(self.slider, 1)
        self.th_info = QtWidgets.QLabel("")
        self._thresholding = False  # a selection from the threshold, on its way back (highlight)
        th.addWidget(self.th_info)
        lay.addLayout(th)
        self.cloud = None
        self.channel = None
        self.keep = None  # the cloud's points shown (None: all)
        self._sub = None  # a stylus cloud is drawn as its shown points: the mask they were taken by
        self._cnt = self._sum = None  # points and sum of values per bin (of the shown points)
        self._near = None  # (cloud, line, bins, positions near the cut line)
        self.values = None
        self.im = self.sel_im = self.cbar = None
        self._unit = None  # display unit of the drawn channel (kept with the colour limits)
        self.ext = None
        self._k = None
        self.profile = None        # (distance along the cut mm, value in display units)
        self.stylus = None         # a stylus profile cloud: its profiles (core.profiles), drawn as curves
        self.profile_line = None   # ((x0, y0), (x1, y1)) mm
        self._line_artist = None
        self._profile_artists = []
        self._press = None
        self._bg = None
        # connected before the selectors: the lasso's own draw_event handler (useblit) draws every
        # animated artist of the axes — our map image and highlight — into the buffer after its
        # background is taken, and a handler called after it copied a "background" holding the map
        # as it was: after a deletion the hole and the old highlight never showed until a full redraw
        self.canvas.mpl_connect("draw_event", self._on_draw)
        self._rect = RectangleSelector(self.ax, self._on_rect, useblit=False, interactive=False)
        self._lasso = LassoSelector(self.ax, self._on_lasso)
        self.canvas.mpl_connect("button_press_event", self._on_press)
        self.canvas.mpl_connect("button_release_event", self._on_release)
        self._mode_changed(self.mode.currentText())

    # -- drawing ------------------------------------------------------------------------------------
    def set_cloud(self, cloud, channel: str, new_input: bool = False, keep_limits: bool = False,
                  keep=None):
        """Show ``cloud`` (less the points ``keep`` hides) in ``channel``; ``keep_limits`` (an edit
        of the same input in the same channel) keeps the extent and colour limits and redraws only
        the image."""
        same = keep_limits and not new_input and self.im is not None and channel == self.channel
        self._sub = None
        if cloud is not None and keep is not None and _is_stylus(cloud):
            cloud, self._sub, keep = cloud.select(keep), keep, None  # short: its rows are its own
        n = 0 if cloud is None else cloud.n if keep is None else int(np.count_nonzero(keep))
        if n == 0:
            self.cloud, self.channel, self.keep = cloud, channel, keep
            self.values = self._k = None
            if self.im is not None:
                self.im.set_data(np.full((2, 2), np.nan))
                self.canvas.draw_idle()
            return
        edit = same and cloud is self.cloud and self._k is not None
        old_keep = self.keep
        self.cloud, self.channel, self.keep = cloud, channel, keep
        if not edit or not self._recount(old_keep, keep):
            vals, title, self._unit, diverging = display.channel_display(
                cloud, channel, self._unit if same else None)  # an edit keeps the unit with the limits
            self.values = vals
            if new_input:
                self.ext = None  # else the input's extent, kept through deletions: the map stays put
                self.profile_line = None
            if self.ext is None:
                self.ext = _extent(cloud.x if keep is None else cloud.x[keep],
                                   cloud.y if keep is None else cloud.y[keep])
            if not same:  # never finer than an instrument grid's pixel (a white grid over the map)
                from pointspro.core.figures import default_bins, raster_pitch

                pixel = cloud.meta.get("pixel_mm")
                if pixel is None:  # a CSV raster: its pitch from its coordinates (white stripes, a review)
                    pixel = raster_pitch(cloud.x, cloud.y)
                self._bins = default_bins(n, self.ext[1] - self.ext[0], pixel)
            self._k = _bin_of(cloud.x, cloud.y, self.ext, self._bins)
            self._count(keep)
        img, ext = self._image(), self.ext
        self.info.setText(f"{n:,} points")
        if same:
            self.im.set_data(img)
            self.sel_im.set_data(np.zeros(img.shape + (4,)))
            if self.stylus is not None:
                self.stylus = _stylus_profiles(cloud)  # the rows of the edited cloud
            if self.stylus is not None:
                self._draw_stylus(fast=True)
            elif self.profile_line is not None:
                self.cut(*self.profile_line, draw=False, fast=True)
            self._blit()
            return
        lo, hi = display.colour_limits(self.values, diverging, keep)  # of the points, as 3D and report
        cmap = "RdBu_r" if diverging else "viridis"
        # the colour bar's ends say where values go beyond its range (the robust limits saturate a
        # few spikes: a ±29 nm bar on a map whose PV is 1.36 µm showed no sign of them)
        shown = self.values if keep is None else self.values[keep]
        from pointspro.core.figures import colour_extend

        extend = colour_extend(shown, lo, hi)
        if self.im is None:
            self.im = self.ax.imshow(img, origin="lower", extent=ext, cmap=cmap, vmin=lo, vmax=hi,
                                     interpolation="nearest", animated=True)
            self.cbar = self.figure.colorbar(self.im, cax=self.cax, extend=extend)
            self.sel_im = self.ax.imshow(np.zeros(img.shape + (4,)), origin="lower", extent=ext,
                                         interpolation="nearest", animated=True)
        else:
            self.im.set_data(img)
            self.im.set_extent(ext)
            self.im.set_cmap(cmap)
            self.im.set_clim(lo, hi)
            self.sel_im.set_extent(ext)
            if self.cbar.extend != extend:  # set when a colour bar is made: made again
                # the old bar let go of the image first: left listening, it tried to redraw its
                # cleared artists at every change ("NotImplementedError: cannot remove artist"
                # on stderr) and one more stale listener piled up each time (a review)
                self.im.callbacks.disconnect(getattr(self.im, "colorbar_cid", None))
                self.cax.clear()
                self.cbar = self.figure.colorbar(self.im, cax=self.cax, extend=extend)
        self.sel_im.set_data(np.zeros(img.shape + (4,)))
        self.cbar.set_label(title)
        self.ax.set_xlim(ext[0], ext[1])
        self.ax.set_ylim(ext[2], ext[3])
        position_axis(self.ax, "x", "x", self._span(), 0.5 * (ext[0] + ext[1]))  # µm for a field under
        position_axis(self.ax, "y", "y", self._span(), 0.5 * (ext[2] + ext[3]))  # 1 mm, from an offset
        self.ax.set_title(title, fontsize=9)
        self._fill_threshold_channels()
        self.stylus = _stylus_profiles(cloud)
        if self.stylus is not None:  # a stylus profile: the curves themselves, not a cut of a map
            self._draw_stylus()
        else:
            if self.profile_line is None:  # the opening cut: along x through the middle of the part,
                cy = 0.5 * (ext[2] + ext[3])  # on the row of points nearest to it (the middle of an
                ys = cloud.y if keep is None else cloud.y[keep]  # even number of rows has none: an
                if ys.size:  # empty profile, "no points near the cut", on a 4 × 4 file)
                    cy = float(ys[np.argmin(np.abs(ys - cy))])
                self.profile_line = ((ext[0], cy), (ext[1], cy))
            self.cut(*self.profile_line, draw=False)
        self.canvas.draw_idle()

    # -- the bins: counts and sums of the shown points, changed by the points an edit changes ------
    def _count(self, keep):
        k, v, nb = self._k, self.values, self._bins ** 2
        if keep is not None:
            k, v = k[keep], v[keep]
        self._cnt = np.bincount(k, minlength=nb)
        self._sum = np.bincount(k, weights=v, minlength=nb)

    def _recount(self, old, new) -> bool:
        """Take the points ``new`` hides out of the bins and put those it shows back; False when a
        full count is needed (a non-finite value among them)."""
        if old is None and new is None:
            return True
        if old is None:
            out, back = np.flatnonzero(~new), None
        elif new is None:
            out, back = None, np.flatnonzero(~old)
        else:
            d = old ^ new
            out, back = np.flatnonzero(d & old), np.flatnonzero(d & new)
        nb = self._bins ** 2
        for pos, sign in ((out, -1), (back, 1)):
            if pos is None or pos.size == 0:
                continue
            v = self.values[pos]
            if not np.all(np.isfinite(v)):
                return False
            k = self._k[pos]
            self._cnt += sign * np.bincount(k, minlength=nb)
            self._sum += sign * np.bincount(k, weights=v, minlength=nb)
        return True

    def _image(self) -> np.ndarray:
        b = self._bins
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self._cnt > 0, self._sum / self._cnt, np.nan).reshape(b, b)

    def _shown_positions(self):
        """Positions of the shown points (None: all of them)."""
        return None if self.keep is None else np.flatnonzero(self.keep)

    def _draw_stylus(self, fast: bool = False):
        """Each stylus profile as a curve of the shown channel against the position along it (mm),
        in scan order; the map above shows where it lies. ``fast``: new data, same axes."""
        label = self.cbar.ax.get_ylabel() if self.cbar else ""
        unit = label[label.rfind("(") + 1:-1] if label.endswith(")") else ""
        curves = []
        for p in self.stylus:
            order = np.argsort(p.s, kind="stable")
            curves.append((p, p.s[order], self.values[p.rows][order]))
        self.profile = (np.concatenate([c[1] for c in curves]), np.concatenate([c[2] for c in curves]))
        pv = ", ".join(f"{p.angle_deg:g}°: PV {display.shown_length(np.ptp(v), unit)}" for p, _, v in curves)
        self.profile_info.setText(f"{len(curves)} stylus profile(s) — {pv}")
        if fast and len(self._profile_artists) == len(curves):
            for art, (_, s_, v) in zip(self._profile_artists, curves):
                art.set_data(s_, v)
            return
        if self._line_artist is not None:
            self._line_artist.remove()
            self._line_artist = None
        pax = self.pax
        pax.clear()
        position_axis(pax, "x", "along the profile", self._span())
        pax.set_ylabel(label)
        self._profile_artists = [pax.plot(s_, v, lw=1.0, label=f"{p.angle_deg:g}°", animated=True)[0]
                                 for p, s_, v in curves]
        lo = min(float(s_.min()) for _, s_, _ in curves)
        hi = max(float(s_.max()) for _, s_, _ in curves)
        vmin = min(float(v.min()) for _, _, v in curves)
        vmax = max(float(v.max()) for _, _, v in curves)
        pad = 0.05 * ((vmax - vmin) or 1.0)
        pax.set_xlim(lo, hi if hi > lo else lo + 1.0)
        pax.set_ylim(vmin - pad, vmax + pad)
        if len(curves) > 1:
            pax.legend(handles=self._profile_artists, fontsize=7, loc="upper right")
        if fast:  # a deletion took a whole profile: the axes changed, a blit would not show it
            self.canvas.draw_idle()

    # -- fast redraws: the map's images over a cached background ------------------------------------
    def _on_draw(self, _ev):
        self._bg = (self.canvas.copy_from_bbox(self.ax.bbox), self.canvas.copy_from_bbox(self.pax.bbox))
        self._draw_animated()

    def _draw_animated(self):
        for a in (self.im, self.sel_im, self._line_artist):
            if a is not None:
                self.ax.draw_artist(a)
        for a in self._profile_artists:
            self.pax.draw_artist(a)

    def _blit(self, profile: bool = True):
        """Redraw the animated artists over the cached background; ``profile=False``: the map's
        axes only (a highlight changes nothing in the profile below)."""
        if self._bg is None:
            self.canvas.draw_idle()
            return
        if not profile:
            self.canvas.restore_region(self._bg[0])
            for a in (self.im, self.sel_im, self._line_artist):
                if a is not None:
                    self.ax.draw_artist(a)
            self.canvas.blit(self.ax.bbox)
            return
        for bg in self._bg:
            self.canvas.restore_region(bg)
        self._draw_animated()
        # one repaint of the rectangle holding both axes (two cost two paint events' fixed part)
        from matplotlib.transforms import Bbox

        self.canvas.blit(Bbox.union([self.ax.bbox, self.pax.bbox]))

    def save_png(self, path, dpi=150):
        """The map as shown (the animated images are drawn too)."""
        arts = [a for a in (self.im, self.sel_im, self._line_artist) if a is not None] + self._profile_artists
        for a in arts:
            a.set_animated(False)
        try:
            self.figure.savefig(path, dpi=dpi)
        finally:
            for a in arts:
                a.set_animated(True)
            self.canvas.draw_idle()

    def highlight(self, mask):
        """Bins holding selected points turn yellow. A selection the threshold did not make (cleared,
        deleted, drawn) resets the threshold's slider and its "44 points: residual > 1.111 µm",
        which stood on after those points were deleted (a review)."""
        if not self._thresholding:
            self.reset_threshold()
        if self.sel_im is None or self._k is None:
            return
        b = self._bins
        rgba = np.zeros((b * b, 4))
        if mask is not None and self._sub is not None:  # over the cloud before the stylus' edits
            mask = mask[self._sub]
        n = self.cloud.n if self.keep is None else int(np.count_nonzero(self.keep))
        if mask is not None and np.any(mask):
            hit = np.bincount(self._k[mask], minlength=b * b) > 0
            rgba[hit] = (1.0, 0.8, 0.0, 0.85)
            self.info.setText(f"{n:,} points, {int(np.count_nonzero(mask)):,} selected")
        else:
            self.info.setText(f"{n:,} points" if self.cloud is not None else "")
        self.sel_im.set_data(rgba.reshape(b, b, 4))
        self._blit(profile=False)

    # -- profile cuts -------------------------------------------------------------------------------
    def _span(self) -> float:
        """The map's width (mm): its axes read µm below 1 mm (core.figures.position_axis)."""
        return float(self.ext[1] - self.ext[0]) if self.ext is not None else float("nan")

    def cut(self, p0, p1, draw: bool = True, fast: bool = False):
        """Profile of the shown channel along p0→p1 (mm): the points within 1.5 map bins of the line,
        their values against the distance along the cut, and their mean per bin. ``fast`` (an edit
        of the same cut): new data in the same axes limits, blitted with the map."""
        if self.cloud is None:
            return None
        self.profile_line = (tuple(map(float, p0)), tuple(map(float, p1)))
        binw = (self.ext[1] - self.ext[0]) / self._bins
        pos = self._near_cut(1.5 * binw)
        x, y, vals = self.cloud.x, self.cloud.y, self.values
        if pos is not None:
            x, y, vals = x[pos], y[pos], vals[pos]
        s, v = display.profile_along(x, y, vals, p0, p1, 1.5 * binw)
        self.profile = (s, v)
        mean_s, mean_v = np.empty(0), np.empty(0)
        if s.size:
            edges = np.arange(0.0, s[-1] + binw, binw)
            j = np.digitize(s, edges)
            n = np.bincount(j, minlength=edges.size + 1)
            m = np.bincount(j, weights=v, minlength=edges.size + 1)
            ok = n > 0
            centres = np.append(edges, edges[-1] + binw) - binw / 2
            mean_s, mean_v = centres[ok], m[ok] / n[ok]
            # the curve breaks where two or more bins have no point (a deleted square, the space
            # between a star's spokes): it was drawn straight across the hole (a review)
            gap = np.flatnonzero(np.diff(mean_s) > 2.5 * binw)
            if gap.size:
                mean_s = np.insert(mean_s, gap + 1, np.nan)
                mean_v = np.insert(mean_v, gap + 1, np.nan)
        label = self.cbar.ax.get_ylabel() if self.cbar else ""
        unit = label[label.rfind("(") + 1:-1] if label.endswith(")") else ""
        self.profile_info.setText(f"profile: {s.size:,} points, PV {display.shown_length(np.ptp(v), unit)}"
                                  if s.size else "profile: no points near the cut")
        drawn = display.envelope_rows(s, v)  # dots: a level of detail with all points' envelope
        ds, dv = (s, v) if drawn is None else (s[drawn], v[drawn])
        if fast and self._profile_artists:
            self._profile_artists[0].set_data(ds, dv)
            self._profile_artists[1].set_data(mean_s, mean_v)
            return self.profile
        if self._line_artist is not None:
            self._line_artist.remove()
        (self._line_artist,) = self.ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color="k", lw=1.2,
                                            animated=True)
        pax = self.pax
        pax.clear()
        position_axis(pax, "x", "along the cut", self._span())
        pax.set_ylabel(label)
        dots, = pax.plot(ds, dv, ".", ms=2, color="#999999", animated=True)
        mean, = pax.plot(mean_s, mean_v, color="#2c6fbb", lw=1.2, animated=True)
        self._profile_artists = [dots, mean]
        if s.size:
            pad = 0.05 * (np.ptp(v) or 1.0)
            pax.set_xlim(0, max(s[-1], binw))
            pax.set_ylim(v.min() - pad, v.max() + pad)
        if draw:
            self.canvas.draw_idle()
        return self.profile

    def _near_cut(self, half_width: float):
        """Positions of the shown points that may lie within ``half_width`` of the cut (None: all):
        those of the bins near the line and of the border bins (where points beyond the extent are
        counted), found once per cloud and line and kept through edits."""
        if self.cloud.n < display.CELL_INDEX_FROM:
            return self._shown_positions()
        key = (self.cloud, self.profile_line, self._bins, self.ext)
        if self._near is None or any(a is not b and a != b for a, b in zip(self._near[0], key)):
            b, ext = self._bins, self.ext
            w = (ext[1] - ext[0]) / b
            c = np.arange(b) + 0.5
            gx, gy = np.meshgrid(ext[0] + w * c, ext[2] + w * c)
            (ax, ay), (bx, by) = self.profile_line
            dx, dy = bx - ax, by - ay
            t = np.clip(((gx - ax) * dx + (gy - ay) * dy) / max(dx * dx + dy * dy, 1e-300), 0.0, 1.0)
            near = np.hypot(gx - ax - t * dx, gy - ay - t * dy) <= half_width + 0.71 * w + 1e-9 * (ext[1] - ext[0])
            near[[0, -1], :] = True
            near[:, [0, -1]] = True
            self._near = (key, np.flatnonzero(near.ravel()[self._k]))
        pos = self._near[1]
        return pos if self.keep is None else pos[self.keep[pos]]

    # -- interaction --------------------------------------------------------------------------------
    def _mode_changed(self, mode):
        self._rect.set_active(mode == "select rectangle")
        self._lasso.set_active(mode == "select lasso")

    def _select(self, box_class, test):
        """Mask over the cloud of the shown points ``test(x, y)`` accepts; whole cells of a
        CellIndex decided by ``box_class(x0, x1, y0, y1)`` above half a million points."""
        c, keep = self.cloud, self.keep
        index = display.cell_index(c)
        if index is None:
            mask = test(c.x, c.y)
            return mask if keep is None else mask & keep
        return index.select(lambda ix: box_class(*ix.xy_boxes()), lambda pos: test(c.x[pos], c.y[pos]),
                            keep)

    def _on_rect(self, press, release):
        from pointspro.core.session import in_rectangle

        if self.cloud is not None:
            r = (press.xdata, release.xdata, press.ydata, release.ydata)
            self.selected.emit(self._select(lambda *b: display.rectangle_class(*b, *r),
                                            lambda x, y: in_rectangle(x, y, *r)))

    def _on_lasso(self, verts):
        from pointspro.plugins.aperture import points_in_polygon

        if self.cloud is not None and len(verts) >= 3:
            poly = np.asarray(verts, dtype=np.float64)
            self.selected.emit(self._select(lambda *b: display.polygon_class(*b, poly),
                                            lambda x, y: points_in_polygon(x, y, poly)))

    def _on_press(self, ev):
        if self.mode.currentText() == "profile cut" and ev.inaxes is self.ax:
            self._press = (ev.xdata, ev.ydata)

    def _on_release(self, ev):
        if self._press is not None and ev.inaxes is self.ax and self.stylus is None:
            self.cut(self._press, (ev.xdata, ev.ydata))
        self._press = None

    # -- threshold ----------------------------------------------------------------------------------
    def _fill_threshold_channels(self):
        names = [n for n in self.cloud.column_names if n not in ("x", "y", "index")]
        cur = self.th_channel.currentText()
        self.th_channel.blockSignals(True)
        self.th_channel.clear()
        self.th_channel.addItems(names)
        if cur in names:
            self.th_channel.setCurrentText(cur)
        elif "omega" in names:
            self.th_channel.setCurrentText("omega")
        self.th_channel.blockSignals(False)
        self.reset_threshold()

    def reset_threshold(self):
        """The slider back at its end and its count cleared (no threshold selection)."""
        self.slider.blockSignals(True)
        self.slider.setValue(1000)
        self.slider.blockSignals(False)
        self.th_info.setText("")

    def threshold_mask(self, name: str, pos: int):
        """Points above the ``pos``/1000 quantile of the channel, and the threshold in display units."""
        vals, title, _ = display.channel_values(self.cloud, name)
        value = float(np.quantile(vals if self.keep is None else vals[self.keep], pos / 1000.0))
        mask = vals > value if self.keep is None else (vals > value) & self.keep
        unit = title[title.rfind("(") + 1:-1] if title.endswith(")") else ""
        return mask, f"{title.split(' (')[0]} > {display.shown_length(value, unit)}"

    def _threshold(self, pos):
        name = self.th_channel.currentText()
        if self.cloud is None or not name:
            return
        if pos >= 1000:
            self.th_info.setText("")
            self._thresholding = True
            try:
                self.selected.emit(None)
            finally:
                self._thresholding = False
            return
        mask, text = self.threshold_mask(name, pos)
        self.th_info.setText(f"{int(mask.sum()):,} points: {text}")
        self._thresholding = True  # the selection comes back through highlight: the slider stays
        try:
            self.selected.emit(mask)
        finally:
            self._thresholding = False


def _stylus_profiles(cloud):
    """The cloud's stylus profiles (core.profiles), or None for areal data or when its lines are
    not straight (then the map and its cuts are shown as for any cloud)."""
    from pointspro.core.errors import PointsProError
    from pointspro.core.profiles import profiles_of

    try:
        return profiles_of(cloud)
    except PointsProError:
        return None


_STYLUS: list = [None, False]  # the last cloud asked about, and the answer


def _is_stylus(cloud) -> bool:
    """Whether the cloud is drawn as stylus profiles (the test of _stylus_profiles, without them)."""
    if _STYLUS[0] is not cloud:
        _STYLUS[:] = [cloud, "profile" in cloud.channels or "angle" in cloud.channels or (
            cloud.n >= 2 and bool(np.ptp(cloud.y) == 0) != bool(np.ptp(cloud.x) == 0))]
    return _STYLUS[1]


def position_axis(ax, which, label, span_mm, centre_mm=None):  # core.figures', imported when a view draws
    from pointspro.core.figures import position_axis as axis

    axis(ax, which, label, span_mm, centre_mm)


def _extent(x, y):
    """The map's square extent about the points (core.figures.binned_image's)."""
    span = (max(np.ptp(x), np.ptp(y)) or 1.0) if len(x) else 1.0
    cx, cy = (0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())) if len(x) else (0.0, 0.0)
    return (cx - span / 2, cx + span / 2, cy - span / 2, cy + span / 2)


def _bin_of(x, y, ext, bins: int) -> np.ndarray:
    """The flat bin of every point (core.figures.binned_image's), int32."""
    span = ext[1] - ext[0]

    def cell(v, lo):  # in place on one temporary; clipped before the cast: no overflow
        t = v - lo
        t /= span
        t *= bins
        np.maximum(t, 0, out=t)
        np.minimum(t, bins - 1, out=t)
        return t.astype(np.int32)
    k = cell(y, ext[2])
    k *= bins
    k += cell(x, ext[0])
    return k
