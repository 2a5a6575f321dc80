"""The widgets of a step's parameter form, one per ``core.forms.FormField`` (its ``editor``).

- float: a spin box with the unit as suffix that shows the value's shortest exact text (repr:
  0.00033333333, 7e-13, 1290) and reads scientific notation. A length (a field in mm, µm or nm) is
  shown in the unit its size asks for (core.units.length_unit: 1e-05 mm reads "10 nm", 0.00033333333
  mm "333.33333 nm"), its digits shifted by a power of ten in decimal, so the text is still exact and
  reads back as the very float64 the recipe holds (in the recipe's unit); a value may be typed in the
  unit shown, or with its own ("0.02 mm", "20 µm", "20um"). A spin box rather than a line edit with
  a QDoubleValidator: it keeps the arrows, the wheel and the suffix, and with Qt's largest
  ``decimals`` (323) it rounds nothing a float64 holds above 1e-323, so values of any decade (a
  7e-13 aspheric coefficient, a 1e6 smoothing) are shown and written back unchanged; an arrow moves
  by a tenth of the value's decade.
- int: a QSpinBox; bool: a QCheckBox; choice: a QComboBox; ``auto | int``: a combo with the choices
  and "number" beside a spin box; text: a line edit (a file: with a "…" button).
- a fixed pair (``centre: [x, y]``): two spin boxes; a list: a small table with + and − (a list of
  known choices: a list of check boxes); a nested group (``initial``): a small form of its fields; a
  mapping with free keys: a key/value table.
- None ("automatic", "not given"): the widget and a box "auto" (or "none") that disables it.

Bounds are enforced where the value is entered: the spin boxes' range is the field's inclusive
bounds, a typed value outside them (or on a strict bound) is not taken and the message is shown while
typing ("window must be > 0 mm (got -5 mm)"), an arrow never leaves them. Each widget emits
``edited(value)`` when the user enters a value (a spin box: on Enter, leaving the field or an arrow);
the dock validates it through the step's Params and marks the widget with the message when it is
refused (``mark``); ``marked(message)`` tells the dock what to show.
"""
from __future__ import annotations

import math
import re
from decimal import Decimal, InvalidOperation

from PySide6 import QtCore, QtGui, QtWidgets

from pointspro.core import forms
from pointspro.core.forms import FormField
from pointspro.core.units import length_unit

INVALID = "background:#ffd6d6"
_DBL_MAX = 1.7976931348623157e308
_INT_MAX = 2 ** 31 - 1


class ParamWidget(QtWidgets.QWidget):
    """One field's editor. ``value()``/``set_value(v)`` (shown, nothing emitted) in the recipe's
    terms (None where the field is automatic); ``enter(v)``: as if the user had entered ``v``."""

    edited = QtCore.Signal(object)
    marked = QtCore.Signal(str)

    def __init__(self, field: FormField, parent=None):
        super().__init__(parent)
        self.field = field
        self.problem = ""
        self.lay = QtWidgets.QHBoxLayout(self)
        self.lay.setContentsMargins(0, 0, 0, 0)
        self.lay.setSpacing(4)
        self.setToolTip(field.tooltip())

    # -- the value --------------------------------------------------------------------------------
    def value(self):
        raise NotImplementedError

    def set_value(self, v) -> None:
        raise NotImplementedError

    def check(self, v) -> str | None:
        """The message when ``v`` cannot be entered here (out of bounds, not a choice), else None."""
        return None

    def enter(self, v) -> None:
        """``v`` entered by the user: refused with the message when it cannot be, else shown and
        emitted (the dock then validates it through the step's Params)."""
        problem = self.check(v)
        if problem:
            self.mark(problem)
            return
        self.set_value(v)
        self.unmark()
        self._emit()

    def _emit(self, *_):
        self.edited.emit(self.value())

    # -- marks ------------------------------------------------------------------------------------
    def mark(self, message: str) -> None:
        """Red with the message as tooltip ("" clears it)."""
        if message == self.problem:
            return
        self.problem = message
        self.setStyleSheet(INVALID if message else "")
        tip = self.field.tooltip()
        self.setToolTip(f"{message}\n\n{tip}" if message else tip)
        self.marked.emit(message)

    def unmark(self) -> None:
        """Clear the marks of this widget and of the ones inside it (a group's, an "auto" box's)."""
        for w in self.findChildren(ParamWidget):
            w.mark("")
        self.mark("")


