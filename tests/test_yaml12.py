"""Every YAML PointsPro reads is read by the YAML 1.2 core schema (core.yamlio, issue 21): an exponent
without a dot is a number, yes/on/y/n are words, 010 is ten; what PointsPro writes reads back equal."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pointspro.core.errors import InputError, RecipeError
from pointspro.core.recipe import load_recipe, make_step, parse_recipe
from pointspro.core.session.project import load_project, write_project, write_recipe
from pointspro.core.simulate.model import load_model
from pointspro.core.yamlio import LineDict, dump_yaml, load_yaml, read_yaml_mapping

from .conftest import EXAMPLE, write


@pytest.mark.parametrize("text,value", [
    ("3e-4", 3e-4), ("1e3", 1000.0), ("-2.5E+2", -250.0), ("1.", 1.0), (".5", 0.5), ("+1.0e-05", 1e-5),
    ("0x10", 16), ("0o17", 15), ("010", 10), ("-007", -7), ("+12", 12), ("1_000", "1_000"),
    ("1:20", "1:20"), ("yes", "yes"), ("no", "no"), ("on", "on"), ("off", "off"), ("y", "y"),
    ("n", "n"), ("Yes", "Yes"), ("true", True), ("True", True), ("TRUE", True), ("false", False),
    ("FALSE", False), ("tRUE", "tRUE"), ("~", None), ("null", None), ("NULL", None), ("", None),
    ("nil", "nil"), (".inf", math.inf), ("-.Inf", -math.inf), ("+.INF", math.inf), ("inf", "inf"),
    ("2020-01-01", "2020-01-01"), ("0b101", "0b101"), ("0X10", "0X10"), ("1e", "1e"), ("'3e-4'", "3e-4"),
])
def test_plain_scalars_by_the_yaml_1_2_core_schema(text, value):
    got = load_yaml(f"key: {text}\n", "t.yaml")["key"]
    assert got == value and type(got) is type(value), (text, got)


def test_nan():
    assert math.isnan(load_yaml("a: .nan\nb: .NaN\nc: .NAN\n", "t")["a"])
    assert load_yaml("a: nan", "t")["a"] == "nan"


def test_explicit_tags_by_the_same_schema():
    assert load_yaml("a: !!int 010\nb: !!float 3e-4\nc: !!bool true\nd: !!str 3e-4\n", "t") == \
        {"a": 10, "b": 3e-4, "c": True, "d": "3e-4"}
    with pytest.raises(RecipeError, match=r"t.yaml, line 2: cannot read the value tag:yaml.org,2002:bool"):
        load_yaml("a: 1\nb: !!bool yes\n", "t.yaml")
    with pytest.raises(RecipeError, match=r"t.yaml, line 3: cannot read the value tag:yaml.org,2002:int"):
        load_yaml("a: 1\nb: 2\nc: !!int 1_000\n", "t.yaml")


RECIPE = """pointspro: 1
surface: {type: even_asphere, c: 3e-4, k: -1, aperture: 50}
steps:
  - aperture: {diameter: 1e3}
  - manual_edit: {note: yes, remove: [010]}
