"""The 3D view: the cloud coloured by a channel (pyvistaqt), with a level of detail for millions of
points, rectangle and lasso selection through the view, and the selection highlighted.

Selection is done in numpy: every point of the shown cloud (not only those drawn) is tested against
the rectangle or lasso drawn on the screen through the camera's world→device matrix — the selection
goes through the part, which is what an optician wants when looking along the optical axis. Above
half a million points the cells of display.CellIndex are decided whole from their projected boxes
and only the points of cells the outline crosses are projected (the same mask, 10–50× faster).

The view is given the session's ``view`` (a cloud and the mask of its points shown): deletions
change the mask, the level of detail is chosen once per cloud, and selections are masks over the
cloud (hidden points never selected).
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from . import display


class _LassoOverlay(QtWidgets.QWidget):
    """The rubber band of the 3D view (rectangle or lasso path), drawn over the render window."""

    def __init__(self, parent):
        super().__init__(parent)
        self.setAttribute(QtCore.Qt.WA_TransparentForMouseEvents)
        self.setAttribute(QtCore.Qt.WA_NoSystemBackground)
        self.path: list[QtCore.QPointF] = []
        self.rect = False

    def paintEvent(self, _):
        if len(self.path) < 2:
            return
        p = QtGui.QPainter(self)
        p.setPen(QtGui.QPen(QtGui.QColor("#ffcc00"), 1.5, QtCore.Qt.DashLine))
        if self.rect:
            p.drawRect(QtCore.QRectF(self.path[0], self.path[-1]).normalized())
        else:
            p.drawPolyline(QtGui.QPolygonF(self.path))
        p.end()


def drawn_text(drawn: int, n: int) -> str:
    """The 3D view's count: "150,000 of 12,600,000 points drawn" (``drawn`` of the measurement's
    ``n`` shown points: the level of detail, never the selection's highlight), "4,680 points" when
    all are drawn."""
    return f"{drawn:,} of {n:,} points drawn" if drawn < n else f"{n:,} points"


class View3D(QtWidgets.QWidget):
    """``selected(mask)`` is emitted with a boolean mask over the shown cloud."""

    selected = QtCore.Signal(object)

    def __init__(self, parent=None, budget: int = display.DEFAULT_3D_BUDGET):
        super().__init__(parent)
        from pyvistaqt import QtInteractor

        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        tools = QtWidgets.QHBoxLayout()
        tools.addWidget(QtWidgets.QLabel("3D:"))
        self.mode = QtWidgets.QComboBox()
        self.mode.addItems(["rotate", "select rectangle", "select lasso"])
        self.mode.setToolTip("rotate/zoom the view, or draw a rectangle or lasso to select the points "
                             "under it (through the part)")
        tools.addWidget(self.mode)
        self.info = QtWidgets.QLabel("")
        tools.addWidget(self.info, 1)
        lay.addLayout(tools)
        # no auto-update timer: pyvistaqt's default re-renders 5×/s whatever changed — with 200,000
        # points in software GL that is a 0.13 s stall of the event loop five times a second
        # no multisampling either: 8× MSAA (the theme default) doubles a software-GL frame and adds
        # nothing to single-pixel points
        self.plotter = QtInteractor(self, auto_update=False, multi_samples=0)
        lay.addWidget(self.plotter.interactor, 1)
        self.overlay = _LassoOverlay(self)
        self.overlay.hide()
        self.plotter.interactor.installEventFilter(self)
        self.budget = budget
        self.cloud = None
        self.n_input = 0
        self.origin = np.zeros(3)
        self.channel = None
        self.mask = None
        self.shown_mask = None  # the cloud's points shown (None: all)
        self._lod = (None, None)  # (key, positions): the level of detail of the cloud
        self._shown_idx = None
        self._actor = None
        self._sel_actor = None  # the highlight of the selection, when one is shown
        self._sel_cache = None  # (actor, mesh) of the highlight, kept hidden between selections
        self.mesh = None  # the drawn points' PolyData (the level of detail)
        self._drag = None
        self._axes = False
        self._big = True  # the colour actor draws flat points (above 100,000), not spheres
        self._keep = False
        self._unit = None  # display unit of the drawn channel (kept with the colour limits)
        self._clim = None

    # -- drawing ------------------------------------------------------------------------------------
    def set_cloud(self, cloud, channel: str, n_input: int | None = None, new_input: bool = False,
                  keep_limits: bool = False, keep=None):
        """Show ``cloud`` (less the points ``keep`` hides) coloured by ``channel``; the camera is
        reset only for a new input, and an edit of the same input in the same channel keeps the
        colour limits (same colour, same value)."""
        self._keep = keep_limits and not new_input and channel == self.channel and self._actor is not None
        self.cloud, self.channel, self.mask, self.shown_mask = cloud, channel, None, keep
        if cloud is None:
            self.plotter.clear_actors()
            self._actor = self._sel_actor = self._sel_cache = self.mesh = None
            self._repaint()
            return
        self.n_input = max(int(n_input or cloud.n), cloud.n)
        if new_input or self._actor is None:
            self.origin = cloud.xyz.mean(axis=0) if cloud.n else np.zeros(3)
        key = (cloud, self.n_input, self.budget)
        if self._lod[0] is None or self._lod[0][0] is not cloud or self._lod[0][1:] != key[1:]:
            self._lod = (key, display.display_subset(cloud.index, self.n_input, self.budget))
        idx = self._lod[1]
        if keep is not None:
            idx = np.flatnonzero(keep) if np.count_nonzero(keep) <= self.budget else idx[keep[idx]]
        self._shown_idx = idx
        self._draw(reset_camera=new_input or self._actor is None)

    def set_channel(self, channel: str):
        if self.cloud is not None and channel:
            self.channel = channel
            self._keep = False
            self._draw(reset_camera=False)

    def _draw(self, reset_camera: bool):
        import pyvista as pv

        c, idx = self.cloud, self._shown_idx
        keep = self._keep and self._clim is not None
        vals, title, self._unit, diverging = display.channel_display(
            c, self.channel, self._unit if keep else None, rows=idx)  # an edit keeps the unit
        if not keep:  # of all shown points, not the drawn ones: the map's and the report's limits
            self._clim = display.channel_limits(c, self.channel, self._unit, diverging, self.shown_mask)
        clim = self._clim
        # display only: VTK draws in float32, about the input's centre so mm detail survives
        poly = pv.PolyData((c.xyz[idx] - self.origin).astype(np.float32))
        poly[title] = vals.astype(np.float32)
        p = self.plotter
        if keep and not reset_camera and self.mesh is not None and self._actor is not None:
            # an edit (same input, channel, unit and colour limits): the drawn points change, the
            # actor, its colour map and scalar bar do not — new points into the same mesh (~5 ms)
            # instead of a new actor (~40 ms of pyvista's add_mesh at 200,000 points)
            self._hide_selection()
            self.mesh.copy_from(poly)
            self.mesh.set_active_scalars(title)
            self._info_and_repaint(c, idx)
            return
        p.suppress_rendering = True  # one render per update, not one per actor
        try:
            if self._actor is not None:
                p.remove_actor(self._actor, render=False)
            if self._sel_cache is not None:  # a new colour actor: the highlight is added after it
                p.remove_actor(self._sel_cache[0], render=False)
            self._sel_actor = self._sel_cache = None
            p.remove_scalar_bar() if p.scalar_bars else None
            big = idx.size > 100_000  # spheres cost ~1 s a frame per 10⁶ points in software GL
            self._big = big
            self._actor = p.add_mesh(poly, scalars=title, cmap="RdBu_r" if diverging else "viridis",
                                     clim=clim, point_size=2 if big else 5,
                                     render_points_as_spheres=not big, render=False, reset_camera=False,
                                     scalar_bar_args={"title": title, "vertical": True, "position_x": 0.82,
                                                      "position_y": 0.1, "width": 0.07, "height": 0.8,
                                                      "title_font_size": 14, "label_font_size": 12,
                                                      "fmt": "%.3g"})
            for bar in p.scalar_bars.values():  # the title clear of the top label ("1.71" touched
                bar.SetVerticalTitleSeparation(8)  # "residual (µm)": a review)
            if not self._axes:
                p.add_axes()
                self._axes = True
            if reset_camera:
                p.view_xy(render=False)  # optics are looked at along their axis
                p.reset_camera(render=False)
                # the data left of the colour bar (x ≥ 0.82 of the view), not under it: the
                # projection's centre moved right by a tenth of the view and the scene made
                # smaller — the bar hid a column of a 4 × 4 file and the right edge of every map
                cam = p.renderer.GetActiveCamera()
                cam.SetWindowCenter(0.2, 0.0)
                cam.Zoom(0.8)
        finally:
            p.suppress_rendering = False
        self.mesh = poly
        self._info_and_repaint(c, idx)

    def _info_and_repaint(self, c, idx):
        self.info.setText(drawn_text(idx.size, c.n if self.shown_mask is None
                                     else int(np.count_nonzero(self.shown_mask))))
        self._repaint()

    def highlight(self, mask):
        """Mark the selected points (drawn ones) in yellow on top of the colours."""
        import pyvista as pv

        self.mask = mask
        p = self.plotter
        self._hide_selection()
        if self.cloud is not None and mask is not None and np.any(mask):
            idx = self._shown_idx[mask[self._shown_idx]]
            if idx.size:
                poly = pv.PolyData((self.cloud.xyz[idx] - self.origin).astype(np.float32))
                if self._sel_cache is None:
                    # drawn as the colours are (spheres below 100,000 points) and larger: flat
                    # 4-pixel points lay inside the 5-pixel spheres at the same depth and were hidden
                    # — the example's selection never showed in 3D (a review)
                    actor = p.add_mesh(poly, color="#ffcc00", point_size=4 if self._big else 8,
                                       render_points_as_spheres=not self._big, render=False,
                                       reset_camera=False, pickable=False)
                    self._sel_cache = (actor, poly)
                else:  # the same actor with the new points: no new actor, no new shader
                    self._sel_cache[1].copy_from(poly)
                    self._sel_cache[0].SetVisibility(True)
                self._sel_actor = self._sel_cache[0]
        self._repaint()

    def _hide_selection(self):
        """Hide the selection's highlight (kept for the next one: adding an actor costs ~20 ms of
        pyvista and, the first time, a shader compiled by software GL)."""
        if self._sel_actor is not None:
            self._sel_actor.SetVisibility(False)
            self._sel_actor = None

    def _repaint(self):
        """Schedule one repaint: the widget's paint renders the scene. (Calling render() as well
        rendered every update twice — 0.1 s each for 200,000 points in software GL.)"""
        QtWidgets.QWidget.update(self.plotter.interactor)

    # -- selection through the view -------------------------------------------------------------------
    def _camera(self):
        w = self.plotter.interactor
        width, height = max(w.width(), 1), max(w.height(), 1)
        cam = self.plotter.renderer.GetActiveCamera()
        m = cam.GetCompositeProjectionTransformMatrix(width / height, -1, 1)
        return np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)]), width, height

    def _select(self, box_class, test) -> np.ndarray:
        """Mask over the cloud of the shown points whose projection ``test(sx, sy)`` accepts;
        ``box_class(sx0, sx1, sy0, sy1)`` decides whole cells of a CellIndex from their screen boxes."""
        matrix, width, height = self._camera()
        xyz, origin, keep = self.cloud.xyz, self.origin, self.shown_mask
        index = display.cell_index(self.cloud)
        if index is None:  # a small cloud: every point projected
            mask = test(*display.to_screen(xyz - origin, matrix, width, height))
            return mask if keep is None else mask & keep

        def boxes(ix):
            bx0, bx1, by0, by1, front = display.screen_boxes(ix.corners(origin), matrix, width, height)
            cls = box_class(bx0, bx1, by0, by1)
            cls[~front] = -1  # a box reaching behind the camera: its points one by one
            return cls
        return index.select(boxes, lambda pos: test(*display.to_screen(xyz[pos] - origin, matrix, width,
                                                                        height)), keep)

    def select_rectangle(self, x0, y0, x1, y1) -> np.ndarray:
        """Mask over the cloud of the shown points whose projection falls in the screen rectangle
        (pixels of the render widget, origin top-left)."""
        from pointspro.core.session import in_rectangle

        return self._select(lambda *b: display.rectangle_class(*b, x0, x1, y0, y1),
                            lambda sx, sy: in_rectangle(sx, sy, x0, x1, y0, y1))

    def select_lasso(self, polygon) -> np.ndarray:
        """Mask over the cloud of the shown points whose projection falls in the lasso (even-odd)."""
        from pointspro.plugins.aperture import points_in_polygon

        poly = np.asarray(polygon, dtype=np.float64)
        return self._select(lambda *b: display.polygon_class(*b, poly),
                            lambda sx, sy: points_in_polygon(sx, sy, poly))

    def eventFilter(self, obj, ev):
        mode = self.mode.currentText()
        if mode == "rotate" or self.cloud is None:
            return False
        t = ev.type()
        if t == QtCore.QEvent.MouseButtonPress and ev.button() == QtCore.Qt.LeftButton:
            self._drag = [ev.position()]
            self.overlay.setGeometry(self.plotter.interactor.geometry())
            self.overlay.rect = mode == "select rectangle"
            self.overlay.path = self._drag
            self.overlay.show()
            self.overlay.raise_()
            return True
        if t == QtCore.QEvent.MouseMove and self._drag is not None:
            if mode == "select rectangle":
                self._drag[1:] = [ev.position()]
            else:
                self._drag.append(ev.position())
            self.overlay.update()
            return True
        if t == QtCore.QEvent.MouseButtonRelease and self._drag is not None:
            pts, self._drag = self._drag + [ev.position()], None
            self.overlay.hide()
            if mode == "select rectangle":
                mask = self.select_rectangle(pts[0].x(), pts[0].y(), pts[-1].x(), pts[-1].y())
            elif len(pts) >= 3:
                mask = self.select_lasso([(p.x(), p.y()) for p in pts])
            else:
                return True
            self.selected.emit(mask)
            return True
        return False