# --- numbers -------------------------------------------------------------------------------------

#: length units a value is shown or typed in: the power of ten of the unit in mm
LENGTH_EXP = {"m": 3, "mm": 0, "µm": -3, "μm": -3, "um": -3, "nm": -6}
_TYPED_UNIT = re.compile(r"(.*?)(mm|µm|μm|um|nm|m)?")
_PARTIAL_UNITS = ("µ", "μ", "u", "n")  # a unit being typed ("20 µ" → "20 µm")


def is_length(field: FormField) -> bool:
    """Whether ``field`` holds a length (its unit mm, µm or nm): shown in the unit its size asks for."""
    return field.unit in LENGTH_EXP


def _shifted(d: Decimal, k: int) -> Decimal:
    """``d`` × 10^k, exactly (the exponent moved; no rounding to a context's precision)."""
    sign, digits, exp = d.as_tuple()
    return Decimal((sign, digits, exp + k))


def _decimal_text(d: Decimal) -> str:
    """The shortest text of ``d`` as Python writes a float: plain from 1e-4 to below 1e16, else
    scientific ("7e-13", "1.5e+20")."""
    sign, digits, exp = d.as_tuple()
    digits = list(digits)
    while len(digits) > 1 and digits[-1] == 0:
        digits.pop()
        exp += 1
    if digits == [0]:
        return "-0" if sign else "0"
    d = Decimal((sign, tuple(digits), exp))
    adjusted = d.adjusted()
    if -4 <= adjusted < 16:
        return format(d, "f")
    mantissa = str(digits[0]) + ("." + "".join(map(str, digits[1:])) if len(digits) > 1 else "")
    return ("-" if sign else "") + f"{mantissa}e{adjusted:+03d}"


def length_text(v: float, unit: str) -> tuple[str, str]:
    """(text, unit shown) of the length ``v`` stated in ``unit`` (mm, µm or nm): in the unit its size
    asks for (core.units.length_unit: nm below 1 µm, µm below 1 mm, mm below 10 m, m above), the
    digits of its shortest exact text shifted by a power of ten — 1e-05 mm → ("10", "nm"), 4.39e-05
    mm → ("43.9", "nm") — so ``parse_length`` of it gives ``v`` back bit for bit. Zero and non-finite
    values in ``unit`` itself."""
    v = float(v)
    if not math.isfinite(v) or v == 0:
        return forms.format_number(v), unit
    d = Decimal(forms.format_number(v))
    shown = length_unit(float(_shifted(d, LENGTH_EXP[unit])))[1]
    return _decimal_text(_shifted(d, LENGTH_EXP[unit] - LENGTH_EXP[shown])), shown


def split_length(text: str) -> tuple[str, str | None]:
    """A typed length as (number text, unit typed or None): "20 µm" → ("20", "µm"), "1e-5" → ("1e-5",
    None); spaces, thin spaces and a typographic minus are read as parse_number reads them."""
    t = str(text).strip().replace("−", "-").replace("\u2009", "").replace(" ", "")
    m = _TYPED_UNIT.fullmatch(t)
    return m.group(1), m.group(2)


def parse_length(text: str, shown: str, unit: str) -> float:
    """The length typed as ``text`` in the unit ``shown`` (or the one typed with it: "0.02 mm"), as a
    float64 in ``unit``: the decimal digits shifted by the units' power of ten, then rounded once (so
    "43.9" nm in a mm field is the float64 nearest 4.39e-05, the same as "4.39e-05" typed in mm).
    ValueError with the message when it is not a finite number."""
    num, typed = split_length(text)
    forms.parse_number(num)  # the message for what is not a finite number
    try:
        d = Decimal(num)
    except InvalidOperation:
        raise ValueError(f"'{text}' is not a number") from None
    v = float(_shifted(d, LENGTH_EXP[typed or shown] - LENGTH_EXP[unit]))
    if not math.isfinite(v):
        raise ValueError(f"'{text}' is not a finite number")
    return v


