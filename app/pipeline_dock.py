"""The pipeline dock: the recipe's steps (enable checkboxes, add from the installed steps, remove,
reorder), a form generated from the selected step's Params (units, bounds and help as tooltips,
invalid values marked in red with the message), Run all / Run to selected / Cancel and the progress.

It edits the recipe only through core.session.Session, which validates each edit before it changes
anything.
"""
from __future__ import annotations

from PySide6 import QtCore, QtWidgets

from pointspro.core.errors import PointsProError


class PipelineDock(QtWidgets.QDockWidget):
    def __init__(self, win):
        super().__init__("Pipeline", win)
        self.win = win
        self.registry = win.session.registry  # the session's: the entry points are read once
        w = QtWidgets.QWidget()
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
        for s in self.win.session.recipe.steps:
            it = QtWidgets.QListWidgetItem(s.id)
            it.setFlags(it.flags() | QtCore.Qt.ItemIsUserCheckable)
            it.setCheckState(QtCore.Qt.Checked if s.enabled else QtCore.Qt.Unchecked)
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
        steps = self.win.session.recipe.steps
        if i < 0 or i >= len(steps):
            return
        step = steps[i]
        cls = step.step_cls
        values = step.to_yaml_entry()[step.id]  # the parameters the recipe sets (not the defaults)
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
