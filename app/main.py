"""The window: a 3D view of measurement files coloured by any channel.

This is the first cut of the desktop application (issue "The desktop application" builds the
pipeline dock, 2D maps, selection and undo on top). It reads files with the core's readers and never
computes anything itself.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

# Signed deviations (mm): shown in µm on a diverging map centred on zero.
DEVIATION_CHANNELS = ("residual", "probe_residual", "distance", "gap")
# Non-negative deviations (mm): shown in µm on a sequential map.
MAGNITUDE_CHANNELS = ("omega",)


def _scalars(cloud, name: str) -> tuple[np.ndarray, str, bool]:
    """(values to colour by, colour-bar title, diverging?) — float32 for display only."""
    if name in DEVIATION_CHANNELS or name in MAGNITUDE_CHANNELS:
        um = (np.asarray(cloud[name]) * 1e3).astype(np.float32)  # display only
        return um, f"{name} (µm)", name in DEVIATION_CHANNELS
    v = np.asarray(cloud[name], dtype=np.float64)
    if name in ("x", "y", "z"):
        return (v - v.mean()).astype(np.float32), f"{name} − mean (mm)", False  # display only
    return v.astype(np.float32), name, False  # display only


def build_window(files: list[Path]):
    from PySide6 import QtCore, QtWidgets
    from pyvistaqt import QtInteractor

    from pointspro.core.errors import PointsProError
    from pointspro.core.io import read_cloud

    win = QtWidgets.QMainWindow()
    win.setWindowTitle("PointsPro" + (f" — {files[0].name}" if files else ""))
    win.resize(1280, 800)
    central = QtWidgets.QWidget()
    layout = QtWidgets.QVBoxLayout(central)
    bar = QtWidgets.QHBoxLayout()
    bar.addWidget(QtWidgets.QLabel("Colour by:"))
    combo = QtWidgets.QComboBox()
    bar.addWidget(combo)
    info = QtWidgets.QLabel()
    bar.addWidget(info, 1)
    layout.addLayout(bar)
    plotter = QtInteractor(central)
    layout.addWidget(plotter.interactor, 1)
    win.setCentralWidget(central)
    log = QtWidgets.QPlainTextEdit(readOnly=True)
    dock = QtWidgets.QDockWidget("Log", win)
    dock.setWidget(log)
    dock.setMaximumHeight(120)
    win.addDockWidget(QtCore.Qt.BottomDockWidgetArea, dock)

    # the report's figures, drawn by the same core.figures functions (matplotlib in a Qt canvas)
    fig_dock = QtWidgets.QDockWidget("Form-error map (as in the report)", win)
    fig_holder = QtWidgets.QWidget()
    fig_layout = QtWidgets.QVBoxLayout(fig_holder)
    fig_layout.setContentsMargins(0, 0, 0, 0)
    fig_dock.setWidget(fig_holder)
    win.addDockWidget(QtCore.Qt.RightDockWidgetArea, fig_dock)
    fig_dock.setVisible(False)

    clouds = []
    win.log_widget = log

    def show(name: str):
        import pyvista as pv

        plotter.clear_actors()
        for c in clouds:
            if name not in ("x", "y", "z") and name not in c.channels:
                continue
            vals, title, diverging = _scalars(c, name)
            # display only: VTK draws in float32; the exaggerated z makes form error visible
            pts = np.asarray(c.xyz - c.xyz.mean(axis=0)).astype(np.float32)
            poly = pv.PolyData(pts)
            poly[title] = vals
            clim = None
            if diverging:
                # centred on zero and robust: a few spikes saturate instead of washing the map out
                lo, hi = np.percentile(vals, [0.5, 99.5])
                m = float(max(abs(lo), abs(hi))) or 1.0
                clim = (-m, m)
            big = c.n > 200_000  # spheres cost ~1 s a frame per 10⁶ points in software GL
            plotter.add_mesh(poly, scalars=title, cmap="RdBu_r" if diverging else "viridis", clim=clim,
                             point_size=2 if big else 6, render_points_as_spheres=not big,
                             scalar_bar_args={"title": title, "vertical": True}, render=False,
                             reset_camera=False)
        if not getattr(plotter, "_pp_axes", False):
            plotter.add_axes()
            plotter._pp_axes = True
        show_figure(name)
        plotter.view_xy(render=False)  # optics are looked at along their axis
        plotter.reset_camera(render=False)
        plotter.render()
        if clouds:
            info.setText(f"{sum(c.n for c in clouds)} points")

    def show_figure(name: str):
        if not clouds or name not in DEVIATION_CHANNELS:
            fig_dock.setVisible(False)
            return
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg

        from pointspro.core.figures import scattered_map

        c = clouds[0]
        canvas = FigureCanvasQTAgg(scattered_map(c.x, c.y, c[name], title=f"{name} ({c.n} points)"))
        canvas.setMinimumWidth(420)
        while fig_layout.count():
            old = fig_layout.takeAt(0).widget()
            if old is not None:
                old.deleteLater()
        fig_layout.addWidget(canvas)
        fig_dock.setVisible(True)
        win.resizeDocks([fig_dock], [480], QtCore.Qt.Horizontal)
        win.figure_canvas = canvas

    def names_of(cloud):
        rest = [n for n in cloud.column_names if n not in ("x", "y", "z", "index")]
        # a form-error map is what an optician opens a processed cloud for: residual first when present
        return (["residual"] if "residual" in rest else []) + ["z"] + [n for n in rest if n != "residual"] \
            + ["x", "y"]

    def plotter_show(cloud):
        """Show the session's current cloud (called on every model event)."""
        clouds[:] = [] if cloud is None else [cloud]
        if cloud is None:
            return
        names = names_of(cloud)
        cur = combo.currentText()
        combo.blockSignals(True)
        combo.clear()
        combo.addItems(names)
        combo.setCurrentText(cur if cur in names else names[0])
        combo.blockSignals(False)
        show(combo.currentText())

    combo.currentTextChanged.connect(lambda name: name and clouds and show(name))
    from .workbench import install

    install(win, plotter_show)
    win.tabifyDockWidget(fig_dock, win.map)
    for f in files[:1]:
        win.open_any(str(f))
        if win.session.shown is not None:
            log.appendPlainText(f"read {f}: {win.session.shown.n} points, channels "
                                f"{sorted(win.session.shown.channels)}")
    for f in files[1:]:
        log.appendPlainText(f"{f}: one measurement at a time — open it after this one")
    win.plotter = plotter  # keep a reference for tests and screenshots
    return win


def run_window(files: list[Path], screenshot: str | None = None) -> int:
    from PySide6 import QtWidgets

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    if screenshot:
        import os

        os.environ["POINTSPRO_NO_DIALOGS"] = "1"  # a render for a picture never waits for a click
    win = build_window(files)
    win.show()
    if screenshot:
        for _ in range(5):
            app.processEvents()
        win.plotter.render()
        app.processEvents()
        screen = win.screen() or app.primaryScreen()
        img = screen.grabWindow(win.winId())
        if img.isNull() or not img.save(str(screenshot)):
            win.grab().save(str(screenshot))
        win.plotter.close()
        win.close()
        # destroy the widgets (and the matplotlib canvas) while the QApplication still exists
        win.figure_canvas = None
        win.deleteLater()
        app.sendPostedEvents(None, 0)
        app.processEvents()
        return 0
    return app.exec()