def bounds_message(field: FormField, v) -> str | None:
    """forms.bounds_problem, with the value refused in the unit it is shown in ("floor must be ≥ 0
    mm (got -10 nm)")."""
    problem = forms.bounds_problem(field, v)
    if problem and is_length(field) and isinstance(v, (int, float)) and " (got " in problem:
        text, shown = length_text(v, field.unit)
        problem = f"{problem[:problem.rfind(' (got ')]} (got {text} {shown})"
    return problem


class _SpinMixin:
    """Shared by the float and int spin boxes: exact text, scientific notation, the unit as suffix,
    bounds with the message while typing, arrows that stay inside the bounds."""

    def _setup(self, owner: ParamWidget, field: FormField, kind: str, prefix: str = ""):
        self.owner, self.field, self.kind = owner, field, kind
        if kind == "float":
            self.setDecimals(323)  # Qt's largest: nothing a float64 holds above 1e-323 is rounded
        self.setKeyboardTracking(False)  # valueChanged on Enter, leaving the field or an arrow
        self.setAccelerated(True)
        self.setCorrectionMode(QtWidgets.QAbstractSpinBox.CorrectToPreviousValue)
        if prefix:
            self.setPrefix(prefix)
        if field.unit:
            self.setSuffix(" " + field.unit)
        big = _DBL_MAX if kind == "float" else _INT_MAX
        lo = field.minimum if field.minimum is not None else field.exclusive_minimum
        hi = field.maximum if field.maximum is not None else field.exclusive_maximum
        if kind == "int" and field.minimum is None and field.exclusive_minimum is not None:
            lo = int(field.exclusive_minimum) + 1
        if kind == "int" and field.maximum is None and field.exclusive_maximum is not None:
            hi = int(-(-field.exclusive_maximum // 1)) - 1
        self.setRange(max(lo, -big) if lo is not None else -big, min(hi, big) if hi is not None else big)
        self.setSizePolicy(QtWidgets.QSizePolicy.Expanding, QtWidgets.QSizePolicy.Fixed)

    def _number_text(self, text: str) -> str:
        t = text
        if self.prefix() and t.startswith(self.prefix()):
            t = t[len(self.prefix()):]
        if getattr(self, "length", False):  # the suffix with its space: "20 mm" typed over " m" is mm
            suffix = self.suffix().rstrip()
            if suffix and t.rstrip().endswith(suffix):
                t = t.rstrip()[:-len(suffix)]
            return t.strip()
        unit = self.suffix().strip()
        if unit and t.rstrip().endswith(unit):
            t = t.rstrip()[:-len(unit)]
        return t.strip()

    def _partial(self, t: str) -> bool:
        return forms.is_partial_number(t)

    def _read(self, t: str):
        return forms.parse_number(t, self.kind)

    def validate(self, text, pos):
        t = self._number_text(text)
        if self._partial(t):
            return QtGui.QValidator.Intermediate
        try:
            v = self._read(t)
        except ValueError:
            return QtGui.QValidator.Invalid
        problem = bounds_message(self.field, v)
        if self.lineEdit().isModified():  # typed (not Qt's own text): a refusal's message stays
            self.owner.mark(problem or "")  # once the text reverts to the value
        return QtGui.QValidator.Intermediate if problem else QtGui.QValidator.Acceptable

    def valueFromText(self, text):
        try:
            return self._read(self._number_text(text))
        except ValueError:
            return self.value()

    def textFromValue(self, v):
        return forms.format_number(int(v) if self.kind == "int" else float(v))

    def stepBy(self, steps):
        v = self.value()
        if self.kind == "int":
            out = v + steps
            out = v if forms.bounds_problem(self.field, out) else out
        else:
            out = forms.stepped(self.field, v, steps)
        if out != v:
            self.setValue(out)

    def sizeHint(self):
        h = super().sizeHint()
        fm = self.fontMetrics()
        w = fm.horizontalAdvance(self.prefix() + "-0.000123456" + self.suffix()) + 36
        return QtCore.QSize(w, h.height())

    def minimumSizeHint(self):
        return QtCore.QSize(60, super().minimumSizeHint().height())


class FloatSpin(_SpinMixin, QtWidgets.QDoubleSpinBox):
    """A float; a length (``is_length``) in the unit its value's size asks for, the suffix following
    the value ("10 nm", "15 mm"), its text exact (``length_text``); typed in the unit shown or with
    one's own ("0.02 mm")."""

    def __init__(self, owner, field, prefix=""):
        super().__init__()
        self.length = is_length(field)
        self._setup(owner, field, "float", prefix)
        if self.length:
            # before any other slot: whoever hears the new value sees its unit shown with it
            self.valueChanged.connect(self._sync_unit)
            self._sync_unit()

    def shown_unit(self) -> str | None:
        """The unit the value is shown (and a unit-less text typed) in."""
        shown = self.suffix().strip()
        return shown if self.length and shown in LENGTH_EXP else self.field.unit

    def _sync_unit(self, *_):
        unit = " " + length_text(self.value(), self.field.unit)[1]
        if self.suffix() != unit:
            self.setSuffix(unit)

    def setValue(self, v):
        super().setValue(v)
        if self.length:
            self._sync_unit()  # set quietly (signals blocked) too

    def _partial(self, t):
        if not self.length:
            return super()._partial(t)
        num, typed = split_length(t)
        if typed is None:
            for u in _PARTIAL_UNITS:  # a unit being typed after a number: "20 µ", "20n"
                if num.endswith(u):
                    try:
                        forms.parse_number(num[:-len(u)])
                    except ValueError:
                        return False
                    return True
        return forms.is_partial_number(num)

    def _read(self, t):
        if not self.length:
            return super()._read(t)
        return parse_length(t, self.shown_unit(), self.field.unit)

    def textFromValue(self, v):
        if not self.length:
            return super().textFromValue(v)
        return length_text(v, self.field.unit)[0]


class IntSpin(_SpinMixin, QtWidgets.QSpinBox):
    def __init__(self, owner, field, prefix=""):
        super().__init__()
        self._setup(owner, field, "int", prefix)


def _set_quietly(w, fn, *args):
    w.blockSignals(True)
    try:
        fn(*args)
    finally:
        w.blockSignals(False)


class NumberWidget(ParamWidget):
    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.spin = (FloatSpin if field.editor == "float" else IntSpin)(self, field)
        self.spin.valueChanged.connect(self._emit)
        self.lay.addWidget(self.spin)

    def value(self):
        return int(self.spin.value()) if self.spin.kind == "int" else float(self.spin.value())

    def set_value(self, v):
        _set_quietly(self.spin, self.spin.setValue, v)

    def check(self, v):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return f"{self.field.key}: {v!r} is not a number"
        if self.spin.kind == "int" and v != int(v):
            return f"{self.field.key}: {v!r} is not a whole number"
        return bounds_message(self.field, v)


class BoolWidget(ParamWidget):
    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.box = QtWidgets.QCheckBox()
        self.box.toggled.connect(self._emit)
        self.lay.addWidget(self.box)
        self.lay.addStretch(1)

    def value(self):
        return self.box.isChecked()

    def set_value(self, v):
        _set_quietly(self.box, self.box.setChecked, bool(v))

    def check(self, v):
        return None if isinstance(v, bool) else f"{self.field.key}: {v!r} is not true or false"


class ChoiceWidget(ParamWidget):
    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.combo = QtWidgets.QComboBox()
        self.combo.addItems([str(c) for c in field.choices])
        self.combo.currentIndexChanged.connect(self._emit)
        self.lay.addWidget(self.combo, 1)

    def _index(self, v) -> int:
        for i, c in enumerate(self.field.choices):
            if c == v and type(c) is type(v) or str(c) == str(v):
                return i
        return -1

    def value(self):
        return self.field.choices[self.combo.currentIndex()]

    def set_value(self, v):
        _set_quietly(self.combo, self.combo.setCurrentIndex, max(self._index(v), 0))

    def check(self, v):
        if self._index(v) < 0:
            return f"{self.field.key}: {v!r} is not one of {', '.join(map(str, self.field.choices))}"
        return None


class UnionWidget(ParamWidget):
    """``auto | int``: the choices and "number" in a combo, the number in a spin box beside it."""

    NUMBER = "number"

    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.combo = QtWidgets.QComboBox()
        self.combo.addItems([str(c) for c in field.choices] + [self.NUMBER])
        self.spin = (FloatSpin if field.number == "float" else IntSpin)(self, field)
        self.combo.currentIndexChanged.connect(self._combo_changed)
        self.spin.valueChanged.connect(self._emit)
        self.lay.addWidget(self.combo)
        self.lay.addWidget(self.spin, 1)
        _set_quietly(self.spin, self.spin.setValue, forms.initial_value(
            FormField(**{**field.__dict__, "widget": field.number, "default": None})))

    def _is_number(self) -> bool:
        return self.combo.currentIndex() == len(self.field.choices)

    def _combo_changed(self, *_):
        self.spin.setEnabled(self._is_number())
        self._emit()

    def value(self):
        if self._is_number():
            return int(self.spin.value()) if self.spin.kind == "int" else float(self.spin.value())
        return self.field.choices[self.combo.currentIndex()]

    def set_value(self, v):
        if v in self.field.choices and not isinstance(v, bool):
            i = self.field.choices.index(v)
        else:
            i = len(self.field.choices)
            _set_quietly(self.spin, self.spin.setValue, v)
        _set_quietly(self.combo, self.combo.setCurrentIndex, i)
        self.spin.setEnabled(self._is_number())

    def check(self, v):
        if v in self.field.choices:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return f"{self.field.key}: {v!r} is neither {', '.join(map(str, self.field.choices))} nor a number"
        return bounds_message(self.field, v)


class TextWidget(ParamWidget):
    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.edit = QtWidgets.QLineEdit()
        self.edit.editingFinished.connect(self._finished)
        self.lay.addWidget(self.edit, 1)
        self._last = None
        if field.editor == "file":
            b = self.browse = QtWidgets.QToolButton()
            b.setText("…")
            b.setToolTip("choose the file")
            b.clicked.connect(self._browse)
            self.lay.addWidget(b)

    def _finished(self):
        if self.edit.text() != self._last:
            self._last = self.edit.text()
            self._emit()

    def _browse(self):
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, self.field.key, self.edit.text())
        if path:
            self.enter(path)

    def value(self):
        return self.edit.text()

    def set_value(self, v):
        self._last = "" if v is None else str(v)
        _set_quietly(self.edit, self.edit.setText, self._last)


class TupleWidget(ParamWidget):
    """A fixed number of numbers (``centre: [x, y]``): one spin box each, named x, y (z)."""

    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        cls = FloatSpin if field.item == "float" else IntSpin
        self.spins = [cls(self, field, prefix=f"{t} ") for t in field.column_titles()]
        for s in self.spins:
            s.valueChanged.connect(self._emit)
            self.lay.addWidget(s, 1)

    def value(self):
        return [int(s.value()) if s.kind == "int" else float(s.value()) for s in self.spins]

    def set_value(self, v):
        for s, x in zip(self.spins, v or []):
            _set_quietly(s, s.setValue, x)

    def check(self, v):
        if not isinstance(v, (list, tuple)) or len(v) != len(self.spins):
            return f"{self.field.key}: give {len(self.spins)} numbers"
        return None


class _TableBase(ParamWidget):
    """A small table with + (a row) and − (the selected rows) beside it."""

    def __init__(self, field, titles, parent=None):
        super().__init__(field, parent)
        t = self.table = QtWidgets.QTableWidget(0, len(titles))
        t.setHorizontalHeaderLabels(titles)
        t.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.Stretch)
        t.verticalHeader().setDefaultSectionSize(t.fontMetrics().height() + 8)
        t.horizontalHeader().setVisible(len(titles) > 1)  # one column: the label says what it holds
        t.setSizePolicy(QtWidgets.QSizePolicy.Expanding, QtWidgets.QSizePolicy.Fixed)
        self.setSizePolicy(QtWidgets.QSizePolicy.Preferred, QtWidgets.QSizePolicy.Fixed)
        t.cellChanged.connect(self._cells_changed)
        self.lay.addWidget(t, 1)
        self._fit()
        col = QtWidgets.QVBoxLayout()
        self.add_button = QtWidgets.QToolButton()
        self.add_button.setText("+")
        self.add_button.setToolTip("add a row (empty rows are left out)")
        self.add_button.clicked.connect(self.add_row)
        self.remove_button = QtWidgets.QToolButton()
        self.remove_button.setText("−")
        self.remove_button.setToolTip("remove the selected rows")
        self.remove_button.clicked.connect(self.remove_rows)
        col.addWidget(self.add_button)
        col.addWidget(self.remove_button)
        col.addStretch(1)
        self.lay.addLayout(col)

    def _fit(self):
        """As tall as its rows and one more to add (2 to 6 rows; more scroll)."""
        t = self.table
        n = min(max(t.rowCount() + 1, 2), 6)
        head = t.horizontalHeader().sizeHint().height() if t.horizontalHeader().isVisible() else 0
        t.setFixedHeight(n * t.verticalHeader().defaultSectionSize() + head + 2 * t.frameWidth())

    def rows(self) -> list[list[str]]:
        t = self.table
        return [[(t.item(r, c).text() if t.item(r, c) else "") for c in range(t.columnCount())]
                for r in range(t.rowCount())]

    def set_rows(self, rows: list[list[str]]) -> None:
        t = self.table
        t.blockSignals(True)
        try:
            t.setRowCount(len(rows))
            for r, cells in enumerate(rows):
                for c in range(t.columnCount()):
                    t.setItem(r, c, QtWidgets.QTableWidgetItem(cells[c] if c < len(cells) else ""))
        finally:
            t.blockSignals(False)
        self._fit()

    def add_row(self):
        t = self.table
        t.blockSignals(True)
        t.insertRow(t.rowCount())
        for c in range(t.columnCount()):
            t.setItem(t.rowCount() - 1, c, QtWidgets.QTableWidgetItem(""))
        t.blockSignals(False)
        self._fit()
        t.setCurrentCell(t.rowCount() - 1, 0)
        if t.isVisible():
            t.editItem(t.item(t.rowCount() - 1, 0))

    def remove_rows(self):
        t = self.table
        rows = sorted({i.row() for i in t.selectedIndexes()} or ({t.rowCount() - 1} if t.rowCount() else set()),
                      reverse=True)
        if not rows:
            return
        t.blockSignals(True)
        for r in rows:
            t.removeRow(r)
        t.blockSignals(False)
        self._fit()
        self._cells_changed()

    def _parse(self, rows):
        raise NotImplementedError

    def _cells_changed(self, *_):
        try:
            self._parse(self.rows())
        except ValueError as e:
            self.mark(str(e))
            return
        self.unmark()
        self._emit()

    def value(self):
        try:
            return self._parse(self.rows())
        except ValueError:
            return None  # the dock never sends it: the cells are marked

    def check(self, v):
        return None