"""


def test_recipe_exponent_without_a_dot_is_a_number_and_yes_a_word(tmp_path):
    r = load_recipe(write(tmp_path / "r.yaml", RECIPE))
    assert r.surface_spec["c"] == 3e-4 and type(r.surface_spec["c"]) is float  # YAML 1.1: '3e-4'
    assert r.steps[0].params.diameter == 1000.0
    assert r.steps[1].params.note == "yes"  # a string where a string is expected (1.1: True, refused)
    assert r.steps[1].params.remove == [10]  # decimal (1.1: octal 8)
    assert r.build_surface().aperture == 50


def test_yes_is_not_a_number_nor_a_boolean(tmp_path):
    # where a number is expected: refused (YAML 1.1 read `yes` as true, and pydantic took it as 1.0 mm)
    text = RECIPE.replace("{diameter: 1e3}", "{diameter: 10, center_x: yes}")
    with pytest.raises(RecipeError, match=r"r.yaml, line 4: step 1 'aperture': key 'center_x': Input "
                                          r"should be a valid number.*got 'yes'"):
        load_recipe(write(tmp_path / "r.yaml", text))
    # where a boolean is expected: refused too
    text = RECIPE + "    enabled: on\n"
    with pytest.raises(RecipeError, match=r"r.yaml, line 5: step 2 'manual_edit': key 'enabled' must be "
                                          r"true or false"):
        load_recipe(write(tmp_path / "r.yaml", text))
    r = load_recipe(write(tmp_path / "r.yaml", RECIPE + "    enabled: false\n"))
    assert r.steps[1].enabled is False
    # `pointspro: true` is not format 1
    with pytest.raises(RecipeError, match="recipe format True is not supported"):
        load_recipe(write(tmp_path / "r.yaml", RECIPE.replace("pointspro: 1", "pointspro: true")))


def test_line_numbers_and_duplicate_keys_still(tmp_path):
    text = RECIPE.replace("{diameter: 1e3}", "{diameter: -1e3}")
    with pytest.raises(RecipeError, match=r"r.yaml, line 4: step 1 'aperture': key 'diameter': Input "
                                          r"should be greater than 0 \(got -1000.0\)"):
        load_recipe(write(tmp_path / "r.yaml", text))
    with pytest.raises(RecipeError, match=r"r.yaml, line 5: duplicate key 'note'"):
        load_recipe(write(tmp_path / "r.yaml", RECIPE.replace("note: yes", "note: yes, note: on")))
    # keys that are equal once read are duplicates: 010 and 10
    with pytest.raises(RecipeError, match=r"line 2: duplicate key 10"):
        load_yaml("10: a\n010: b\n", "t")
    with pytest.raises(RecipeError, match=r"r.yaml, line 3: not valid YAML \(mapping values are not allowed"):
        load_recipe(write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - a: b: c\n  - aperture\n"))
    d = load_yaml("a: 1\nb:\n  c: 3e-4\n", "t")
    assert isinstance(d, LineDict) and d.key_lines == {"a": 1, "b": 2} and d["b"].key_lines == {"c": 3}


def test_the_example_recipe_reads_as_before():
    r = load_recipe(EXAMPLE / "recipe.yaml")
    again = parse_recipe(load_yaml(r.to_yaml(), "again"), "again")
    assert again.to_dict() == r.to_dict()


# --- projects and measurement models: one reader (read_yaml_mapping) ---------------------------------
def test_project_read_by_yaml_1_2(tmp_path):
    p = write(tmp_path / "p.pointspro.yaml", "pointspro_project: 1\ninput: data.csv\nrecipe:\n"
              "  pointspro: 1\n  surface: {type: even_asphere, c: 3e-4, k: -1, aperture: 50}\n"
              "  steps: [{manual_edit: {note: on}}]\n")
    data = load_project(p)
    assert data["recipe"]["surface"]["c"] == 3e-4
    r = parse_recipe(data["recipe"], str(p))
    assert r.steps[0].params.note == "on"
    write(p, "pointspro_project: 1\ninput: a.csv\ninput: b.csv\n")
    with pytest.raises(InputError, match=r"p.pointspro.yaml, line 3: duplicate key 'input'"):
        load_project(p)
    write(p, "pointspro_project: 1\nrecipe:\n  pointspro: 1\n  steps:\n  - aperture: {diameter: x}\n")
    with pytest.raises(RecipeError, match=r"p.pointspro.yaml, line 5: step 1 'aperture': key 'diameter'"):
        parse_recipe(load_project(p)["recipe"], str(p))
    write(p, "pointspro_project: 2\n")
    with pytest.raises(InputError, match=r"p.pointspro.yaml, line 1: project format 2 is not supported"):
        load_project(p)
    write(p, "- 1\n")
    with pytest.raises(InputError, match=r"p.pointspro.yaml: not a PointsPro project \(no 'pointspro_project: 1'\)"):
        load_project(p)
    with pytest.raises(InputError, match=r"none.yaml: project file not found"):
        load_project(tmp_path / "none.yaml")
    with pytest.raises(InputError, match=r": is a folder, not a project file"):
        load_project(tmp_path)


MODEL = """pointspro_model: 1
surface: {type: even_asphere, c: 3e-4, k: -1, aperture: 50}
scan: {type: spiral, radius: 20, rpm: 30, pitch: 1e-1, fs: 5e2}
probe: {noise: 2e-6}
seed: 010
effects:
  - pose: {alpha_deg: 2e-3, dz: 1e-3}
