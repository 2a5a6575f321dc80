"""The batch's "does this output folder hold an input?" check, asked once per input, answered from the
inputs resolved once (core/io/atomic.py InputPlaces): the same answers as resolving every input for
each folder, and no N² path resolution (issue 17: 200 inputs spent 0.65 s on it before the first
input started)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from pointspro.core.batch import check_output_targets
from pointspro.core.errors import RecipeError
from pointspro.core.io.atomic import InputPlaces, why_not_replace


def test_places_name_the_input_a_folder_is_or_holds(tmp_path):
    a = tmp_path / "out" / "part" / "part.csv"
    b = tmp_path / "data" / "b.csv"
    for p in (a, b):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("x,y,z\n")
    places = InputPlaces([a, b])
    assert places.held_by((tmp_path / "out" / "part").resolve()) == a
    assert places.held_by((tmp_path / "out").resolve()) == a
    assert places.held_by(b.resolve()) == b
    assert places.held_by((tmp_path / "elsewhere").resolve()) is None
    assert why_not_replace(tmp_path / "out" / "part", "report.json", places) == ("input", a)
    assert why_not_replace(tmp_path / "data" / "other", "report.json", places) is None


def test_the_first_input_given_is_named_where_several_share_a_folder(tmp_path):
    (tmp_path / "d").mkdir()
    first, second = tmp_path / "d" / "1.csv", tmp_path / "d" / "2.csv"
    assert InputPlaces([first, second]).held_by((tmp_path / "d").resolve()) == first
    assert InputPlaces([second, first]).held_by((tmp_path / "d").resolve()) == second


def test_an_input_reached_through_a_link_is_found_where_it_lies(tmp_path):
    real = tmp_path / "o" / "part"
    real.mkdir(parents=True)
    (real / "part.csv").write_text("x,y,z\n")
    (tmp_path / "link").symlink_to(real)
    linked = tmp_path / "link" / "part.csv"
    assert why_not_replace(tmp_path / "o" / "part", "report.json", [linked]) == ("input", linked)
    assert why_not_replace(tmp_path / "o" / "part", "report.json", InputPlaces([linked])) == ("input", linked)


def test_many_inputs_checked_without_resolving_each_for_every_folder(tmp_path, monkeypatch):
    """Counts Path.resolve calls: linear in the inputs (was N² + N: 40,200 for 200 inputs)."""
    (tmp_path / "in").mkdir()
    inputs = []
    for k in range(200):
        p = tmp_path / "in" / f"m{k:03d}.csv"
        p.write_text("x,y,z\n")
        inputs.append(p)
    calls = 0
    resolve = Path.resolve

    def counting(self, *a, **kw):
        nonlocal calls
        calls += 1
        return resolve(self, *a, **kw)

    monkeypatch.setattr(Path, "resolve", counting)
    check_output_targets(tmp_path / "out", inputs, [p.stem for p in inputs])
    assert calls <= 4 * len(inputs)


def test_an_input_inside_its_own_output_folder_is_still_refused(tmp_path):
    inside = tmp_path / "out" / "m1" / "m1.csv"
    inside.parent.mkdir(parents=True)
    inside.write_text("x,y,z\n")
    other = tmp_path / "m0.csv"
    other.write_text("x,y,z\n")
    with pytest.raises(RecipeError, match=r"m1\.csv: lies in .*out.m1, the output folder of"):
        check_output_targets(tmp_path / "out", [other, inside], ["m0", "m1"])
    assert os.path.exists(inside)