class ListTable(_TableBase):
    """A list of numbers or names, or of rows of numbers (``vertices``, a matrix): one entry a row."""

    def __init__(self, field, parent=None):
        super().__init__(field, field.column_titles(), parent)

    def _parse(self, rows):
        return forms.table_value(self.field, rows)

    def set_value(self, v):
        rows = forms.table_rows(self.field, v)
        if self.field.item == "row" and self.field.columns is None:  # a matrix: as wide as its rows
            n = max([len(r) for r in rows] + [4])
            if n != self.table.columnCount():
                self.table.setColumnCount(n)
                self.table.setHorizontalHeaderLabels([str(j + 1) for j in range(n)])
        self.set_rows(rows)

    def check(self, v):
        if not isinstance(v, list):
            return f"{self.field.key}: {v!r} is not a list"
        try:
            forms.table_value(self.field, forms.table_rows(self.field, v))
        except ValueError as e:
            return str(e)
        return None


class PairsTable(_TableBase):
    """A mapping with free keys (``A: {4: 7e-13}``): key and value a row; whole-number keys are ints."""

    def __init__(self, field, parent=None):
        super().__init__(field, ["key", "value" + (f" ({field.unit})" if field.unit else "")], parent)

    def _parse(self, rows):
        return forms.pairs_value(self.field, rows)

    def set_value(self, v):
        self.set_rows(forms.pairs_rows(v))


