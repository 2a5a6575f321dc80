"""File → Export correction…: the `correction` step's outputs for the last run, with a preview.

The dialog is the step's own form (the pipeline dock's widgets, built from ``CorrectionStep.Params``;
the values of a `correction` step in the recipe when there is one), a preview of the correction dz
and of the error predicted after it (the step's ``correction.png``: the filter and the edge are what
it leaves) with the figures of the report (error RMS → predicted RMS, the corrected surface's fit,
the removal depth), and Export…, which writes every output into ``<folder>/correction/`` (all or
nothing). The step runs in a worker thread (app/worker.py), never in the event loop. Sign
convention: docs/conventions.md, Correction — dz is the height to ADD to the programmed surface.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

from PySide6 import QtCore, QtGui, QtWidgets

from .param_widgets import build_widget
from .worker import Worker

#: the subfolder Export… writes into (replaced as a whole when it holds only correction outputs)
FOLDER = "correction"


def _load_step():
    from pointspro.core.registry import Registry

    return Registry().load("correction")


class CorrectionDialog(QtWidgets.QDialog):
    """``cloud``: the last run's cloud (with its residual); ``surface``: the recipe's nominal (None:
    only the cutting and polishing outputs); ``values``: parameters to start from."""

    computed = QtCore.Signal()

    def __init__(self, cloud, surface=None, values: dict | None = None, parent=None):
        super().__init__(parent)
        from pointspro.core.forms import form_fields

        self.setWindowTitle("Export correction — the next run's programme")
        self.step_cls = _load_step()
        self.cloud, self.surface = cloud, surface
        self.values = dict(values or {})
        self.result = None  # the step's StepResult for the values shown
        self.worker = Worker(self)
        self.worker.done.connect(self._computed)
        self.worker.failed.connect(self._failed)

        lay = QtWidgets.QHBoxLayout(self)
        left = QtWidgets.QVBoxLayout()
        form = QtWidgets.QFormLayout()
        self.widgets = {}
        for f in form_fields(self.step_cls.Params):
            w = build_widget(f, self.values.get(f.key))
            w.edited.connect(lambda v, key=f.key: self._edited(key, v))
            form.addRow(f.key, w)
            self.widgets[f.key] = w
        box = QtWidgets.QWidget()
        box.setLayout(form)
        scroll = QtWidgets.QScrollArea()
        scroll.setWidget(box)
        scroll.setWidgetResizable(True)
        scroll.setMinimumWidth(380)
        left.addWidget(scroll)
        self.message = QtWidgets.QLabel()
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color:#a00")
        left.addWidget(self.message)
        buttons = QtWidgets.QHBoxLayout()
        self.preview_button = QtWidgets.QPushButton("Preview")
        self.export_button = QtWidgets.QPushButton("Export…")
        close = QtWidgets.QPushButton("Close")
        for b in (self.preview_button, self.export_button, close):
            buttons.addWidget(b)
        self.preview_button.clicked.connect(self.compute)
        self.export_button.clicked.connect(self._ask_export)
        close.clicked.connect(self.reject)
        left.addLayout(buttons)
        lay.addLayout(left)

        right = QtWidgets.QVBoxLayout()
        self.picture = QtWidgets.QLabel("computing the preview…")
        self.picture.setAlignment(QtCore.Qt.AlignCenter)
        self.picture.setMinimumSize(560, 300)
        right.addWidget(self.picture, 1)
        self.summary = QtWidgets.QLabel()
        self.summary.setWordWrap(True)
        self.summary.setTextInteractionFlags(QtCore.Qt.TextSelectableByMouse)
        right.addWidget(self.summary)
        lay.addLayout(right, 1)
        self.export_button.setEnabled(False)
        QtCore.QTimer.singleShot(0, self.compute)

    # -- parameters -----------------------------------------------------------------------------------
    def _edited(self, key, value):
        if value is None:
            self.values.pop(key, None)
        else:
            self.values[key] = value
        self.result = None
        self.export_button.setEnabled(False)
        self.compute()

    def params(self):
        """The step's validated Params for the values shown (PointsProError naming the key)."""
        from pydantic import ValidationError

        from pointspro.core.errors import RecipeError
        from pointspro.core.recipe import format_validation_error

        try:
            return self.step_cls.Params(**self.values)
        except ValidationError as e:
            raise RecipeError(format_validation_error(e, "correction: ")) from None

    # -- preview --------------------------------------------------------------------------------------
    def compute(self) -> bool:
        """Run the step on the cloud in the worker thread (False when one is already running or the
        values are invalid; the message says which)."""
        from pointspro.core.errors import PointsProError

        try:
            params = self.params()
        except PointsProError as e:
            self._failed(str(e))
            return False
        if self.worker.busy:
            return False
        self.message.setText("")
        self.picture.setText("computing the preview…")
        step, cloud, surface = self.step_cls(), self.cloud, self.surface

        def job(progress):
            from pointspro.core.step import Context

            return step.run(cloud, params, Context(progress=progress, surface=surface))
        return self.worker.start(job)

    def _computed(self, out):
        self.result = out
        self.export_button.setEnabled(True)
        png = out.artifacts.get("correction.png")
        if png is not None:
            with tempfile.TemporaryDirectory() as d:
                p = Path(d) / "preview.png"
                png(p)
                pix = QtGui.QPixmap(str(p))
            self.picture.setPixmap(pix.scaled(self.picture.size(), QtCore.Qt.KeepAspectRatio,
                                              QtCore.Qt.SmoothTransformation))
        self.summary.setText(summary_text(out.report, sorted(out.artifacts)))
        self.computed.emit()

    def _failed(self, message):
        self.result = None
        self.export_button.setEnabled(False)
        self.message.setText(message)
        self.picture.setText("no preview")
        self.computed.emit()

    # -- export ---------------------------------------------------------------------------------------
    def _ask_export(self):
        d = QtWidgets.QFileDialog.getExistingDirectory(self, f"Export the correction into <folder>/{FOLDER}/")
        if d:
            self.export(d)

    def export(self, folder) -> Path | None:
        """Write every output of the previewed correction into ``folder/correction/`` (a temporary
        folder renamed when complete). A ``correction/`` that holds anything else is never replaced:
        the message says so and nothing is written. Returns the folder written, or None."""
        from pointspro.core.batch import write_artifact
        from pointspro.core.io.atomic import atomic_dir

        if self.result is None:
            self.message.setText("export: wait for the preview (or correct the parameters)")
            return None
        target = Path(folder) / FOLDER
        names = set(self.result.artifacts)
        if target.exists():
            foreign = sorted(p.name for p in target.iterdir() if p.name not in names)
            if not target.is_dir() or foreign:
                self.message.setText(f"export: {target} holds other files ({', '.join(foreign[:3]) or 'not a folder'})"
                                     " — choose another folder")
                return None
        try:
            with atomic_dir(target) as tmp:
                for name, art in self.result.artifacts.items():
                    write_artifact(tmp, name, art)
        except OSError as e:
            self.message.setText(f"export: {target}: {e.strerror or e}")
            return None
        self.message.setText("")
        self.summary.setText(self.summary.text() + f"\nwritten to {target}")
        return target


