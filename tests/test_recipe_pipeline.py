"""Recipes are validated whole before anything runs; the runner times, reports and cancels."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core.errors import Cancelled, RecipeError, StepError
from pointspro.core.pipeline import run_pipeline
from pointspro.core.progress import CancelToken, Progress
from pointspro.core.recipe import load_recipe, parse_recipe

from .conftest import EXAMPLE, write

GOOD = """pointspro: 1
surface: {type: even_asphere, c: 3.3333333e-4, k: -0.98, A: {4: 7.0e-13, 6: 1.0e-19}, aperture: 1300}
steps:
  - aperture: {diameter: 1200}
  - manual_edit:
      remove: [1, 2, 3]
  - transform: {pose: {alpha_deg: 0.1, dz: 5}, direction: to_measuring}
  - aperture
"""


def test_example_recipe_loads():
    r = load_recipe(EXAMPLE / "recipe.yaml")
    assert [s.id for s in r.steps] == ["manual_edit", "probe_radius", "misalignment", "knn_denoise",
                                       "aperture", "zernike", "bspline_map"]
    assert r.build_surface().aperture == 1300


def test_recipe_parses_and_round_trips(tmp_path):
    r = load_recipe(write(tmp_path / "r.yaml", GOOD))
    assert [s.id for s in r.steps] == ["aperture", "manual_edit", "transform", "aperture"]
    assert r.steps[0].params.diameter == 1200 and r.steps[1].params.remove == [1, 2, 3]
    assert r.steps[2].line == 7
    again = load_recipe(write(tmp_path / "r2.yaml", r.to_yaml()))
    assert [s.params for s in again.steps] == [s.params for s in r.steps]


@pytest.mark.parametrize("text,pattern", [
    (GOOD.replace("aperture: {diameter: 1200}", "knn_magic: {}"),
     r"r.yaml, line 4: step 1: unknown step 'knn_magic'; installed steps: .*aperture"),
    (GOOD.replace("diameter: 1200", "diametre: 1200"),
     r"r.yaml, line 4: step 1 'aperture': key 'diametre': unknown key"),
    (GOOD.replace("diameter: 1200", "diameter: -5"),
     r"r.yaml, line 4: step 1 'aperture': key 'diameter': Input should be greater than 0 \(got -5\)"),
    (GOOD.replace("diameter: 1200", "diameter: big"),
     r"step 1 'aperture': key 'diameter': Input should be a valid number"),
    (GOOD.replace("remove: [1, 2, 3]", "remove: [1, -2]"),
     r"r.yaml, line 6: step 2 'manual_edit': key 'remove': indices are input rows"),
    (GOOD.replace("alpha_deg: 0.1", "alpha_deg: 0.1, gamma_deg: 3"),
     r"step 3 'transform': key 'pose.gamma_deg': unknown key"),
    (GOOD.replace("k: -0.98", "k: minus"), r"r.yaml, line 2: surface: key 'k'"),
    (GOOD.replace("pointspro: 1", "pointspro: 7"), r"line 1: recipe format 7 is not supported"),
    (GOOD.replace("pointspro: 1\n", ""), r"missing `pointspro: 1`"),
    (GOOD + "colour: red\n", r"r.yaml, line 9: unknown key 'colour'"),
    (GOOD.replace("  - aperture\n", "  - aperture: {diameter: 1}\n    manual_edit: {}\n"),
     r"step 4: write one step per list item"),
    ("pointspro: 1\nsteps: [\n", r"r.yaml, line \d+: not valid YAML"),
    ("pointspro: 1\npointspro: 1\n", r"r.yaml, line 2: duplicate key 'pointspro'"),
])
def test_recipe_errors_name_file_line_step_key(tmp_path, text, pattern):
    with pytest.raises(RecipeError, match=pattern):
        load_recipe(write(tmp_path / "r.yaml", text))


def test_missing_recipe(tmp_path):
    with pytest.raises(RecipeError, match="none.yaml: recipe file not found"):
        load_recipe(tmp_path / "none.yaml")


def test_schema_version_migration():
    from pointspro.core.registry import Registry
    from pointspro.core.step import Params, Step, StepResult, param

    class OldParams(Params):
        schema_version = 2
        diameter: float = param(1.0, unit="mm", gt=0, help="d")

        @classmethod
        def migrate(cls, data, from_version):
            data = super().migrate(data, from_version)
            if from_version == 1 and "radius" in data:  # version 1 took a radius
                data = dict(data)
                data["diameter"] = 2 * data.pop("radius")
            return data

    class Mig(Step):
        id, title, Params = "mig_test", "Migration test", OldParams

        def run(self, cloud, params, ctx):
            return StepResult(cloud)

    reg = Registry(extra={"mig_test": Mig})
    r = parse_recipe({"pointspro": 1, "steps": [{"mig_test": {"schema_version": 1, "radius": 3}}]},
                     registry=reg)
    assert r.steps[0].params.diameter == 6
    with pytest.raises(RecipeError, match="newer version"):
        parse_recipe({"pointspro": 1, "steps": [{"mig_test": {"schema_version": 3}}]}, registry=reg)


def test_runner_progress_timing_provenance(raster_cloud):
    r = parse_recipe({"pointspro": 1, "steps": [{"aperture": {"diameter": 1000}},
                                                 {"manual_edit": {"remove": [0, 1]}},
                                                 {"aperture": {"diameter": 500}, "enabled": False}]})
    seen = []
    res = run_pipeline(raster_cloud, r, progress=Progress(lambda f, m: seen.append(f)))
    assert [s.id for s in res.steps] == ["aperture", "manual_edit"]
    assert all(s.seconds >= 0 for s in res.steps)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0)
    assert [p["id"] for p in res.cloud.provenance] == ["aperture", "manual_edit"]
    assert res.cloud.n == res.steps[-1].points_out < raster_cloud.n
    assert np.all(np.hypot(res.cloud.x, res.cloud.y) <= 500)
    s = res.summary()
    # no residual and no nominal: the figures are of the heights after piston and tilt, said so
    assert s["points_in"] == raster_cloud.n and s["figures_of"].startswith("heights, piston and tilt")
    from pointspro.core.pipeline import remove_piston_tilt

    h = remove_piston_tilt(res.cloud.x, res.cloud.y, res.cloud.z)
    assert s["rms_um"] == pytest.approx(np.std(h) * 1e3, rel=1e-12)


def test_runner_cancel_and_step_errors(raster_cloud):
    r = parse_recipe({"pointspro": 1, "steps": [{"aperture": {"diameter": 1000}}]})
    tok = CancelToken()
    tok.cancel()
    with pytest.raises(Cancelled):
        run_pipeline(raster_cloud, r, progress=Progress(None, tok))
    r2 = parse_recipe({"pointspro": 1, "steps": [{"manual_edit": {}}, {"aperture": {}}]})
    with pytest.raises(StepError, match=r"step 2 'aperture': no diameter given and the recipe's "
                                        r"surface has no aperture"):
        run_pipeline(raster_cloud, r2)
    r3 = parse_recipe({"pointspro": 1, "steps": [{"aperture": {"diameter": 1, "center_x": 5000}}]})
    with pytest.raises(StepError, match="no point lies inside the aperture"):
        run_pipeline(raster_cloud, r3)


def test_auxiliary_inputs_resolved_relative_to_recipe(tmp_path):
    write(tmp_path / "fid.csv", "fiducial,x,y,z\n1,0,0,0\n")
    r = load_recipe(write(tmp_path / "r.yaml", "pointspro: 1\ninputs: {fiducials: fid.csv}\nsteps: []\n"))
    assert r.inputs["fiducials"] == tmp_path / "fid.csv"
    with pytest.raises(RecipeError, match=r"r2.yaml, line 2: inputs: key 'ref': file .*nope.csv not found"):
        load_recipe(write(tmp_path / "r2.yaml", "pointspro: 1\ninputs: {ref: nope.csv}\nsteps: []\n"))


def test_terminal_progress_tty_and_plain():
    import io

    from pointspro.core.terminal import TerminalProgress

    class Tty(io.StringIO):
        def isatty(self):
            return True

    plain = io.StringIO()
    p = TerminalProgress(plain, label="[1/1] a.csv")
    p(0.5, "aperture")
    p(0.6, "aperture")  # same message: no new line
    p(1.0, "written")
    assert plain.getvalue().splitlines() == ["[1/1] a.csv  50.0% aperture", "[1/1] a.csv 100.0% written"]
    tty = Tty()
    t = TerminalProgress(tty, label="x")
    t(1.0, "done")
    t.done()
    assert "\r" in tty.getvalue() and "#" * 30 in tty.getvalue() and tty.getvalue().endswith("\n")


# --- true and false are not numbers; one coefficient is written once -----------------------------------
# YAML's true/false load as Python's True/False, the integers 1 and 0 to pydantic's lax mode: without a
# check `radius: true` ran with radius 1.0 and `side: true` with side 1.

def _steps(*entries: str) -> str:
    return "pointspro: 1\nsteps:\n" + "".join(f"  - {e}\n" for e in entries)


@pytest.mark.parametrize("entry, pattern", [
    # float
    ("probe_radius: {radius: true}",
     r"r.yaml, line 3: step 1 'probe_radius': key 'radius': should be a number \(got true\)$"),
    # Optional[float]
    ("aperture: {diameter: false}", r"line 3: step 1 'aperture': key 'diameter': should be a number "
                                    r"\(got false\)$"),
    # int
    ("probe_radius: {radius: 4, neighbours: true}", r"key 'neighbours': should be a number \(got true\)$"),
    # Literal[1, -1]
    ("probe_radius: {radius: 4, side: true}", r"key 'side': should be a number \(got true\)$"),
    # Union[Literal['auto'], int]
    ("knn_denoise: {remove: true}", r"key 'remove': should be a number \(got true\)$"),
    # list[int], list[float], list[str | int]
    ("manual_edit: {remove: [520, true]}",
     r"step 1 'manual_edit': key 'remove': item 2 should be a number \(got true\)$"),
    ("bspline_map: {profile_angles: [0, 45, false]}", r"key 'profile_angles': item 3 should be a number "
                                                      r"\(got false\)$"),
    ("zernike: {remove: [piston, true]}", r"key 'remove': item 2 should be a number \(got true\)$"),
    # list[tuple[int, int]], list[list[float]], tuple[float, float] | None
    ("manual_edit: {remove_ranges: [[1, 5], [7, true]]}",
     r"key 'remove_ranges': item 2's item 2 should be a number \(got true\)$"),
    ("transform: {matrix: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, true], [0, 0, 0, 1]]}",
     r"key 'matrix': item 3's item 4 should be a number \(got true\)$"),
    ("zernike: {centre: [1, false]}", r"key 'centre': item 2 should be a number \(got false\)$"),
    # a field of a nested model
    ("transform: {pose: {dz: true}}", r"step 1 'transform': key 'pose.dz': should be a number \(got true\)$"),
    ("probe_radius: {radius: 4, initial: {alpha_deg: false}}",
     r"key 'initial.alpha_deg': should be a number \(got false\)$"),
])
def test_true_and_false_are_not_numbers_in_step_parameters(tmp_path, entry, pattern):
    with pytest.raises(RecipeError, match=pattern):
        load_recipe(write(tmp_path / "r.yaml", _steps(entry)))


def test_true_and_false_still_fill_yes_no_parameters_and_other_fields_say_their_own(tmp_path):
    r = load_recipe(write(tmp_path / "r.yaml", _steps(
        "probe_radius: {radius: 4, side: -1}", "register: {repair: false}", "bspline_map: {extrapolate: true}",
        "manual_edit: {remove: [520, 3640]}", "knn_denoise: {remove: auto}", "zernike: {remove: [piston, 4]}")))
    p = [s.params for s in r.steps]
    p[0], p[1], p[2], p[3] = p[1], p[2], p[3], p[0]  # as before: register, bspline_map, manual_edit, probe_radius
    assert p[1].extrapolate is True and p[0].repair is False
    assert p[2].remove == [520, 3640] and p[3].radius == 4.0 and p[3].side == -1
    assert p[4].remove == "auto" and p[5].remove == ["piston", 4]
    # a yes/no word is still refused as such; a text field says it wants text (true, as written)
    with pytest.raises(RecipeError, match=r"key 'extrapolate': Input should be true or false"):
        load_recipe(write(tmp_path / "r2.yaml", _steps("bspline_map: {extrapolate: yes}")))
    with pytest.raises(RecipeError, match=r"key 'note': Input should be a valid string \(got true\)$"):
        load_recipe(write(tmp_path / "r3.yaml", _steps("manual_edit: {note: true}")))
    # nor is a number a yes/no (lax mode took 1 as true)
    with pytest.raises(RecipeError, match=r"key 'extrapolate': Input should be true or false \(got 1\)"):
        load_recipe(write(tmp_path / "r4.yaml", _steps("bspline_map: {extrapolate: 1}")))
    with pytest.raises(RecipeError, match=r"key 'repair': Input should be true or false \(got 0\)"):
        load_recipe(write(tmp_path / "r5.yaml", "pointspro: 1\nsurface: {type: mesh, path: m.obj, repair: 0}\n"
                                                "steps: []\n"))


def test_true_is_not_a_number_through_the_python_api_and_the_step_editor():
    from pointspro.core.recipe import make_step

    with pytest.raises(RecipeError, match=r"step 1 'probe_radius': key 'side': should be a number "
                                          r"\(got true\)$"):
        make_step("probe_radius", {"radius": 4, "side": True})
    r = parse_recipe({"pointspro": 1, "steps": [{"aperture": {"diameter": 10}}]})
    with pytest.raises(RecipeError, match=r"key 'diameter': should be a number \(got true\)$"):
        r.with_params(0, {"diameter": True})


SURFACE = "pointspro: 1\nsurface: {surface}\nsteps: []\n"


@pytest.mark.parametrize("surface, pattern", [
    ("{type: even_asphere, c: true, k: -0.98}", r"key 'c': should be a number \(got true\)$"),
    ("{type: even_asphere, c: 3.3e-4, k: false}",
     r"r.yaml, line 2: surface: key 'k': should be a number \(got false\)$"),
    ("{type: even_asphere, c: 3.3e-4, aperture: true}",
     r"key 'aperture': should be a number \(got true\)$"),
    ("{type: even_asphere, c: 3.3e-4, A: {4: 7.0e-13, 6: true}}",
     r"key 'A.6': should be a number \(got true\)$"),
    ("{type: even_asphere, c: 3.3e-4, A: {true: 7.0e-13}}", r"key 'A': key true should be a "
                                                             r"number$"),
    ("{type: qcon, R: 500, norm_radius: 50, a: [1e-4, true]}",
     r"key 'a': item 2 should be a number \(got true\)$"),
    ("{type: xy_polynomial, norm_radius: true, terms: {x2y0: 1e-3}}",
     r"key 'norm_radius': should be a number \(got true\)$"),
    ("{type: mesh, path: part.stl, repair: yes}", r"key 'repair': Input should be true or false"),
])
def test_true_and_false_are_not_numbers_in_the_surface(tmp_path, surface, pattern):
    with pytest.raises(RecipeError, match=pattern):
        load_recipe(write(tmp_path / "r.yaml", SURFACE.format(surface=surface)))


@pytest.mark.parametrize("surface, pattern", [
    # YAML's own duplicate-key check sees "4" and 4 as two keys; the model reads both as A_4
    ('{type: even_asphere, c: 3.3e-4, k: -0.98, A: {"4": 7.0e-13, 4: 1.0e-19}}',
     r"r.yaml, line 2: surface: key 'A': duplicate coefficient 4 \(written as '4' and 4\)$"),
    ('{type: even_asphere, c: 3.3e-4, A: {6: 1.0e-19, "04": 7.0e-13, 4: 1.0e-19}}',
     r"duplicate coefficient 4 \(written as '04' and 4\)$"),
    ('{type: xy_polynomial, terms: {x2y0: 1e-3, x02y0: 2e-3}}',
     r"key 'terms': duplicate term x2y0 \(written as 'x2y0' and 'x02y0'\)$"),
    # the unquoted spellings: YAML's own check (04, 4.0 and +4 are all the number 4)
    ("{type: even_asphere, c: 3.3e-4, A: {04: 7.0e-13, 4: 1.0e-19}}", r"r.yaml, line 2: duplicate key 4$"),
    ("{type: even_asphere, c: 3.3e-4, A: {4.0: 7.0e-13, 4: 1.0e-19}}", r"r.yaml, line 2: duplicate key 4$"),
])
def test_a_coefficient_written_twice_is_refused(tmp_path, surface, pattern):
    with pytest.raises(RecipeError, match=pattern):
        load_recipe(write(tmp_path / "r.yaml", SURFACE.format(surface=surface)))


def test_surface_errors_name_the_line_of_the_key(tmp_path):
    text = ("pointspro: 1\nsurface:\n  type: even_asphere\n  c: 3.3e-4\n  A:\n"
            '    "4": 7.0e-13\n    6: 1.0e-19\n    4: 1.0e-19\nsteps: []\n')
    with pytest.raises(RecipeError, match=r"r.yaml, line 5: surface: key 'A': duplicate "
                                          r"coefficient 4 \(written as '4' and 4 on lines 6 and 8\)$"):
        load_recipe(write(tmp_path / "r.yaml", text))
    text = "pointspro: 1\nsurface:\n  type: even_asphere\n  c: 3.3e-4\n  A:\n    4: 7.0e-13\n    6: true\n"
    with pytest.raises(RecipeError, match=r"r2.yaml, line 7: surface: key 'A.6': should be"):
        load_recipe(write(tmp_path / "r2.yaml", text))
    # a quoted power alone is still the power; the example's surface is unchanged
    ok = load_recipe(write(tmp_path / "r3.yaml", SURFACE.format(
        surface='{type: even_asphere, c: 3.3e-4, A: {"4": 7.0e-13, 6: 1.0e-19}}')))
    assert ok.build_surface().A == {4: 7.0e-13, 6: 1.0e-19}


@pytest.mark.parametrize("edit, override, says", [
    (("radius: 4.0, side: +1", "radius: true, side: +1"), None,
     "line 9: step 2 'probe_radius': key 'radius': should be a number (got true)"),
    (("radius: 4.0, side: +1", "radius: 4.0, side: true"), None,
     "line 9: step 2 'probe_radius': key 'side': should be a number (got true)"),
    (("remove: [520, 3640]", "remove: [520, true]"), None,
     "line 7: step 1 'manual_edit': key 'remove': item 2 should be a number (got true)"),
    (("A: {4: 7.0e-13, 6: 1.0e-19}", 'A: {"4": 7.0e-13, 4: 1.0e-19}'), None,
     "line 4: surface: key 'A': duplicate coefficient 4 (written as '4' and 4)"),
    (None, "probe_radius.radius=true", "key 'radius': should be a number (got true) "
                                       "(with --set probe_radius.radius=true)"),
    (None, "surface.aperture=true", "key 'aperture': should be a number (got true)"),
])
def test_batch_refuses_true_as_a_number_in_one_line_exit_2(run_cli, tmp_path, edit, override, says):
    text = (EXAMPLE / "recipe.yaml").read_text(encoding="utf-8")
    if edit:
        assert edit[0] in text
        text = text.replace(edit[0], edit[1])
    recipe = write(tmp_path / "recipe.yaml", text)
    code, out, err = run_cli("--batch", recipe, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o",
                             "--figures", "none", *(["--set", override] if override else []))
    assert code == 2, err
    assert says in err and str(recipe) in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o" / "asphere_cmm").exists()


def test_a_step_after_every_point_was_removed_names_the_step_that_removed_them():
    """A manual_edit that removes every row, then probe_radius: the input failed as "internal error
    ValueError: attempt to get argmax of an empty sequence — please report" (a review)."""
    import numpy as np

    from pointspro.core import PointCloud
    from pointspro.core.errors import StepError
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import parse_recipe

    rec = parse_recipe({"pointspro": 1,
                        "surface": {"type": "even_asphere", "c": 0.01, "k": 0, "aperture": 20},
                        "steps": [{"manual_edit": {"remove_ranges": [[0, 1000]]}},
                                  {"probe_radius": {"radius": 1.0, "side": 1}}]})
    x = np.linspace(-5, 5, 50)
    cloud = PointCloud.from_xyz(x, np.zeros(50), 0.005 * x**2)
    with pytest.raises(StepError, match=r"step 2 'probe_radius': no point is left to process — "
                                        r"step 1 'manual_edit' removed them all"):
        run_pipeline(cloud, rec)
