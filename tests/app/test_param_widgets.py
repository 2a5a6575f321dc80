"""The pipeline dock's parameter forms: core.forms' Qt-free half (editor per field, numbers written
and read back exactly, bounds messages, tables) headless, then the widgets (pytest-qt, offscreen) on
real steps' fields: each kind edits the recipe, bounds are enforced, refusals carry the message."""
from __future__ import annotations

from typing import Literal

import pytest
from pydantic import BaseModel

from pointspro.core import forms
from pointspro.core.forms import form_fields
from pointspro.core.registry import Registry

from ..conftest import EXAMPLE


def _field(step_id, key):
    cls = Registry().load(step_id)
    return next(f for f in form_fields(cls.Params) if f.key == key)


class _Extra(BaseModel):
    """Kinds no installed step has yet: a list of known choices, a mapping with free keys."""
    planes: list[Literal["xy", "yz", "zx"]] = ["xy"]
    A: dict[int, float] = {}


# --- headless: core.forms ------------------------------------------------------------------------

def test_each_real_field_gets_its_editor():
    window = _field("knn_denoise", "window")
    assert (window.editor, window.unit, window.exclusive_minimum) == ("float", "mm", 0)
    assert _field("zernike", "terms").editor == "int"
    assert _field("bspline_map", "extrapolate").editor == "bool"
    ordering = _field("zernike", "ordering")
    assert ordering.editor == "choice" and ordering.choices == ["ansi", "noll", "fringe"]
    remove = _field("knn_denoise", "remove")  # "auto" | int
    assert (remove.editor, remove.choices, remove.number) == ("union", ["auto"], "int")
    diameter = _field("aperture", "diameter")  # None = the surface's aperture
    assert diameter.editor == "float" and diameter.nullable and diameter.null_label == "auto"
    terms = _field("zernike", "remove")  # [piston, tilt] or indices
    assert (terms.editor, terms.item) == ("table", "name_or_int")
    centre = _field("zernike", "centre")
    assert (centre.editor, centre.length, centre.column_titles()) == ("tuple", 2, ["x", "y"])
    vertices = _field("aperture", "vertices")
    assert (vertices.editor, vertices.item, vertices.columns) == ("table", "row", 2)
    initial = _field("misalignment", "initial")
    assert initial.editor == "group" and [f.key for f in initial.fields] == ["alpha_deg", "beta_deg", "dx", "dy", "dz"]
    assert initial.fields[2].unit == "mm" and initial.fields[2].nullable
    matrix = _field("transform", "matrix")
    assert (matrix.editor, matrix.item, matrix.nullable, matrix.null_label) == ("table", "row", True, "none")
    assert _field("dynamic", "calibration").editor == "file"
    extra = {f.key: f for f in form_fields(_Extra)}
    assert (extra["planes"].item, extra["planes"].item_choices) == ("choice", ["xy", "yz", "zx"])
    assert (extra["A"].editor, extra["A"].value_kind) == ("pairs", "float")


def test_numbers_are_written_and_read_back_exactly():
    for v, text in ((3.3333333e-4, "0.00033333333"), (7e-13, "7e-13"), (10.0, "10"), (1 / 3, "0.3333333333333333"),
                    (1e6, "1000000"), (-2.5, "-2.5"), (36, "36")):
        assert forms.format_number(v) == text
        assert forms.parse_number(text, "int" if isinstance(v, int) else "float") == v
    assert forms.parse_number("−2") == -2.0 and forms.parse_number(" 1e-3 ") == 1e-3
    assert forms.parse_number("4.0", "int") == 4
    for bad, kind, msg in (("abc", "float", "'abc' is not a number"), ("nan", "float", "not a finite number"),
                           ("2.5", "int", "'2.5' is not a whole number")):
        with pytest.raises(ValueError, match=msg):
            forms.parse_number(bad, kind)
    assert forms.is_partial_number("1e-") and forms.is_partial_number("-") and not forms.is_partial_number("1e-3")