def summary_text(report: dict, files) -> str:
    """The figures an engineer checks before sending the files: the sign, error → predicted RMS,
    the corrected surface and the removal, and the files that will be written."""
    from pointspro.core.units import format_length

    def um(key):
        v = report.get(key)
        return None if v is None else format_length(v * 1e-3)

    lines = ["dz is the height to ADD to the programmed surface (docs/conventions.md, Correction)"]
    if um("error_rms_um") and um("predicted_rms_um"):
        # of the correction's gridded map (not the points' residual RMS of the status bar)
        over = f" over Ø{report['diameter_mm']:g} mm" if isinstance(report.get("diameter_mm"), (int, float)) else ""
        lines.append(f"form error of the gridded map{over} {um('error_rms_um')} RMS → predicted after "
                     f"correction {um('predicted_rms_um')} RMS")
    cs = report.get("corrected_surface")
    if isinstance(cs, dict) and cs.get("type"):
        fit = cs.get("fit_rms_nm")
        lines.append(f"corrected surface: {cs['type']}"
                     + (f", within {format_length(fit * 1e-6)} RMS" if fit is not None else ""))
    rem = report.get("removal")
    if isinstance(rem, dict) and rem.get("max_depth_um") is not None:
        lines.append(f"removal (polishing): {format_length(rem['max_depth_um'] * 1e-3)} deep, "
                     f"{rem.get('volume_mm3', 0):.4g} mm³")
    lines.append("files: " + ", ".join(files))
    return "\n".join(lines)