class ChecksWidget(ParamWidget):
    """A list of known choices: one check box each, in the choices' order."""

    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.list = QtWidgets.QListWidget()
        for c in field.item_choices:
            it = QtWidgets.QListWidgetItem(str(c))
            it.setFlags(it.flags() | QtCore.Qt.ItemIsUserCheckable)
            it.setCheckState(QtCore.Qt.Unchecked)
            self.list.addItem(it)
        self.list.setMaximumHeight(self.list.sizeHintForRow(0) * min(len(field.item_choices), 6) + 6)
        self.list.itemChanged.connect(self._emit)
        self.lay.addWidget(self.list, 1)

    def value(self):
        return [c for i, c in enumerate(self.field.item_choices)
                if self.list.item(i).checkState() == QtCore.Qt.Checked]

    def set_value(self, v):
        self.list.blockSignals(True)
        for i, c in enumerate(self.field.item_choices):
            self.list.item(i).setCheckState(QtCore.Qt.Checked if c in (v or []) else QtCore.Qt.Unchecked)
        self.list.blockSignals(False)

    def check(self, v):
        bad = [x for x in v if x not in self.field.item_choices] if isinstance(v, list) else [v]
        return f"{self.field.key}: {bad[0]!r} is not one of {', '.join(map(str, self.field.item_choices))}" \
            if bad else None


