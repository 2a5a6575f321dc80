"""The main window: composes the views and panels around core.session.Session (the model) and turns
the optician's actions into session calls. It computes nothing itself.

Layout: the 3D view in the centre; the 2D map (selection, profile cuts, threshold) on the right; the
pipeline on the left; log, report and Explain tabbed at the bottom. Selection is shared by the two
views (a mask over the shown cloud); Delete records it as a `manual_edit` step.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from pointspro.core.errors import PointsProError
from pointspro.core.session import CHANGES, Session
from pointspro.core.units import format_length

from . import display
from .explain_panel import ExplainPanel
from .mapview import MapView
from .pipeline_dock import PipelineDock
from .report_panel import ReportPanel
from .view3d import View3D
from .worker import Worker


def _data_filter() -> str:
    """Every extension the readers know (core.io.formats.READ_SUFFIXES: point clouds and every
    SurfaceTopography map format), then all files — the reader goes by content, not by extension."""
    from pointspro.core.io.formats import READ_SUFFIXES

    return ("Measurements (" + " ".join(f"*{s}" for s in READ_SUFFIXES) + ");;All files (*)")


DATA_FILTER = _data_filter()
AUTOSAVE_DELAY_MS = 1500


def autosave_path() -> Path:
    base = os.environ.get("POINTSPRO_AUTOSAVE_DIR") or QtCore.QStandardPaths.writableLocation(
        QtCore.QStandardPaths.AppDataLocation) or str(Path.home() / ".pointspro")
    return Path(base) / "autosave.pointspro.yaml"


def unsaved_session_path() -> Path:
    """Where a session that did not close normally waits, beside the autosave (the same folder: the
    project's relative input path still holds), until it is restored or discarded."""
    return autosave_path().with_name("unsaved-session.pointspro.yaml")


def _dialogs() -> bool:
    return not os.environ.get("POINTSPRO_NO_DIALOGS")


class MainWindow(QtWidgets.QMainWindow):
    def __init__(self):
        super().__init__()
        self.setWindowTitle("PointsPro")
        self.resize(1280, 800)
        self.setAcceptDrops(True)
        self.session = Session()
        self._sel = None  # the selection: a mask over the views' cloud (self._shown)
        self.last_report = None
        self._report_recipe = None
        self._shown = None  # the cloud the views draw (session.view) and the mask of its points shown
        self._keep = None
        ini = os.environ.get("POINTSPRO_SETTINGS")  # tests keep their recent-files list apart
        self.settings = QtCore.QSettings(ini, QtCore.QSettings.IniFormat) if ini else \
            QtCore.QSettings("PointsPro", "PointsPro")

        # colour-by, shared by both views
        bar = self.addToolBar("View")
        bar.setObjectName("view_toolbar")
        bar.addWidget(QtWidgets.QLabel(" Colour by: "))
        self.channel = QtWidgets.QComboBox()
        self.channel.setMinimumWidth(140)
        self.channel.currentTextChanged.connect(self._channel_changed)
        bar.addWidget(self.channel)
        self.sel_label = QtWidgets.QLabel("")
        bar.addWidget(self.sel_label)

        # restore banner (an unsaved session found at start-up)
        central = QtWidgets.QWidget()
        clay = QtWidgets.QVBoxLayout(central)
        clay.setContentsMargins(0, 0, 0, 0)
        self.banner = QtWidgets.QFrame()
        self.banner.setStyleSheet("QFrame{background:#fff4cc}")
        blay = QtWidgets.QHBoxLayout(self.banner)
        self.banner_text = QtWidgets.QLabel()
        # wrapped: as one line its ~800 px set the centre's minimum width, the window grew past its
        # 1280 px and the map dock was squeezed to 320 px, its y-axis label cut off
        self.banner_text.setWordWrap(True)
        blay.addWidget(self.banner_text, 1)
        b = QtWidgets.QPushButton("Restore")
        b.clicked.connect(self.restore_autosave)
        blay.addWidget(b)
        b = QtWidgets.QPushButton("Discard")
        b.clicked.connect(self.discard_autosave)
        blay.addWidget(b)
        self.banner.hide()
        clay.addWidget(self.banner)
        self.view3d = View3D(central)
        clay.addWidget(self.view3d, 1)
        self.setCentralWidget(central)
        self.plotter = self.view3d.plotter

        self.map = MapView()
        self.map_dock = self._dock("2D map", self.map, QtCore.Qt.RightDockWidgetArea)
        self.pipeline = PipelineDock(self)
        self.addDockWidget(QtCore.Qt.LeftDockWidgetArea, self.pipeline)
        self.log_widget = QtWidgets.QPlainTextEdit(readOnly=True)
        log_dock = self._dock("Log", self.log_widget, QtCore.Qt.BottomDockWidgetArea)
        self.report = ReportPanel()
        self.report_dock = self._dock("Report", self.report, QtCore.Qt.BottomDockWidgetArea)
        self.explain = ExplainPanel(self.session)
        self.explain.log.connect(self.log)
        self.explain.result_shown.connect(self._room_for_explain)
        self.explain_dock = self._dock("Explain", self.explain, QtCore.Qt.BottomDockWidgetArea)
        self.tabifyDockWidget(log_dock, self.report_dock)
        self.tabifyDockWidget(self.report_dock, self.explain_dock)
        log_dock.raise_()
        # the side docks run the full height; log/report/Explain sit under the 3D view
        self.setCorner(QtCore.Qt.BottomRightCorner, QtCore.Qt.RightDockWidgetArea)
        self.setCorner(QtCore.Qt.BottomLeftCorner, QtCore.Qt.LeftDockWidgetArea)
        self._log_dock = log_dock
        self._sized = False

        self.view3d.selected.connect(self.set_selection)
        self.map.selected.connect(self.set_selection)
        self.runner = Worker(self)
        self.runner.progressed.connect(self._progress)
        self.runner.done.connect(self._ran)
        self.runner.failed.connect(self._run_failed)
        self.exporter = Worker(self)
        self.exporter.done.connect(lambda msg: self.log(msg))
        self.exporter.failed.connect(lambda msg: self.log(f"error: {msg}"))
        self._autosave_timer = QtCore.QTimer(self, singleShot=True, interval=AUTOSAVE_DELAY_MS)
        self._autosave_timer.timeout.connect(self.autosave_now)
        self._autosave_thread = None
        for name in CHANGES:
            self.session.events[name].connect(self._on_session)
        self.session.events.warning.connect(self._session_warning)
        self._menus()
        self._offer_restore()

    def _dock(self, title, widget, area):
        d = QtWidgets.QDockWidget(title, self)
        d.setObjectName(title)
        d.setWidget(widget)
        self.addDockWidget(area, d)
        return d

    # -- messages -----------------------------------------------------------------------------------
    def log(self, msg: str) -> None:
        self.log_widget.appendPlainText(msg)
        self.statusBar().showMessage(msg.splitlines()[0] if msg else "", 8000)

    def act(self, fn):
        """Run a model action; a PointsProError becomes one message (log, status bar and, outside
        tests, a dialog) and the session is left as it was."""
        try:
            return fn()
        except PointsProError as e:
            self.log(f"error: {e}")
            if _dialogs():
                QtWidgets.QMessageBox.warning(self, "PointsPro", str(e))
        except OSError as e:
            self.log(f"error: {e.filename or ''}: {e.strerror or e}")
            if _dialogs():
                QtWidgets.QMessageBox.warning(self, "PointsPro", f"{e.filename or ''}: {e.strerror or e}")
        return None

    # -- the model changed ----------------------------------------------------------------------------
    def _session_warning(self, event) -> None:
        """The model says something that went wrong although the action did not fail (e.g. a project
        that opened but whose recipe did not run): shown like an error of an action."""
        self.log(f"warning: {event.value}")
        if _dialogs():
            QtWidgets.QMessageBox.warning(self, "PointsPro", str(event.value))

    def _on_session(self, event) -> None:
        s = self.session
        what = event.type
        if what == "opened":
            # the last run was of the measurement open before: shown stale, never exported as this
            # one's (a review: Export report wrote the old file's RMS under the new file's name);
            # dropped before the forms are refreshed, whose "auto" fields read it ("last run:
            # 80.43 mm" of the asphere stood beside a 0.7 mm MetroPro map — a review)
            self.last_report = None
            self.pipeline.bar.setValue(0)
            self.pipeline.bar.setFormat("")
        self.pipeline.refresh()
        base, keep = s.view
        if base is not self._shown or keep is not self._keep:
            self._show_cloud(new_input=what == "opened", edit=what in ("deleted", "undo", "redo"))
        self.undo_action.setEnabled(s.can_undo)
        self.redo_action.setEnabled(s.can_redo)
        if what == "opened" and s.input_path is not None:
            self.setWindowTitle(f"PointsPro — {s.input_path.name}")
        if what != "opened" or s.steps:
            self._autosave_timer.start()
        if what == "opened":
            self.report.set_stale("another measurement was opened")
        if what == "deleted":
            self.report.set_stale("points were deleted")
        elif what in ("steps", "recipe", "restored", "undo", "redo") and not self.runner.busy:
            self.report.set_stale("the recipe or the points changed")

    def _show_cloud(self, new_input: bool, edit: bool = False) -> None:
        s = self.session
        c, shown_mask = self._shown, self._keep = s.view
        self._sel = None
        self.sel_label.setText("")
        self.map.reset_threshold()  # no selection: nor the threshold's (it said "44 points" after they went)
        if c is None:
            return
        display.prepare_cell_index(c)  # for the first selection, in a thread
        names = display.channel_order(c)
        before = {self.channel.itemText(i) for i in range(self.channel.count())}
        cur = self.channel.currentText()
        # a run that produced the first residual shows it: the form error is what the run was for
        fresh_residual = "residual" in names and "residual" not in before
        keep = cur in names and not new_input and not fresh_residual
        self.channel.blockSignals(True)
        self.channel.clear()
        self.channel.addItems(names)
        self.channel.setCurrentText(cur if keep else names[0])
        self.channel.blockSignals(False)
        ch = self.channel.currentText()
        n_input = s.input_cloud.n if s.input_cloud is not None else c.n
        self.map.set_cloud(c, ch, new_input=new_input, keep_limits=edit, keep=shown_mask)
        self.view3d.set_cloud(c, ch, n_input=n_input, new_input=new_input, keep_limits=edit,
                              keep=shown_mask)

    def _channel_changed(self, name: str) -> None:
        if name and self._shown is not None:
            self.map.set_cloud(self._shown, name, keep=self._keep)
            self.view3d.set_channel(name)
            self.set_selection(self._sel)

    # -- selection and cleanup ------------------------------------------------------------------------
    @property
    def selection(self):
        """The selected points: a boolean mask over the shown cloud (session.shown), or None."""
        if self._sel is None or self._keep is None:
            return self._sel
        return self._sel[self._keep]

    def set_selection(self, mask) -> None:
        """``mask`` over the shown cloud, or over the views' cloud (session.view: what the views
        select in, at full resolution, without a copy per deletion)."""
        if mask is not None:
            mask = np.asarray(mask, dtype=bool)
            if self._shown is None:
                return
            keep = self._keep
            if mask.shape == (self._shown.n,):
                if keep is not None:
                    mask = mask & keep
            elif keep is not None and mask.shape == (int(np.count_nonzero(keep)),):
                full = np.zeros(self._shown.n, dtype=bool)
                full[keep] = mask
                mask = full
            else:
                return
            if not mask.any():
                mask = None
        self._sel = mask
        n = 0 if mask is None else int(np.count_nonzero(mask))
        self.sel_label.setText(f"   {n:,} point(s) selected — Delete removes them" if n else "")
        self.view3d.highlight(mask)
        self.map.highlight(mask)

    def delete_selection(self) -> None:
        m = self._sel
        if m is None or not np.any(m):
            self.log("nothing selected")
            return
        if self.runner.busy:
            # the run's result would replace the view and bring the points back, the step left in the
            # recipe (a review: 800 points deleted during a run reappeared when it finished)
            self.log("a run is in progress: delete after it finishes (or Cancel it)")
            return
        n = self.act(lambda: self.session.delete(m))
        if n:
            self.log(f"deleted {n:,} point(s) (recorded as a manual_edit step before the others); the "
                     "steps' figures and the report are from before the deletion: Run all to update them")

    # -- running ------------------------------------------------------------------------------------
    def start_run(self, upto):
        if self.runner.busy:
            return
        if self.session.input_cloud is None:
            self.log("run: open a measurement first")
            return
        session = self.session
        self.pipeline.cancel.setEnabled(True)
        self.pipeline.run_all.setEnabled(False)
        self.pipeline.run_to.setEnabled(False)

        def job(progress):
            res = session.compute(upto, progress=progress)
            res.summary()  # the metrics fit a map: in the worker, not in the GUI thread
            return res
        self._run_recipe = session.recipe  # what the run computes (Recipe edits make new objects)
        self._run_input = session.input_cloud  # and of which measurement (another opened meanwhile)
        self.runner.start(job)

    def cancel_run(self):
        self.runner.cancel()

    @property
    def _thread(self):  # for tests: a run is under way
        return self.runner._thread

    def _progress(self, f, m):
        self.pipeline.bar.setValue(int(f * 1000))
        self.pipeline.bar.setFormat(f"{m} %p%")

    def _run_ended(self):
        self.pipeline.cancel.setEnabled(False)
        self.pipeline.run_all.setEnabled(True)
        self.pipeline.run_to.setEnabled(True)

    def _ran(self, res):
        self._run_ended()
        if getattr(self, "_run_input", self.session.input_cloud) is not self.session.input_cloud:
            # another measurement was opened while the steps ran (a review: its result was then taken
            # as the new file's, and Export report wrote it under the new name)
            self.pipeline.bar.setFormat("discarded")
            self.log("run: another measurement was opened while it ran; its result is discarded")
            return
        if self.session.recipe is not getattr(self, "_run_recipe", self.session.recipe):
            # the recipe changed while the steps ran (an edit, Undo, Restore all): the result is of
            # the recipe as it was, and shown it would undo the change on screen (a review: points
            # restored during a run vanished again when it finished)
            self.pipeline.bar.setFormat("discarded")
            self.log("run: the recipe changed while it ran; its result is discarded — Run all again")
            self.report.set_stale("the recipe changed during the last run")
            return
        self.session.accept(res)  # back in the GUI thread: the model changes and the views follow
        self.last_report = res
        self._report_recipe = getattr(self, "_run_recipe", self.session.recipe)  # what last_report's numbers are of
        self.report.set_result(res)
        self.pipeline.show_used()  # the "auto" fields: the values the steps computed
        s = res.summary()
        rms = (f", {_what(s)} RMS {format_length(s['rms_um'] * 1e-3, 4)}, PV {format_length(s['pv_um'] * 1e-3, 4)}"
               if s["rms_um"] is not None else "")
        self.log(f"ran {len(res.steps)} step(s): {res.cloud.n:,} points{rms}")
        if s.get("uncertainty") or s.get("tolerance"):  # the shop's answer (core/assessment.py)
            from pointspro.core.statement import figure_rows, verdict_line

            if s.get("uncertainty"):
                self.log("  RMS " + figure_rows(s).get("RMS", "—") + " — Report tab: every figure")
            if s.get("tolerance"):
                self.log("  " + verdict_line(s["tolerance"]))
        for rec in res.steps:
            for w in rec.report.get("warnings", []) or []:
                self.log(f"  {rec.id}: {w}")

    def _run_failed(self, msg):
        self._run_ended()
        cancelled = "cancel" in str(msg).lower()
        # not left at the step it stopped in, looking hung (a review)
        self.pipeline.bar.setFormat("cancelled" if cancelled else "failed")
        self.log(f"run: {msg}")
        self.report.set_stale("a run was cancelled" if cancelled else "a run failed")

    # -- files ----------------------------------------------------------------------------------------
    def open_any(self, path: str) -> bool:
        p = Path(path)
        if p.name.endswith((".pointspro.yaml", ".pointspro")):
            # the recipe runs in the worker, as Run all (a review: a project with edits ran on the GUI
            # thread, the window frozen and its result missing from the Report tab and the exports)
            ok = self.act(lambda: self.session.open_project(p, run=False) or True)
            if ok and any(st.id == "manual_edit" for st in self.session.recipe.steps):
                self.start_run(None)
        elif p.suffix.lower() in (".yaml", ".yml"):
            ok = self.act(lambda: self.session.load_recipe(p) or True)
        else:
            t0 = time.perf_counter()
            dropped = []
            ok = self.act(lambda: dropped.append(self.session.open(p)) or True)
            if ok:
                c = self.session.input_cloud
                self.log(f"read {p}: {c.n:,} points, channels {sorted(c.channels)} "
                         f"({time.perf_counter() - t0:.2f} s)")
                if dropped and dropped[0]:
                    self.log(f"  the {dropped[0]} deletion step(s) made in the window on the file open before "
                             "were dropped: they name that file's rows")
        if ok:
            recent = self.settings.value("recent", []) or []
            recent = [str(p)] + [r for r in recent if r != str(p)]
            self.settings.setValue("recent", recent[:10])
            QtCore.QTimer.singleShot(0, self._warm)
        return bool(ok)

    def _warm(self):
        """Load the step classes while the optician looks at the data, so the first edit is quick."""
        try:
            self.pipeline.registry.load("manual_edit")
        except PointsProError:
            pass

    def export_cloud(self, path) -> None:
        if self.act(lambda: self.session.export_cloud(path) or True):  # a failure is logged, not "exported"
            self.log(f"exported the cloud to {path}")

    def export_map(self, path) -> None:
        """The map as shown (.png), or the gridded form-error map of the last run's bspline_map step
        (.x3p, .csv, .asc); a failure (a missing folder, a folder named as the file) is one message
        (a review: an OSError left the menu's slot with nothing said)."""
        self.act(lambda: self._export_map(path))

    def _export_map(self, path) -> None:
        path = Path(path)
        if path.suffix.lower() == ".png":
            self.map.save_png(path)
            self.log(f"exported the map view to {path}")
            return
        arts = self.last_report.artifacts if self.last_report is not None else {}
        name = "map" + path.suffix.lower()
        if name not in arts:
            self.log(f"error: {path}: a gridded map ({path.suffix}) comes from a bspline_map step — add "
                     "one and run, or export the view as .png")
            return
        from pointspro.core.batch import write_artifact
        from pointspro.core.io.atomic import atomic_path

        with atomic_path(path) as tmp:
            write_artifact(Path(tmp).parent, Path(tmp).name, arts[name])
        self.log(f"exported the map to {path}")

    def export_mesh(self, path) -> None:
        """The last run's bspline_map map as a triangle mesh for CAD/FEA (.ply binary float64, .stl,
        .obj; mm): the step's map_mesh artifact when it wrote one, else its error map triangulated
        (core.io.mesh.map_mesh_of); a failure is one message."""
        self.act(lambda: self._export_mesh(path))

    def _export_mesh(self, path) -> None:
        from pointspro.core.io.mesh import WRITE_MESH_SUFFIXES, map_mesh_of

        path = Path(path)
        fmt = path.suffix.lower()
        if fmt not in WRITE_MESH_SUFFIXES:
            self.log(f"error: {path}: a mesh is written as {', '.join(WRITE_MESH_SUFFIXES)}")
            return
        art = map_mesh_of(self.last_report.artifacts if self.last_report is not None else {})
        if art is None:
            self.log(f"error: {path}: the mesh is the map of a bspline_map step — add one and run")
            return
        from pointspro.core.io.atomic import atomic_path

        with atomic_path(path) as tmp:
            art(tmp, fmt.lstrip("."))
        self.log(f"exported the map as a mesh to {path} ({len(art.vertices):,} vertices, "
                 f"{len(art.faces):,} triangles)")

    def export_correction(self):
        """File → Export correction…: the correction step's form, a preview of dz and of the error
        predicted after it, and Export… (app/correction_dialog.py). Needs a run that formed a
        residual; the parameters start from a `correction` step of the recipe when there is one."""
        res = self.last_report
        values = next((s.params.model_dump(mode="json", exclude_defaults=True)
                       for s in self.session.recipe.steps if s.id == "correction"), {})
        # heights that are the error (an instrument's error map, `channel: z`) need no residual (a
        # review: a run that had just made the correction was refused here)
        if res is None or ("residual" not in res.cloud.channels and values.get("channel") != "z"):
            self.log("export correction: run the pipeline first (a step that forms a residual, e.g. "
                     "misalignment; or a correction step with channel: z for heights that are the error)")
            return None
        from .correction_dialog import CorrectionDialog

        dlg = CorrectionDialog(res.cloud, getattr(res, "surface", None), values, self)
        dlg.setModal(False)
        dlg.show()
        self.correction_dialog = dlg
        return dlg

    def export_report(self, folder) -> None:
        """The batch's outputs for the last run (cloud.csv, artifacts, report.json, report.html), drawn
        in a worker thread."""
        res, s = self.last_report, self.session
        if res is None:
            self.log("export report: run the pipeline first")
            return
        from pointspro.core.batch import check_replaceable, write_outputs
        from pointspro.core.errors import PointsProError

        target = Path(folder)
        # the report replaces the folder as a whole (all or nothing): never a folder of other files,
        # the input, or a file put beside an earlier report (core.batch.check_replaceable)
        try:
            check_replaceable(target, [s.input_path] if s.input_path else [], s.input_path or "the cloud")
        except PointsProError as e:
            self.log(f"export report: {e} (an earlier report's folder is replaced)")
            return
        # the recipe the shown numbers were computed with, not the one edited since (a review: two
        # manual_edit steps listed beside the numbers of one) — typed and immutable: thread-safe
        recipe = self._report_recipe
        inp = str(s.input_path)
        if recipe is not s.recipe:
            self.log("export report: the recipe changed since the last run; the report is of the last "
                     "run and its recipe — Run all first to export the changes")

        def write(_p):
            write_outputs(Path(folder), inp, recipe, res)
            return f"exported the report to {folder}"
        self.exporter.start(write)

    # -- autosave and restore -------------------------------------------------------------------------
    def autosave_now(self) -> None:
        """Write the project text off the GUI thread (a recipe with thousands of deleted rows takes
        a while to dump); the recipe is never mutated in place, so the thread's snapshot is safe."""
        s = self.session
        if s.input_path is None:
            return
        target = autosave_path()
        snap = (s.recipe, s.input_path)

        def write():
            from pointspro.core.session import write_project

            try:
                write_project(target, *snap)
            except OSError:
                pass
        if self._autosave_thread is not None:
            self._autosave_thread.join()
        self._autosave_thread = threading.Thread(target=write, daemon=True)
        self._autosave_thread.start()

    def _offer_restore(self) -> None:
        """A session the window did not close normally is moved aside (unsaved_session_path) before
        this session autosaves over it, and offered until the user restores or discards it (a review:
        files opened before Restore was clicked autosaved over the crashed session 1.5 s later)."""
        p, kept = autosave_path(), unsaved_session_path()
        if p.is_file():
            with contextlib.suppress(OSError):
                os.replace(p, kept)
        if not kept.is_file():
            return
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(kept.stat().st_mtime))
        self.banner_text.setText(f"An unsaved session from {when} was found (the window did not close "
                                 "normally). Restore it?")
        self.banner.show()

    def restore_autosave(self) -> None:
        self.banner.hide()
        kept = unsaved_session_path()
        if self.open_any(str(kept)):  # restored: this session's autosave holds it from now on
            kept.unlink(missing_ok=True)
        # else kept, offered again at the next start (its data file moved: put back, then restore)

    def discard_autosave(self) -> None:
        self.banner.hide()
        unsaved_session_path().unlink(missing_ok=True)

    def showEvent(self, ev):
        super().showEvent(ev)
        if not self._sized:  # dock sizes only take once the window has its size
            self._sized = True
            QtCore.QTimer.singleShot(0, self._size_docks)

    def _room_for_explain(self):
        """A result in the Explain dock gets ~45 % of the window's height (it had ~190 px, the form
        and ~70 px of result, at 1280 × 800); never shrunk, the user's own size is kept."""
        want = int(0.45 * self.height())
        if self.explain_dock.isVisible() and not self.explain_dock.isFloating() \
                and self.explain_dock.height() < want:
            self.resizeDocks([self.explain_dock], [want], QtCore.Qt.Vertical)

    def _size_docks(self):
        self.resizeDocks([self._log_dock], [190], QtCore.Qt.Vertical)
        self.resizeDocks([self.map_dock, self.pipeline], [430, 290], QtCore.Qt.Horizontal)

    def closeEvent(self, ev):
        if self.runner.busy:
            self.runner.cancel()
        self._autosave_timer.stop()
        if self._autosave_thread is not None:
            self._autosave_thread.join()
        autosave_path().unlink(missing_ok=True)  # a normal close: nothing to restore
        self.plotter.close()
        super().closeEvent(ev)

    # -- drag and drop --------------------------------------------------------------------------------
    def dragEnterEvent(self, e):
        if e.mimeData().hasUrls():
            e.acceptProposedAction()

    def dropEvent(self, e):
        for u in e.mimeData().urls():
            self.open_any(u.toLocalFile())

    # -- menus ----------------------------------------------------------------------------------------
    def _ask_open(self, title, filt):
        return QtWidgets.QFileDialog.getOpenFileName(self, title, "", filt)[0]

    def _ask_save(self, title, filt, fn):
        p = QtWidgets.QFileDialog.getSaveFileName(self, title, "", filt)[0]
        if p:
            fn(p)

    def _menus(self):
        mb = self.menuBar()
        fm = mb.addMenu("&File")
        for text, filt, key in (("Open data…", DATA_FILTER, QtGui.QKeySequence.Open),
                                ("Open recipe…", "Recipes (*.yaml *.yml)", None),
                                ("Open project…", "Projects (*.pointspro.yaml)", None)):
            a = fm.addAction(text)
            if key is not None:
                a.setShortcut(key)
            a.triggered.connect(lambda _=False, t=text, f=filt: (lambda p: p and self.open_any(p))(
                self._ask_open(t, f)))
        recent = fm.addMenu("Recent files")
        recent.aboutToShow.connect(lambda: (recent.clear(), [recent.addAction(
            r, lambda r=r: self.open_any(r)) for r in (self.settings.value("recent", []) or [])]))
        fm.addSeparator()
        a = fm.addAction("Save project…")
        a.setShortcut(QtGui.QKeySequence.Save)
        a.triggered.connect(lambda: self._ask_save("Save project", "Projects (*.pointspro.yaml)",
                                                   lambda p: self.act(lambda: self.session.save_project(p))))
        fm.addAction("Save recipe…").triggered.connect(lambda: self._ask_save(
            "Save recipe", "Recipes (*.yaml)", lambda p: self.act(lambda: self.session.save_recipe(p))))
        fm.addSeparator()
        fm.addAction("Export cloud…").triggered.connect(lambda: self._ask_save(
            "Export cloud", "Clouds (*.csv *.ply)", self.export_cloud))
        fm.addAction("Export map…").triggered.connect(lambda: self._ask_save(
            "Export map", "Maps (*.png *.x3p *.csv *.asc)", self.export_map))
        fm.addAction("Export mesh…").triggered.connect(lambda: self._ask_save(
            "Export the map as a mesh (CAD/FEA, mm)", "Meshes (*.ply *.stl *.obj)", self.export_mesh))
        fm.addAction("Export correction…").triggered.connect(self.export_correction)
        fm.addAction("Export report…").triggered.connect(lambda: (lambda d: d and self.export_report(d))(
            QtWidgets.QFileDialog.getExistingDirectory(self, "Export report into (a new folder)")))
        fm.addSeparator()
        fm.addAction("Restore autosaved session", self.restore_autosave)
        fm.addAction("Quit", self.close).setShortcut(QtGui.QKeySequence.Quit)
        em = mb.addMenu("&Edit")
        self.undo_action = em.addAction("Undo", self.session.undo)
        self.undo_action.setShortcut(QtGui.QKeySequence("Ctrl+Z"))
        self.redo_action = em.addAction("Redo", self.session.redo)
        self.redo_action.setShortcut(QtGui.QKeySequence("Ctrl+Shift+Z"))
        em.addSeparator()
        d = em.addAction("Delete selection", self.delete_selection)
        d.setShortcut(QtGui.QKeySequence(QtCore.Qt.Key_Delete))
        em.addAction("Clear selection", lambda: self.set_selection(None)).setShortcut(
            QtGui.QKeySequence(QtCore.Qt.Key_Escape))
        em.addAction("Restore all deleted points", lambda: self.act(self.session.restore_all))
        vm = mb.addMenu("&View")
        lod = vm.addMenu("Points drawn in 3D")
        group = QtGui.QActionGroup(self)
        for n in sorted({display.DEFAULT_3D_BUDGET, 200_000, 500_000, 1_000_000, 10**9}):  # default ticked
            a = lod.addAction("all" if n == 10**9 else f"{n:,}")
            a.setCheckable(True)
            a.setChecked(n == self.view3d.budget)
            group.addAction(a)
            a.triggered.connect(lambda _=False, n=n: self.set_3d_budget(n))
        for dock in (self.pipeline, self.map_dock, self.report_dock, self.explain_dock):
            vm.addAction(dock.toggleViewAction())

    def set_3d_budget(self, n: int) -> None:
        self.view3d.budget = n
        if self._shown is not None:
            self.view3d.set_cloud(self._shown, self.channel.currentText(),
                                  n_input=self.session.input_cloud.n, keep=self._keep)
            self.view3d.highlight(self._sel)


def _what(summary: dict) -> str:
    """What the summary's figures are of, in a word or two (docs/conventions.md, Summary figures)."""
    return "residual" if summary.get("figures_of", "residual") == "residual" else "height (piston, tilt removed)"