"""


def test_measurement_model_read_by_yaml_1_2(tmp_path):
    m = load_model(write(tmp_path / "m.yaml", MODEL))
    assert m.seed == 10  # YAML 1.1: octal 8
    assert m.surface["c"] == 3e-4 and type(m.surface["c"]) is float
    assert m.scan.fs == 500.0 and m.probe.noise == 2e-6
    assert m.effects == [{"pose": {"alpha_deg": 2e-3, "dz": 1e-3}}]
    again = load_model(write(tmp_path / "m2.yaml", m.to_yaml()))
    assert again == m
    with pytest.raises(RecipeError, match=r"m.yaml, line 5: key 'seed': Input should be a valid integer"):
        load_model(write(tmp_path / "m.yaml", MODEL.replace("seed: 010", "seed: yes")))
    with pytest.raises(RecipeError, match=r"m.yaml, line 6: duplicate key 'seed'"):
        load_model(write(tmp_path / "m.yaml", MODEL.replace("effects:", "seed: 1\neffects:")))
    with pytest.raises(RecipeError, match=r"m.yaml: not a PointsPro measurement model \(no 'pointspro_model: 1'\)"):
        load_model(write(tmp_path / "m.yaml", MODEL.replace("pointspro_model: 1\n", "")))


def test_read_yaml_mapping_names_the_file(tmp_path):
    p = tmp_path / "x.yaml"
    p.write_bytes(b"a: \xff\n")
    with pytest.raises(InputError, match=r"x.yaml, line 1: not UTF-8 text \(byte 0xff\); save the thing as UTF-8"):
        read_yaml_mapping(p, "thing", "pointspro_thing")
    p.write_text("pointspro_thing: 1.0\n", encoding="utf-8")
    with pytest.raises(RecipeError, match=r"x.yaml, line 1: thing format 1.0 is not supported"):
        read_yaml_mapping(p, "thing", "pointspro_thing", error=RecipeError)
    p.write_text("pointspro_thing: 1\nv: 3e-4\n", encoding="utf-8")
    assert read_yaml_mapping(p, "thing", "pointspro_thing") == {"pointspro_thing": 1, "v": 3e-4}


# --- writing: what PointsPro writes reads back equal ----------------------------------------------------
TRICKY = ["yes", "no", "on", "off", "y", "n", "Y", "N", "True", "FALSE", "~", "null", "", " ", "3e-4",
          "1e3", "1E+3", ".5", "5.", "010", "0o17", "0x1F", "1_000", "1:20", "190:20:30", "2020-01-01",
          "2001-12-14t21:59:43.10-05:00", ".inf", "-.Inf", ".nan", "<<", "=", "- a", "a: b", "#x",
          "'q'", '"q"', "µm", "\t", "line\nbreak", 0, -7, 10**30, 1e-05, 1e16, -0.0, 3e-4, 1.0, 0.1,
          math.inf, -math.inf, True, False, None]


@pytest.mark.parametrize("fast", [False, True])
def test_tricky_values_round_trip(fast):
    for v in TRICKY:
        for data in ([v], {"k": v}, {"k": [v, {"j": v}]}):
            text = dump_yaml(data, fast=fast, sort_keys=False)
            back = load_yaml(text, "dump")
            assert back == data and type(back[0] if isinstance(data, list) else back["k"]) is \
                type(data[0] if isinstance(data, list) else data["k"]), (v, text)
    assert dump_yaml(["yes", "on", "3e-4", "010", "y"]).splitlines() == \
        ["- 'yes'", "- 'on'", "- '3e-4'", "- '010'", "- 'y'"]
    assert dump_yaml([1e-05]) == "- 1.0e-05\n"


PLAIN = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=12)
    | st.sampled_from([v for v in TRICKY if isinstance(v, str)]),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4),
    max_leaves=20)


@settings(max_examples=300, deadline=None)
@given(PLAIN, st.booleans())
def test_any_plain_data_round_trips(data, fast):
    assert load_yaml(dump_yaml(data, fast=fast, sort_keys=False), "dump") == data


def test_recipe_project_and_recipe_file_round_trip(tmp_path):
    r = parse_recipe(load_yaml(RECIPE, "r"), "r")
    steps = [make_step("manual_edit", {"note": v, "remove": [1]}) for v in TRICKY if isinstance(v, str)]
    r = r.with_steps(steps)
    again = parse_recipe(load_yaml(r.to_yaml(), "again"), "again")
    assert [s.params.note for s in again.steps] == [s.params.note for s in steps]
    assert again.to_dict() == r.to_dict()
    write_project(tmp_path / "p.pointspro.yaml", r, None)
    assert parse_recipe(load_project(tmp_path / "p.pointspro.yaml")["recipe"], "p").to_dict() == r.to_dict()
    write_recipe(tmp_path / "r.yaml", r)
    assert load_recipe(tmp_path / "r.yaml").to_dict() == r.to_dict()


def test_boolean_step_parameters_take_true_or_false_only():
    """`repair: yes` reads as the word "yes" (YAML 1.2); a yes/no parameter refuses it by name instead
    of pydantic's lax mode taking it as true."""
    from pointspro.core.errors import RecipeError
    from pointspro.core.recipe import load_yaml, parse_recipe

    text = "pointspro: 1\nsteps:\n  - bspline_map: {extrapolate: on}\n"
    with pytest.raises(RecipeError, match=r"line 3: step 1 'bspline_map': key 'extrapolate': Input should be "
                       r"true or false \(yes, no, on and off are words in YAML 1.2\) \(got 'on'\)"):
        parse_recipe(load_yaml(text, "r.yaml"), "r.yaml")
    ok = parse_recipe(load_yaml(text.replace("on}", "true}"), "r.yaml"), "r.yaml")
    assert ok.steps[0].params.extrapolate is True
