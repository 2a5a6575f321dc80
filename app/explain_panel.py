"""The Explain panel: compare the open measurement with a simulation of it (a model YAML, or a
simulated cloud), name the physical effects the model is missing, add them and show the gap shrink —
core.explain.workflow.explain, the same as `pointspro explain`, run in a worker thread.

The page shown is the workflow's explain.html (verdict, gap before/after, found effects with their
evidence, ambiguities, unexplained regions, checks); the updated model can be saved from here.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from .worker import Worker

#: explain.html in the dock: a heading's size, no page margins
DOCK_CSS = "body{margin:0;max-width:none} p.title{font-size:11pt;font-weight:bold;margin:0 0 4px 0} " \
           "h2{font-size:10pt;margin-top:8px}"


class ExplainPanel(QtWidgets.QWidget):
    log = QtCore.Signal(str)
    result_shown = QtCore.Signal()  # the window gives the dock room to read it (MainWindow)

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        # two rows, not a four-row form: the panel shares a ~190 px dock under the 3D view with the log
        # and the report, and the form left the result ~50–70 px at 1280 × 800 (a review)
        row = QtWidgets.QHBoxLayout()
        self.kind = QtWidgets.QComboBox()
        self.kind.addItems(["model (YAML)", "simulated cloud"])
        self.kind.setToolTip("what the measurement is compared with: a model evaluated at the measured "
                             "positions, or a simulated cloud (matched by row or by position)")
        row.addWidget(QtWidgets.QLabel("Compare with"))
        row.addWidget(self.kind)
        self.path = QtWidgets.QLineEdit()
        self.path.setPlaceholderText("model.yaml or simulated cloud")
        self.path.setMinimumWidth(80)
        browse = QtWidgets.QPushButton("…")
        browse.setToolTip("choose the file")
        browse.setMaximumWidth(32)
        browse.clicked.connect(self._browse)
        row.addWidget(self.path, 1)
        row.addWidget(browse)
        lay.addLayout(row)
        row = QtWidgets.QHBoxLayout()
        self.bootstrap = QtWidgets.QSpinBox()
        self.bootstrap.setRange(0, 200)
        self.bootstrap.setValue(10)
        self.bootstrap.setToolTip("bootstrap resamples for the stability of each found effect")
        row.addWidget(QtWidgets.QLabel("Bootstrap"))
        row.addWidget(self.bootstrap)
        self.run = QtWidgets.QPushButton("Explain the gap")
        self.run.clicked.connect(self.start)
        self.save = QtWidgets.QPushButton("Save updated model…")
        self.save.setEnabled(False)
        self.save.clicked.connect(self._save_model)
        row.addWidget(self.run)
        row.addWidget(self.save)
        row.addStretch(1)
        lay.addLayout(row)
        self.view = QtWidgets.QTextBrowser()
        self.view.setHtml("<p style='color:#777'>Open a measurement, choose the model of its simulation "
                          "and press <i>Explain the gap</i>.</p>")
        lay.addWidget(self.view, 1)
        self.worker = Worker(self)
        self.worker.done.connect(self._done)
        self.worker.failed.connect(self._failed)
        self._dir = QtCore.QTemporaryDir()
        self._runs = 0
        self.report = None
        self.folder = None

    def _browse(self):
        filt = "Models (*.yaml *.yml)" if self.kind.currentIndex() == 0 else "Clouds (*.csv *.txt *.ply *.xyz)"
        p = QtWidgets.QFileDialog.getOpenFileName(self, "Compare with", "", filt)[0]
        if p:
            self.path.setText(p)

    def start(self) -> bool:
        from pointspro.core.explain.workflow import explain

        s = self.session
        if s.input_path is None:
            self.log.emit("explain: open a measurement first")
            return False
        other = self.path.text().strip()
        if not other:
            self.log.emit("explain: choose a model YAML or a simulated cloud to compare with")
            return False
        self._runs += 1
        out = Path(self._dir.path()) / f"explain_{self._runs}"
        model = Path(other) if self.kind.currentIndex() == 0 else None
        sim = Path(other) if model is None else None
        measured, boot = s.input_path, self.bootstrap.value()
        kept = s.input_less_edits()  # the measurement less the points deleted (a snapshot: thread-safe)
        if kept is not None and kept.n < s.input_cloud.n:
            self.log.emit(f"explain: comparing the {kept.n:,} points kept ({s.input_cloud.n - kept.n:,} "
                          "deleted in the window or by the recipe's manual edits)")
        self.folder = out
        self.run.setEnabled(False)
        self.view.setHtml("<p>comparing…</p>")
        return self.worker.start(lambda _p: explain(measured, out, model, sim, bootstrap=boot,
                                                    measured_cloud=kept))

    def _done(self, report):
        self.report = report
        self.run.setEnabled(True)
        self.save.setEnabled(True)
        page = (self.folder / "explain.html").read_text(encoding="utf-8")
        # the page's title and margins are a browser page's: in a dock its h1 took two lines of a
        # 250 px view; a rule after the page's own style wins (the saved explain.html is unchanged).
        # Qt draws an <h1> at its own heading size whatever CSS says: the title is a bold paragraph.
        page = page.replace("<h1>", "<p class='title'>").replace("</h1>", "</p>")
        self.view.setHtml(page.replace("</head>", f"<style>{DOCK_CSS}</style></head>", 1))
        self.result_shown.emit()
        from pointspro.core.explain.workflow import found_name

        names = ", ".join(found_name(f) for f in report["found"]) or "nothing"
        from pointspro.core.units import format_length

        self.log.emit(f"explain: {report['verdict']} — found {names}; gap RMS "
                      f"{format_length(report['gap_before']['rms_um'] * 1e-3, 4)} → "
                      f"{format_length(report['gap_after']['rms_um'] * 1e-3, 4)}")
        for w in report.get("warnings") or []:
            self.log.emit(f"explain: warning: {w}")

    def _failed(self, msg):
        self.run.setEnabled(True)
        self.view.setHtml(f"<p style='color:#a40000'>{msg}</p>")
        self.log.emit(f"explain: {msg}")

    def save_model(self, target) -> None:
        shutil.copyfile(self.folder / "model.updated.yaml", target)
        self.log.emit(f"saved the updated model to {target}")

    def _save_model(self):
        if os.environ.get("POINTSPRO_NO_DIALOGS"):
            return
        p = QtWidgets.QFileDialog.getSaveFileName(self, "Save updated model", "model.updated.yaml",
                                                  "Models (*.yaml)")[0]
        if p:
            try:
                self.save_model(p)
            except OSError as e:
                self.log.emit(f"error: {p}: {e.strerror}")
