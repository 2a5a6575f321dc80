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
     r"r.yaml, line 6: step 2 'manual_edit': key 'remove': Value error, indices are input rows"),
    (GOOD.replace("alpha_deg: 0.1", "alpha_deg: 0.1, gamma_deg: 3"),
     r"step 3 'transform': key 'pose.gamma_deg': unknown key"),
    (GOOD.replace("k: -0.98", "k: minus"), r"r.yaml, line 2: surface: key 'even_asphere.k'"),
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