class KeptWidget(ParamWidget):
    """A list too long for a form (thousands of deleted rows): shown by its length and kept."""

    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        self.label = QtWidgets.QLabel()
        self.label.setEnabled(False)
        self.lay.addWidget(self.label, 1)
        self._v = None

    def value(self):
        return self._v

    def set_value(self, v):
        self._v = v
        self.label.setText(f"{len(v or []):,} values (kept; edit the recipe file)")


class GroupWidget(ParamWidget):
    """A nested parameter group (``initial: {dx: …}``, a pose): a small form of its fields."""

    def __init__(self, field, parent=None):
        super().__init__(field, parent)
        box = QtWidgets.QFrame()
        box.setFrameShape(QtWidgets.QFrame.StyledPanel)
        form = QtWidgets.QFormLayout(box)
        form.setContentsMargins(4, 2, 4, 2)
        self.children_ = {}
        for f in field.fields:
            w = build_widget(f, f.default)
            w.edited.connect(self._emit)
            w.marked.connect(self.marked)
            label = QtWidgets.QLabel(f.key)
            label.setToolTip(f.tooltip())
            form.addRow(label, w)
            self.children_[f.key] = w
        self.lay.addWidget(box, 1)

    def value(self):
        return forms.group_value({k: w.value() for k, w in self.children_.items()})

    def set_value(self, v):
        v = v or {}
        for k, w in self.children_.items():
            w.set_value(v.get(k, w.field.default))

    def check(self, v):
        if not isinstance(v, dict):
            return f"{self.field.key}: {v!r} is not a mapping"
        unknown = [k for k in v if k not in self.children_]
        if unknown:
            return f"{self.field.key}: unknown key '{unknown[0]}' (it has {', '.join(self.children_)})"
        for k, x in v.items():
            problem = self.children_[k].check(x)
            if problem:
                return problem
        return None


