"""The pipeline dock: the recipe's steps (enable checkboxes, add from the installed steps, remove,
reorder), a form generated from the selected step's Params, Run all / Run to selected / Cancel and
the progress.

The form has one widget per parameter (app.param_widgets, from core.forms' description: spin boxes
with the unit as suffix and the bounds, check boxes, combo boxes, small tables for lists and
mappings, an "auto" box where None means automatic; help and bounds as tooltips). Each value the
user enters goes at once to the recipe through core.session.Session, which validates it with the
step's Params before it changes anything: a refused value stays in its widget, marked in red with the
message (also shown under the form), and is sent again with the next edit (so two parameters that
must change together, a transform's pose and matrix, can), while the recipe keeps its valid values.
The widgets show the recipe's values (the defaults where it sets none) and follow it on undo/redo.
"""
from __future__ import annotations

import functools

from PySide6 import QtCore, QtWidgets

from pointspro.core.errors import PointsProError

from .param_widgets import NullableWidget, ParamWidget, build_widget, fits


class PipelineDock(QtWidgets.QDockWidget):
    def __init__(self, win):
        super().__init__("Pipeline", win)
        self.win = win
        self.registry = win.session.registry  # the session's: the entry points are read once
        w = QtWidgets.QWidget()
        w.setMinimumWidth(w.fontMetrics().horizontalAdvance("m") * 34)  # a form's label, value and "auto"
        lay = QtWidgets.QVBoxLayout(w)
        self.list = QtWidgets.QListWidget()
        lay.addWidget(self.list, 1)
        row = QtWidgets.QHBoxLayout()
        self.add_combo = QtWidgets.QComboBox()
        self.add_combo.addItems(self.registry.ids())
        add = self.add_button = QtWidgets.QPushButton("Add")
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
        self.form.setFieldGrowthPolicy(QtWidgets.QFormLayout.AllNonFixedFieldsGrow)
        self.form.setLabelAlignment(QtCore.Qt.AlignRight | QtCore.Qt.AlignVCenter)
        self.box = QtWidgets.QGroupBox("Parameters")
        self.box.setLayout(self.form)
        scroll = QtWidgets.QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QtWidgets.QFrame.NoFrame)
        scroll.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarAlwaysOff)
        scroll.setWidget(self.box)
        lay.addWidget(scroll, 3)
        self.message = QtWidgets.QLabel()
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color:#b00000")
        self.message.hide()
        lay.addWidget(self.message)
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
        self.fields: dict[str, ParamWidget] = {}  # the form's widgets by parameter
        self._form_of = None  # (row, step id, Params class) the form shows
        self._pending: dict = {}  # values entered but refused, sent again with the next edit

    def refresh(self):
        self.list.blockSignals(True)
        row = self.list.currentRow()
        self.list.clear()
        for s in self.win.session.recipe.steps:
            it = QtWidgets.QListWidgetItem(s.id)
            it.setFlags(it.flags() | QtCore.Qt.ItemIsUserCheckable)
            it.setCheckState(QtCore.Qt.Checked if s.enabled else QtCore.Qt.Unchecked)
            self.list.addItem(it)
        if self.list.count():
            self.list.setCurrentRow(min(max(row, 0), self.list.count() - 1))
        self.list.blockSignals(False)
        i = self.list.currentRow()
        steps = self.win.session.recipe.steps
        if self._form_of is not None and 0 <= i < len(steps) and self._form_of == self._key(i) \
                and self._fill(steps[i]):
            return  # the same step: its widgets follow the recipe, the one being typed in keeps focus
        self._show_form(i)

    def _key(self, i):
        step = self.win.session.recipe.steps[i]
        return (i, step.id, step.step_cls.Params)

    def _values(self, step) -> dict:
        """The values the form shows: the recipe's, the defaults where it sets none."""
        return step.params.model_dump(mode="json")

    def _show_form(self, i):
        from pointspro.core.forms import form_fields

        while self.form.rowCount():  # deleted later: this may run inside one of their signals
            row = self.form.takeRow(0)
            for item in (row.labelItem, row.fieldItem):
                if item is not None and item.widget() is not None:
                    item.widget().hide()
                    item.widget().deleteLater()
        self.fields = {}
        self._form_of = None
        self._pending = {}
        self._say("")
        steps = self.win.session.recipe.steps
        if i < 0 or i >= len(steps):
            self.box.setTitle("Parameters")
            return
        step = steps[i]
        self.box.setTitle(f"Parameters of {step.id}")
        values = self._values(step)
        for f in form_fields(step.step_cls.Params):
            w = build_widget(f, values.get(f.key))
            w.edited.connect(functools.partial(self._commit, f.key))
            w.marked.connect(self._say)
            shown_unit = f.unit and f.editor in ("table", "group", "pairs", "text", "file")
            label = QtWidgets.QLabel(f.key + (f" [{f.unit}]" if shown_unit else "") + (" *" if f.required else ""))
            label.setToolTip(f.tooltip())
            self.form.addRow(label, w)
            self.fields[f.key] = w
        self._form_of = self._key(i)
        self.show_used()

    def show_used(self) -> None:
        """Beside each "auto" field of the form, the value its step computed in the last run (read
        from the step's report: the key itself, or with ``_mm``), so "auto" is not a blank."""
        i = -1 if self._form_of is None else self._form_of[0]
        report = self._last_report_of(i)
        for key, w in self.fields.items():
            if isinstance(w, NullableWidget):
                v = report.get(key, report.get(f"{key}_mm"))
                w.show_used(used_text(v, w.field.unit))

    def _last_report_of(self, i: int) -> dict:
        """The report of recipe step ``i`` in the last run ({} when it did not run there)."""
        res = getattr(self.win, "last_report", None)
        steps = self.win.session.recipe.steps
        if res is None or not 0 <= i < len(steps) or not steps[i].enabled:
            return {}
        k = sum(1 for s in steps[:i] if s.enabled)  # the run's steps are the enabled ones, in order
        if k >= len(res.steps) or res.steps[k].id != steps[i].id:
            return {}
        return res.steps[k].report

    def _fill(self, step) -> bool:
        """Show the recipe's values in the form's widgets (not those holding a refused value);
        False when a widget cannot show its new value (the form is built again)."""
        values = self._values(step)
        for k, w in self.fields.items():
            if not fits(w, values.get(k)):
                return False
        for k, w in self.fields.items():
            if k in self._pending:
                continue
            if w.value() != values.get(k):
                w.set_value(values.get(k))
            w.unmark()
        return True

    def _commit(self, key, value):
        """A value entered in the form: to the recipe when the step's Params accept it (with the
        values refused before), else marked with the message and kept to be sent again."""
        i = self.list.currentRow()
        steps = self.win.session.recipe.steps
        if i < 0 or i >= len(steps) or self._form_of != self._key(i):
            return
        step = steps[i]
        pending = self._pending | {key: value}
        self._pending = {}  # the session's event refreshes the form: every widget from the recipe
        try:
            self.win.session.set_params(i, step.to_yaml_entry()[step.id] | pending)
        except PointsProError as e:  # nothing changed
            self._pending = pending
            msg = str(e)
            for k, w in self.fields.items():
                if k == key or f"key '{k}'" in msg or f"key '{k}." in msg:
                    w.mark(msg)
            self._say(msg)
            self.win.log(f"invalid: {msg}")
            return
        self._say("")

    def _say(self, message: str):
        """The last refusal, under the form ("" hides it)."""
        if not message:
            message = next((w.problem for w in self.fields.values() if w.problem), "")
        self.message.setText(message)
        self.message.setVisible(bool(message))

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


def used_text(v, unit: str | None) -> str | None:
    """A reported value for the "last run" readout: a length (the field's unit mm or µm) in the unit
    its size asks for, a pair of lengths as "(x, y)", other numbers as they are; None for nothing."""
    from pointspro.core.units import SHOWN_LENGTH_MM, format_length

    scale = SHOWN_LENGTH_MM.get(unit or "")

    def one(x):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            return str(x)
        return format_length(x * scale, 4) if scale is not None else f"{x:.4g}"

    if v is None:
        return None
    if isinstance(v, (list, tuple)) and 0 < len(v) <= 3:
        return "(" + ", ".join(one(x) for x in v) + ")"
    if isinstance(v, (list, tuple, dict)):
        return None
    return one(v)
