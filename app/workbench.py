"""The optician's workbench: the pipeline dock, the 2D map with selection, undo/redo, projects and a
worker thread, around core.session.Session (the model; this module only renders it and forwards the
user's actions).

Steps run in a QThread with the core's Progress (its sink emits a signal to the progress bar; Cancel
sets the token the steps check), so the event loop keeps turning while a step computes.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from pointspro.core.errors import PointsProError
from pointspro.core.session import Session

DATA_FILTER = "Measurements (*.csv *.txt *.xyz *.asc *.dat *.ply *.pcd *.pts *.datx *.sur *.sdf *.x3p)"


def autosave_path() -> Path:
    base = os.environ.get("POINTSPRO_AUTOSAVE_DIR") or QtCore.QStandardPaths.writableLocation(
        QtCore.QStandardPaths.AppDataLocation) or str(Path.home() / ".pointspro")
    return Path(base) / "autosave.pointspro.yaml"


class RunWorker(QtCore.QObject):
    progressed = QtCore.Signal(float, str)
    finished = QtCore.Signal(object)
    failed = QtCore.Signal(str)

    def __init__(self, session: Session, upto: int | None):
        super().__init__()
        from pointspro.core.progress import CancelToken

        self.session, self.upto, self.token = session, upto, CancelToken()

    @QtCore.Slot()
    def run(self):
        from pointspro.core.errors import Cancelled
        from pointspro.core.progress import Progress

        try:
            res = self.session.run(self.upto, progress=Progress(lambda f, m: self.progressed.emit(f, m),
                                                                self.token))
            self.finished.emit(res)
        except Cancelled:
            self.failed.emit("cancelled")
        except PointsProError as e:
            self.failed.emit(str(e))
        except Exception as e:  # a bug: say it in the log, keep the window
            self.failed.emit(f"internal error: {type(e).__name__}: {e}")


class PipelineDock(QtWidgets.QDockWidget):
    def __init__(self, win):
        super().__init__("Pipeline", win)
        from pointspro.core.registry import Registry

        self.win = win
        self.registry = Registry()  # reading the entry points costs ~0.2 s: once
        w = QtWidgets.QWidget()
        lay = QtWidgets.QVBoxLayout(w)
        self.list = QtWidgets.QListWidget()
        lay.addWidget(self.list, 1)
        row = QtWidgets.QHBoxLayout()
        self.add_combo = QtWidgets.QComboBox()
        self.add_combo.addItems(self.registry.ids())
        add = QtWidgets.QPushButton("Add")
        add.clicked.connect(lambda: win.act(lambda: win.session.add_step(self.add_combo.currentText())))
        row.addWidget(self.add_combo, 1)
        row.addWidget(add)
        lay.addLayout(row)
        row = QtWidgets.QHBoxLayout()
        for text, fn in (("Remove", self._remove), ("Up", lambda: self._move(-1)), ("Down", lambda: self._move(1))):
            b = QtWidgets.QPushButton(text)
            b.clicked.connect(fn)
            row.addWidget(b)
        lay.addLayout(row)
        self.form = QtWidgets.QFormLayout()
        box = QtWidgets.QGroupBox("Parameters")
        box.setLayout(self.form)
        lay.addWidget(box)
        self.apply = QtWidgets.QPushButton("Apply parameters")
        self.apply.clicked.connect(self._apply)
        lay.addWidget(self.apply)
        row = QtWidgets.QHBoxLayout()
        self.run_all = QtWidgets.QPushButton("Run all")
        self.run_all.clicked.connect(lambda: win.start_run(None))
        self.run_to = QtWidgets.QPushButton("Run to selected")
        self.run_to.clicked.connect(lambda: win.start_run(self.list.currentRow() + 1))
        self.cancel = QtWidgets.QPushButton("Cancel")
        self.cancel.setEnabled(False)
        self.cancel.clicked.connect(lambda: win.cancel_run())
        for b in (self.run_all, self.run_to, self.cancel):
            row.addWidget(b)
        lay.addLayout(row)
        self.bar = QtWidgets.QProgressBar()
        self.bar.setRange(0, 1000)
        lay.addWidget(self.bar)
        self.setWidget(w)
        self.list.currentRowChanged.connect(self._show_form)
        self.list.itemChanged.connect(self._toggled)
        self.fields = {}

    def refresh(self):
        self.list.blockSignals(True)
        row = self.list.currentRow()
        self.list.clear()
        for s in self.win.session.steps:
            sid = next(k for k in s if k != "enabled")
            it = QtWidgets.QListWidgetItem(sid)
            it.setFlags(it.flags() | QtCore.Qt.ItemIsUserCheckable)
            it.setCheckState(QtCore.Qt.Unchecked if s.get("enabled") is False else QtCore.Qt.Checked)
            self.list.addItem(it)
        self.list.blockSignals(False)
        if self.list.count():
            self.list.setCurrentRow(min(max(row, 0), self.list.count() - 1))
        self._show_form(self.list.currentRow())

    def _show_form(self, i):
        import yaml

        from pointspro.core.forms import form_fields

        while self.form.rowCount():
            self.form.removeRow(0)
        self.fields = {}
        if i < 0 or i >= len(self.win.session.steps):
            return
        entry = self.win.session.steps[i]
        sid = next(k for k in entry if k != "enabled")
        cls = self.registry.load(sid)
        values = entry[sid] or {}
        for f in form_fields(cls.Params):
            edit = QtWidgets.QLineEdit()
            if f.key in values and isinstance(values[f.key], list) and len(values[f.key]) > 50:
                # thousands of deleted rows are not for a text field: shown, kept, not edited here
                edit.setPlaceholderText(f"{len(values[f.key]):,} values (kept; edit the recipe file)")
                edit.setEnabled(False)
                edit.setProperty("keep", values[f.key])
            elif f.key in values:
                edit.setText(yaml.safe_dump(values[f.key], default_flow_style=True).strip().removesuffix("..."
                                                                                                       ).strip())
            else:
                edit.setPlaceholderText("" if f.default is None else str(f.default))
            tip = f.help + (f" [{f.unit}]" if f.unit else "") + (f" ({f.bounds_text()})" if f.bounds_text() else "")
            edit.setToolTip(tip)
            self.form.addRow(f.key + (f" [{f.unit}]" if f.unit else ""), edit)
            self.fields[f.key] = edit

    def _apply(self):
        import yaml

        i = self.list.currentRow()
        if i < 0:
            return
        params = {}
        for k, edit in self.fields.items():
            edit.setStyleSheet("")
            if not edit.isEnabled():
                params[k] = edit.property("keep")
                continue
            t = edit.text().strip()
            if t:
                params[k] = yaml.safe_load(t)
        try:
            self.win.session.set_params(i, params)
        except PointsProError as e:
            msg = str(e)
            for k, edit in self.fields.items():
                if f"key '{k}'" in msg:
                    edit.setStyleSheet("background:#ffd6d6")
                    edit.setToolTip(msg)
            self.win.log(f"invalid: {msg}")

    def _remove(self):
        i = self.list.currentRow()
        if i >= 0:
            self.win.act(lambda: self.win.session.remove_step(i))

    def _move(self, d):
        i = self.list.currentRow()
        j = i + d
        if 0 <= i < self.list.count() and 0 <= j < self.list.count():
            self.win.act(lambda: self.win.session.move_step(i, j))
            self.list.setCurrentRow(j)

    def _toggled(self, item):
        i = self.list.row(item)
        self.win.act(lambda: self.win.session.set_enabled(i, item.checkState() == QtCore.Qt.Checked))


class MapDock(QtWidgets.QDockWidget):
    """The 2D map (the report's figure) with rectangle and lasso selection, and the threshold tool."""

    def __init__(self, win):
        super().__init__("2D map and selection", win)
        self.win = win
        self.mask = None
        w = QtWidgets.QWidget()
        self.lay = QtWidgets.QVBoxLayout(w)
        tools = QtWidgets.QHBoxLayout()
        self.mode = QtWidgets.QComboBox()
        self.mode.addItems(["rectangle", "lasso"])
        self.mode.currentTextChanged.connect(lambda _: self.redraw())
        tools.addWidget(QtWidgets.QLabel("Select:"))
        tools.addWidget(self.mode)
        self.info = QtWidgets.QLabel("nothing selected")
        tools.addWidget(self.info, 1)
        dele = QtWidgets.QPushButton("Delete selection")
        dele.clicked.connect(lambda: win.delete_selection())
        tools.addWidget(dele)
        self.lay.addLayout(tools)
        th = QtWidgets.QHBoxLayout()
        self.th_channel = QtWidgets.QComboBox()
        self.slider = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.slider.setRange(0, 1000)
        self.slider.setValue(1000)
        self.slider.valueChanged.connect(self._threshold)
        th.addWidget(QtWidgets.QLabel("Threshold on"))
        th.addWidget(self.th_channel)
        th.addWidget(self.slider, 1)
        self.lay.addLayout(th)
        self.canvas = None
        self.setWidget(w)

    def redraw(self):
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
        from matplotlib.widgets import LassoSelector, RectangleSelector

        from pointspro.core.figures import scattered_map

        c = self.win.session.shown
        if c is None:
            return
        ch = "residual" if "residual" in c.channels else None
        v = c[ch] if ch else c.z - c.z.mean()
        fig = scattered_map(c.x, c.y, v, title=f"{ch or 'z − mean'} ({c.n} points)")
        canvas = FigureCanvasQTAgg(fig)
        canvas.setMinimumSize(380, 320)
        if self.canvas is not None:
            self.lay.removeWidget(self.canvas)
            self.canvas.deleteLater()
        self.canvas = canvas
        self.lay.insertWidget(0, canvas, 1)
        ax = fig.axes[0]
        if self.mode.currentText() == "rectangle":
            self.selector = RectangleSelector(ax, self._rect, useblit=False, interactive=False)
        else:
            self.selector = LassoSelector(ax, self._lasso)
        names = [n for n in c.column_names if n not in ("x", "y", "index")]
        cur = self.th_channel.currentText()
        self.th_channel.blockSignals(True)
        self.th_channel.clear()
        self.th_channel.addItems(names)
        if cur in names:
            self.th_channel.setCurrentText(cur)
        elif "omega" in names:
            self.th_channel.setCurrentText("omega")
        self.th_channel.blockSignals(False)
        self.set_mask(None)

    def _rect(self, press, release):
        self.set_mask(self.win.session.select_rectangle(press.xdata, release.xdata, press.ydata, release.ydata))

    def _lasso(self, verts):
        self.set_mask(self.win.session.select_lasso(verts))

    def _threshold(self, pos):
        c = self.win.session.shown
        name = self.th_channel.currentText()
        if c is None or not name:
            return
        v = c.z if name == "z" else c[name]
        value = float(np.quantile(v, pos / 1000.0))
        self.set_mask(self.win.session.select_threshold(name, value) if pos < 1000 else None,
                      f" above {name} = {value:.4g}")

    def set_mask(self, mask, how=""):
        self.mask = mask
        n = 0 if mask is None else int(np.sum(mask))
        self.info.setText(f"{n} point(s) selected{how}" if n else "nothing selected")


def install(win, plotter_show):
    """Add the workbench to the first-cut window: session, docks, menus, drag and drop, autosave."""
    win.session = Session()
    win.setAcceptDrops(True)
    win.pipeline = PipelineDock(win)
    win.map = MapDock(win)
    win.addDockWidget(QtCore.Qt.LeftDockWidgetArea, win.pipeline)
    win.addDockWidget(QtCore.Qt.RightDockWidgetArea, win.map)
    win._thread = None

    def log(msg):
        win.log_widget.appendPlainText(msg)
    win.log = log

    def refresh(what=""):
        win.pipeline.refresh()
        win.map.redraw()
        plotter_show(win.session.shown)
        win.undo_action.setEnabled(win.session.can_undo)
        win.redo_action.setEnabled(win.session.can_redo)
        if what and what != "opened":
            try:
                win.session.autosave(autosave_path())
            except OSError:
                pass
    win.session.listeners.append(lambda what: refresh(what))
    win.refresh = refresh

    def act(fn):
        try:
            fn()
        except PointsProError as e:
            log(f"error: {e}")
            QtWidgets.QMessageBox.warning(win, "PointsPro", str(e)) if not os.environ.get("POINTSPRO_NO_DIALOGS") \
                else None
    win.act = act

    def delete_selection():
        m = win.map.mask
        if m is None or not np.any(m):
            log("nothing selected")
            return
        act(lambda: log(f"deleted {win.session.delete(m)} point(s)"))
    win.delete_selection = delete_selection

    def start_run(upto):
        if win._thread is not None:
            return
        worker = RunWorker(win.session, upto)
        thread = QtCore.QThread(win)
        worker.moveToThread(thread)
        thread.started.connect(worker.run)
        worker.progressed.connect(lambda f, m: (win.pipeline.bar.setValue(int(f * 1000)),
                                                win.pipeline.bar.setFormat(f"{m} %p%")))

        def done(res=None, err=None):
            thread.quit()
            thread.wait()
            win._thread = win._worker = None
            win.pipeline.cancel.setEnabled(False)
            win.pipeline.run_all.setEnabled(True)
            if err:
                log(f"run: {err}")
            else:
                log(f"ran {len(res.steps)} step(s): {res.cloud.n} points")
                win.last_report = res
        worker.finished.connect(lambda res: done(res=res))
        worker.failed.connect(lambda msg: done(err=msg))
        win._thread, win._worker = thread, worker
        win.pipeline.cancel.setEnabled(True)
        win.pipeline.run_all.setEnabled(False)
        thread.start()
    win.start_run = start_run
    win.cancel_run = lambda: win._worker and win._worker.token.cancel()

    # menus
    mb = win.menuBar()
    fm = mb.addMenu("&File")

    def open_any(path: str):
        p = Path(path)
        if p.name.endswith((".pointspro.yaml", ".pointspro")):
            act(lambda: win.session.open_project(p))
        elif p.suffix in (".yaml", ".yml"):
            act(lambda: win.session.load_recipe(p))
        else:
            act(lambda: win.session.open(p))
        recent = win.settings.value("recent", []) or []
        recent = [str(p)] + [r for r in recent if r != str(p)]
        win.settings.setValue("recent", recent[:10])
    win.open_any = open_any
    win.settings = QtCore.QSettings("PointsPro", "PointsPro")
    for text, filt in (("Open data…", DATA_FILTER), ("Open recipe…", "Recipes (*.yaml *.yml)"),
                       ("Open project…", "Projects (*.pointspro.yaml)")):
        a = fm.addAction(text)
        a.triggered.connect(lambda _=False, f=filt: (lambda p: p and open_any(p))(
            QtWidgets.QFileDialog.getOpenFileName(win, "Open", "", f)[0]))
    recent_menu = fm.addMenu("Recent files")
    recent_menu.aboutToShow.connect(lambda: (recent_menu.clear(), [recent_menu.addAction(
        r, lambda r=r: open_any(r)) for r in (win.settings.value("recent", []) or [])]))
    a = fm.addAction("Save project…")
    a.triggered.connect(lambda: (lambda p: p and act(lambda: win.session.save_project(p)))(
        QtWidgets.QFileDialog.getSaveFileName(win, "Save project", "", "Projects (*.pointspro.yaml)")[0]))
    a = fm.addAction("Export cloud…")
    a.triggered.connect(lambda: (lambda p: p and act(lambda: win.session.export_cloud(p)))(
        QtWidgets.QFileDialog.getSaveFileName(win, "Export cloud", "", "Clouds (*.csv *.ply)")[0]))
    em = mb.addMenu("&Edit")
    win.undo_action = em.addAction("Undo", win.session.undo)
    win.undo_action.setShortcut(QtGui.QKeySequence("Ctrl+Z"))
    win.redo_action = em.addAction("Redo", win.session.redo)
    win.redo_action.setShortcut(QtGui.QKeySequence("Ctrl+Shift+Z"))
    d = em.addAction("Delete selection", delete_selection)
    d.setShortcut(QtGui.QKeySequence(QtCore.Qt.Key_Delete))
    em.addAction("Restore all deleted points", lambda: act(win.session.restore_all))

    def drag_enter(e):
        if e.mimeData().hasUrls():
            e.acceptProposedAction()

    def drop(e):
        for u in e.mimeData().urls():
            open_any(u.toLocalFile())
    win.dragEnterEvent = drag_enter
    win.dropEvent = drop
    return win