class NullableWidget(ParamWidget):
    """A field where None means automatic or not given: the editor and a box "auto" ("none") that
    disables it; unticking the box enters the editor's value (the default, or one inside the
    bounds)."""

    def __init__(self, field, inner: ParamWidget, parent=None):
        super().__init__(field, parent)
        self.inner = inner
        self.auto = QtWidgets.QCheckBox(field.null_label)
        self.auto.setToolTip("None: " + ("computed by the step" if field.null_label == "auto" else "not given"))
        inner.set_value(forms.initial_value(field))
        inner.edited.connect(self._inner_edited)
        inner.marked.connect(self.marked)
        self.auto.toggled.connect(self._toggled)
        # what the step computed in the last run ("last run: 86.6 mm"), shown while "auto" is ticked
        self.used = QtWidgets.QLabel()
        self.used.setStyleSheet("color:#555")
        self.used.setToolTip("the value the step computed in the last run (its report)")
        self.used.hide()
        self._used_text = ""
        self.lay.addWidget(inner, 1)
        self.lay.addWidget(self.used, 1)
        self.lay.addWidget(self.auto, 0, QtCore.Qt.AlignTop)

    def show_used(self, text: str | None) -> None:
        """The value the step used in the last run, as text (None: no run, or nothing reported)."""
        self._used_text = text or ""
        self.used.setText(f"last run: {self._used_text}" if self._used_text else "")
        self.used.setVisible(bool(self._used_text) and self.auto.isChecked())

    def _inner_edited(self, v):
        if not self.auto.isChecked():
            self.edited.emit(v)

    def _toggled(self, on):
        self.inner.setEnabled(not on)
        self.inner.setHidden(on)  # a greyed "1 mm" read as the value used (the step computes it)
        self.used.setVisible(on and bool(self._used_text))
        self._emit()

    def value(self):
        return None if self.auto.isChecked() else self.inner.value()

    def set_value(self, v):
        _set_quietly(self.auto, self.auto.setChecked, v is None)
        self.inner.setEnabled(v is not None)
        self.inner.setHidden(v is None)  # the step's own value is in its report, not a placeholder
        self.used.setVisible(v is None and bool(self._used_text))
        if v is not None:
            self.inner.set_value(v)

    def check(self, v):
        return None if v is None else self.inner.check(v)