def test_bounds_messages_steps_and_starting_values():
    window = _field("knn_denoise", "window")
    assert forms.bounds_problem(window, -5.0) == "window must be > 0 mm (got -5 mm)"
    assert forms.bounds_problem(window, 0.0) is not None and forms.bounds_problem(window, 1e-300) is None
    sigma = _field("knn_denoise", "threshold_sigma")  # > 1, ≤ 100
    assert forms.bounds_problem(sigma, 1.0) and forms.bounds_problem(sigma, 100.5) and not forms.bounds_problem(sigma, 100)
    # an arrow moves by a tenth of the value's decade, to that step's decimals, never out of bounds
    assert forms.stepped(window, 1.0, -1) == 0.9 and forms.stepped(window, 0.9, -1) == 0.89
    assert forms.stepped(window, 15.0, 1) == 16.0 and forms.stepped(window, 0.00033, 1) == 0.00034
    inner = _field("aperture", "inner_diameter")  # ≥ 0
    assert forms.stepped(inner, 0.0, -1) == 0.0 and forms.stepped(inner, 0.0, 1) == 1.0
    # unticking "auto" starts from a value the field accepts
    assert forms.initial_value(_field("aperture", "diameter")) == 1.0
    assert forms.initial_value(_field("z_scale", "amplification")) == 1.0  # in (0.5, 2)
    assert forms.initial_value(_field("dynamic", "order")) == 1  # 1 … 8
    assert forms.initial_value(_field("fiducials", "diameter")) == 9.997  # its default
    assert forms.initial_value(_field("zernike", "centre")) == [0.0, 0.0]