_EDITORS = {"float": NumberWidget, "int": NumberWidget, "bool": BoolWidget, "choice": ChoiceWidget,
            "union": UnionWidget, "text": TextWidget, "file": TextWidget, "tuple": TupleWidget,
            "table": ListTable, "group": GroupWidget, "pairs": PairsTable}


def build_widget(field: FormField, value=None, parent=None) -> ParamWidget:
    """The editor of ``field`` showing ``value`` (the recipe's)."""
    e = field.editor
    if e == "table" and isinstance(value, list) and len(value) > forms.MAX_TABLE_ROWS:
        w = KeptWidget(field)
    elif e == "table" and field.item == "choice":
        w = ChecksWidget(field)
    else:
        w = _EDITORS[e](field)
    if field.nullable:
        w = NullableWidget(field, w)
    if parent is not None:
        w.setParent(parent)
    w.set_value(forms.initial_value(field) if value is None and not field.nullable else value)
    return w


def fits(w: ParamWidget, value) -> bool:
    """Whether ``w`` can show ``value`` (a list that grew past MAX_TABLE_ROWS, or shrank below it,
    needs another widget)."""
    inner = w.inner if isinstance(w, NullableWidget) else w
    long = isinstance(value, list) and len(value) > forms.MAX_TABLE_ROWS
    return not (w.field.editor == "table" and long != isinstance(inner, KeptWidget))