def test_tables_stand_for_lists_and_mappings():
    remove = _field("zernike", "remove")
    assert forms.table_rows(remove, ["piston", "tilt", 4]) == [["piston"], ["tilt"], ["4"]]
    assert forms.table_value(remove, [["piston"], [""], [" 4 "], ["coma"]]) == ["piston", 4, "coma"]
    angles = _field("bspline_map", "profile_angles")
    with pytest.raises(ValueError, match=r"profile_angles, row 2: 'x' is not a number"):
        forms.table_value(angles, [["0"], ["x"]])
    vertices = _field("aperture", "vertices")
    assert forms.table_value(vertices, [["0", "0"], ["1e1", "0"], ["10", "5"]]) == [[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]]
    matrix = _field("transform", "matrix")  # a 3 × 4 matrix typed in a 4-column table
    assert forms.table_value(matrix, [["1", "0", "0", "2"], ["0", "1", "0", ""], ["0", "0", "1"]]) \
        == [[1.0, 0.0, 0.0, 2.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    A = {f.key: f for f in form_fields(_Extra)}["A"]
    assert forms.pairs_rows({4: 7e-13, 6: 1e-19}) == [["4", "7e-13"], ["6", "1e-19"]]
    assert forms.pairs_value(A, [["4", "7e-13"], ["6", "1e-19"]]) == {4: 7e-13, 6: 1e-19}
    with pytest.raises(ValueError, match="row 2: key 4 given twice"):
        forms.pairs_value(A, [["4", "1"], ["4", "2"]])


# --- the widgets ---------------------------------------------------------------------------------

@pytest.fixture
def dock(qtbot):
    """The window's pipeline dock on the example recipe (no measurement: the form is what counts)."""
    pytest.importorskip("pytestqt")
    from pointspro.app.main import build_window

    win = build_window([EXAMPLE / "recipe.yaml"])
    qtbot.addWidget(win)
    assert [s.id for s in win.session.recipe.steps] == ["manual_edit", "probe_radius", "misalignment",
                                                        "knn_denoise", "aperture", "zernike", "bspline_map"]
    return win.pipeline


def _step(dock, i):
    return dock.win.session.steps[i]


def test_float_spin_box_with_unit_bounds_and_exact_values(dock, qtbot):
    from PySide6 import QtCore, QtWidgets

    dock.list.setCurrentRow(3)  # knn_denoise: window 15 mm (> 0)
    w = dock.fields["window"]
    spin = w.spin
    assert isinstance(spin, QtWidgets.QDoubleSpinBox) and spin.suffix() == " mm"
    assert spin.value() == 15.0 and spin.text() == "15 mm"
    # typed, scientific notation: the recipe gets the value
    spin.lineEdit().selectAll()
    qtbot.keyClicks(spin, "2.5e1")
    qtbot.keyClick(spin, QtCore.Qt.Key_Return)
    assert _step(dock, 3) == {"knn_denoise": {"window": 25.0}}
    # many decades: shown (in the unit its size asks for) and written back exactly, not rounded to
    # the spin box's decimals
    spacing = dock.fields["spacing"].spin
    spacing.setValue(3.3333333e-4)
    assert spacing.text() == "333.33333 nm" and _step(dock, 3)["knn_denoise"]["spacing"] == 3.3333333e-4
    # an arrow: a tenth of the decade
    spacing.stepBy(1)
    assert _step(dock, 3)["knn_denoise"]["spacing"] == 0.00034 and spacing.text() == "340 nm"
    # out of range (window > 0): refused where it is typed, with the message; the recipe keeps its value
    spin.lineEdit().selectAll()
    qtbot.keyClicks(spin, "-5")
    assert "ffd6d6" in w.styleSheet() and "window must be > 0 mm (got -5 mm)" in w.toolTip()
    assert dock.message.text() == "window must be > 0 mm (got -5 mm)"
    qtbot.keyClick(spin, QtCore.Qt.Key_Return)  # not taken: back to the recipe's value, the message stays
    assert _step(dock, 3)["knn_denoise"]["window"] == 25.0 and spin.value() == 25.0
    assert "(got -5 mm)" in dock.message.text()
    w.enter(0.0)  # on the strict bound: refused too
    assert _step(dock, 3)["knn_denoise"]["window"] == 25.0 and "> 0 mm" in dock.message.text()
    # a value within the bounds that the step's Params refuse: their message, the recipe unchanged
    w.enter(1e-4)
    assert _step(dock, 3)["knn_denoise"]["window"] == 25.0 and "ffd6d6" in w.styleSheet()
    assert "spacing must not exceed window" in dock.message.text()
    w.enter(20.0)
    assert _step(dock, 3)["knn_denoise"]["window"] == 20.0 and w.styleSheet() == "" and dock.message.isHidden()


def test_lengths_are_shown_in_the_unit_their_size_asks_for(dock, qtbot):
    """knn_denoise's floor (1e-05 mm) reads "10 nm", not "1e-05 mm"; the text stays exact, so the
    recipe keeps its value in its own unit (mm) bit for bit, whether the value was typed in the unit
    shown, with its own unit, or not edited at all (leaving the field changes nothing)."""
    from PySide6 import QtCore

    dock.list.setCurrentRow(3)  # knn_denoise: floor 1e-05 mm (its default, not in the recipe)
    w = dock.fields["floor"]
    spin = w.spin
    assert spin.text() == "10 nm" and spin.suffix() == " nm" and w.value() == 1e-05
    got = []
    w.edited.connect(got.append)
    spin.interpretText()  # what leaving the field does: a value shown is not a value entered
    spin.editingFinished.emit()
    assert got == [] and "floor" not in _step(dock, 3)["knn_denoise"] and w.value() == 1e-05
    w.set_value(4.39e-05)
    assert spin.text() == "43.9 nm"

    def typed(text):
        spin.lineEdit().selectAll()  # the number, not the unit shown after it
        qtbot.keyClicks(spin, text)
        qtbot.keyClick(spin, QtCore.Qt.Key_Return)
        return _step(dock, 3)["knn_denoise"].get("floor")

    assert typed("20") == 2e-05 and spin.text() == "20 nm"  # in the unit shown
    assert typed("43.9") == 4.39e-05  # the float64 nearest 4.39e-05, as typed in mm
    assert typed("0.0001 mm") == 1e-04 and spin.text() == "100 nm"  # with its own unit
    assert typed("1.5 µm") == 1.5e-03 and spin.text() == "1.5 µm" and spin.suffix() == " µm"
    assert typed("2um") == 2e-03 and typed("3e-6mm") == 3e-06 and spin.text() == "3 nm"
    # refused where typed, with the value in the unit it was typed in
    spin.lineEdit().selectAll()
    qtbot.keyClicks(spin, "-5")
    assert dock.message.text() == "floor must be ≥ 0 mm (got -5 nm)"
    qtbot.keyClick(spin, QtCore.Qt.Key_Return)
    assert _step(dock, 3)["knn_denoise"]["floor"] == 3e-06
    # tiny and huge values, and ones with 17 digits: shown and read back as the same float64
    from pointspro.app.param_widgets import length_text, parse_length

    for v in (1e-300, 7e-13, 1e-05 / 3, 2.5e-07, 9.9996e-04, 0.1 + 0.2, 1 / 3, 123456.789, 1e4, 1.5e15, 1e300,
              1.7976931348623157e308, 5e-320):
        w.set_value(v)
        text = spin.text()
        spin.interpretText()
        assert w.value() == v and spin.text() == text, (v, text)
        t, unit = length_text(v, "mm")
        assert parse_length(t, unit, "mm") == v and text == f"{t} {unit}"
    assert length_text(1e4, "mm") == ("10", "m") and length_text(1234.5, "mm") == ("1234.5", "mm")
    assert length_text(1e-05 / 3, "mm") == ("3.3333333333333337", "nm")  # repr: 3.3333333333333337e-06
    assert length_text(1e300, "mm") == ("1e+297", "m") and length_text(7e-13, "mm") == ("7e-07", "nm")
    assert got[-1] == 3e-06  # none of those was sent to the recipe

    # the other lengths alike: a group's (mm), a point's, and fields stated in µm and nm
    dock.list.setCurrentRow(2)  # misalignment initial.dx
    dx = dock.fields["initial"].children_["dx"]
    dx.auto.click()
    dx.inner.enter(2.5e-06)
    assert dx.inner.spin.text() == "2.5 nm" and _step(dock, 2) == {"misalignment": {"initial": {"dx": 2.5e-06}}}
    dock.list.setCurrentRow(6)  # bspline_map centre: [x, y] mm
    centre = dock.fields["centre"]
    centre.auto.click()
    centre.inner.spins[0].setValue(-0.0025)
    assert [s.text() for s in centre.inner.spins] == ["x -2.5 µm", "y 0 mm"]
    assert _step(dock, 6)["bspline_map"]["centre"] == [-0.0025, 0.0]
    from pointspro.app.param_widgets import build_widget

    sigma = build_widget(_field("fiducials", "sigma_reference"), 0.2)  # µm in the recipe: "200 nm"
    qtbot.addWidget(sigma)
    assert sigma.spin.text() == "200 nm" and sigma.value() == 0.2
    sigma.spin.lineEdit().selectAll()
    qtbot.keyClicks(sigma.spin, "0.3 mm")
    qtbot.keyClick(sigma.spin, QtCore.Qt.Key_Return)
    assert sigma.value() == 300.0 and sigma.spin.text() == "300 µm"
    tol = build_widget(_field("correction", "fit_tolerance_nm"), 1.0)  # nm in the recipe
    bias = build_widget(_field("correction", "bias_um"), 0.0)
    qtbot.addWidget(tol)
    qtbot.addWidget(bias)
    assert tol.spin.text() == "1 nm" and bias.spin.text() == "0 µm"  # zero: in the recipe's unit


def test_int_spin_box_and_choice_combo(dock, qtbot):
    from PySide6 import QtCore, QtWidgets

    dock.list.setCurrentRow(5)  # zernike
    terms = dock.fields["terms"].spin
    assert isinstance(terms, QtWidgets.QSpinBox) and (terms.minimum(), terms.maximum()) == (1, 231)
    terms.setValue(28)
    assert _step(dock, 5)["zernike"]["terms"] == 28
    terms.lineEdit().selectAll()
    qtbot.keyClicks(terms, "300")
    qtbot.keyClick(terms, QtCore.Qt.Key_Return)
    assert _step(dock, 5)["zernike"]["terms"] == 28
    assert "terms must be ≥ 1, ≤ 231 (got 300)" in dock.fields["terms"].toolTip()
    ordering = dock.fields["ordering"].combo
    assert isinstance(ordering, QtWidgets.QComboBox)
    assert [ordering.itemText(i) for i in range(ordering.count())] == ["ansi", "noll", "fringe"]
    assert ordering.currentText() == "fringe"
    ordering.setCurrentText("noll")
    assert _step(dock, 5)["zernike"]["ordering"] == "noll"
    # the values shown are the recipe's: undo puts the widget back
    dock.win.session.undo()
    assert _step(dock, 5)["zernike"].get("ordering", "fringe") == "fringe"
    assert dock.fields["ordering"].combo.currentText() == "fringe"


def test_list_table_of_names_and_indices(dock):
    dock.list.setCurrentRow(5)  # zernike remove: [piston, tilt]
    w = dock.fields["remove"]
    t = w.table
    assert [t.item(r, 0).text() for r in range(t.rowCount())] == ["piston", "tilt"]
    w.add_button.click()
    t.item(2, 0).setText("astigmatism")
    assert _step(dock, 5)["zernike"]["remove"] == ["piston", "tilt", "astigmatism"]
    # a name the step does not know: the step's Params refuse it, with its message
    t.item(2, 0).setText("bogus")
    assert _step(dock, 5)["zernike"]["remove"] == ["piston", "tilt", "astigmatism"]
    assert "ffd6d6" in w.styleSheet() and "unknown term name 'bogus'" in dock.message.text()
    t.item(2, 0).setText("11")  # an index in the ordering
    assert _step(dock, 5)["zernike"]["remove"] == ["piston", "tilt", 11] and not dock.message.isVisible()
    t.setCurrentCell(0, 0)
    w.remove_button.click()
    assert _step(dock, 5)["zernike"]["remove"] == ["tilt", 11]


def test_bool_auto_box_union_and_group(dock):
    from PySide6 import QtWidgets

    dock.list.setCurrentRow(6)  # bspline_map: spacing 10 mm; extrapolate false
    box = dock.fields["extrapolate"].box
    assert isinstance(box, QtWidgets.QCheckBox) and not box.isChecked()
    box.click()
    assert _step(dock, 6)["bspline_map"]["extrapolate"] is True
    spacing = dock.fields["spacing"]  # None = automatic
    assert not spacing.auto.isChecked() and spacing.inner.spin.value() == 10.0
    spacing.auto.click()
    assert "spacing" not in _step(dock, 6)["bspline_map"] and not spacing.inner.isEnabled()
    assert spacing.inner.isHidden()  # no placeholder number that reads as the value the step used
    spacing.auto.click()  # back: the value it had
    assert _step(dock, 6)["bspline_map"]["spacing"] == 10.0 and not spacing.inner.isHidden()
    centre = dock.fields["centre"]
    centre.auto.click()
    centre.inner.spins[0].setValue(-2.5)
    assert _step(dock, 6)["bspline_map"]["centre"] == [-2.5, 0.0]

    dock.list.setCurrentRow(3)  # knn_denoise remove: auto | a count
    remove = dock.fields["remove"]
    assert remove.combo.currentText() == "auto" and not remove.spin.isEnabled()
    remove.combo.setCurrentText("number")
    remove.spin.setValue(12)
    assert _step(dock, 3)["knn_denoise"]["remove"] == 12
    remove.combo.setCurrentText("auto")
    assert "remove" not in _step(dock, 3)["knn_denoise"]

    dock.list.setCurrentRow(2)  # misalignment initial: {dx: …}, each None = its start
    dx = dock.fields["initial"].children_["dx"]
    dx.auto.click()
    dx.inner.spin.setValue(0.5)
    assert _step(dock, 2) == {"misalignment": {"initial": {"dx": 0.5}}}
    assert dx.inner.spin.text() == "500 µm"  # a length in the unit its size asks for; the recipe's mm


def test_refused_values_are_sent_again_until_the_step_accepts_them(dock):
    """A transform needs exactly one of pose and matrix: switching from one to the other passes
    through refused states; each refused value stays marked and goes with the next edit."""
    s = dock.win.session
    s.add_step("transform", {"pose": {"dz": 1.0}})
    dock.list.setCurrentRow(7)
    pose, matrix = dock.fields["pose"], dock.fields["matrix"]
    assert pose.inner.children_["dz"].spin.value() == 1.0 and matrix.auto.isChecked()
    matrix.auto.click()  # an empty matrix
    assert s.steps[7] == {"transform": {"pose": {"dz": 1.0}}} and "matrix must be 4 × 4" in dock.message.text()
    matrix.inner.set_value([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
    matrix.inner.table.item(2, 3).setText("-3")  # a matrix and a pose
    assert s.steps[7] == {"transform": {"pose": {"dz": 1.0}}} and "exactly one of pose and matrix" in dock.message.text()
    assert "ffd6d6" in matrix.styleSheet()
    pose.auto.click()  # the pose left out: the matrix refused before goes with it
    assert s.steps[7] == {"transform": {"matrix": [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, -3.0]]}}
    assert not dock.message.isVisible() and matrix.styleSheet() == "" and pose.styleSheet() == ""


def test_checks_and_key_value_tables(qtbot):
    from pointspro.app.param_widgets import ChecksWidget, PairsTable, build_widget

    fields = {f.key: f for f in form_fields(_Extra)}
    planes = build_widget(fields["planes"], ["xy"])
    qtbot.addWidget(planes)
    assert isinstance(planes, ChecksWidget)
    got = []
    planes.edited.connect(got.append)
    from PySide6 import QtCore

    planes.list.item(2).setCheckState(QtCore.Qt.Checked)
    assert got[-1] == ["xy", "zx"]
    A = build_widget(fields["A"], {4: 7e-13, 6: 1e-19})
    qtbot.addWidget(A)
    assert isinstance(A, PairsTable) and A.table.item(0, 1).text() == "7e-13"
    A.edited.connect(got.append)
    A.table.item(1, 1).setText("2e-19")
    assert got[-1] == {4: 7e-13, 6: 2e-19}
    A.table.item(1, 1).setText("abc")
    assert got[-1] == {4: 7e-13, 6: 2e-19} and "A, row 2: 'abc' is not a number" in A.problem
