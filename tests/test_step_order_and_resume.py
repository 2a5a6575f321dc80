"""What an independent review of the command found accepted with exit 0 (2026-11-26): steps in an order
that silently gives a wrong result, keys of another aperture shape, an input named `..csv`, a
--resume that trusted an incomplete folder, warnings nobody saw."""
from __future__ import annotations

import json
import re

import pytest

from pointspro.core.errors import RecipeError
from pointspro.core.recipe import load_recipe

from .conftest import EXAMPLE, write

SURFACE = ("surface: {type: even_asphere, c: 3.3333333333333335e-4, k: -0.98, "
           "A: {4: 7.0e-13, 6: 1.0e-19}, aperture: 1300}\n")
DATA = EXAMPLE / "asphere_cmm.csv"


def recipe(tmp_path, *steps, name="r.yaml"):
    return write(tmp_path / name, "pointspro: 1\n" + SURFACE + "steps:\n"
                 + "".join(f"  - {s}\n" for s in steps))


@pytest.mark.parametrize("first", ["bspline_map: {}", "zernike: {terms: 4}", "correction: {}"])
def test_a_form_error_step_before_the_residual_is_made_is_refused(tmp_path, first):
    """A review: bspline_map first wrote map.asc of the part's sag (71.8 mm PV) with exit 0."""
    r = recipe(tmp_path, "probe_radius: {radius: 4.0}", first, "misalignment: {}")
    step = first.split(":")[0]
    with pytest.raises(RecipeError, match=rf"r\.yaml, line 5: step 2 '{step}' works on the form error "
                                          rf"\(the residual\), which step 3 'misalignment' makes later"):
        load_recipe(r)


def test_the_order_rule_spares_disabled_steps_and_heights_asked_for_by_name(tmp_path):
    load_recipe(recipe(tmp_path, "bspline_map: {channel: z}", "misalignment: {}"))
    # between two misalignments (a second pass on the kept points): a residual is there (a review)
    load_recipe(recipe(tmp_path, "misalignment: {}", "bspline_map: {}", "aperture: {diameter: 1200}",
                       "misalignment: {}", "zernike: {}"))
    load_recipe(recipe(tmp_path, "{zernike: {terms: 4}, enabled: false}", "misalignment: {}"))
    load_recipe(recipe(tmp_path, "misalignment: {}", "zernike: {}", "bspline_map: {}"))


def test_the_order_rule_holds_for_recipes_edited_in_the_window_too(tmp_path):
    """The window and the Python API insert steps without parsing a file: run_pipeline checks too."""
    from pointspro.core.io import read_cloud
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import make_step

    r = load_recipe(recipe(tmp_path, "misalignment: {}"))
    r = r.inserted(make_step("zernike", {"terms": 4}), at=0)
    with pytest.raises(RecipeError, match="step 1 'zernike' works on the form error"):
        run_pipeline(read_cloud(DATA), r)


def test_moving_the_points_after_the_residual_was_made_is_refused(run_cli, tmp_path):
    """A review: probe_radius after misalignment kept the probe centres' residual (RMS 27.8 µm for a
    true 0.99 µm), exit 0."""
    r = recipe(tmp_path, "misalignment: {}", "probe_radius: {radius: 4.0, side: 1}")
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o", "--figures", "none", "--quiet")
    assert code == 2  # refused with the recipe, before any input (--check-only called it ready)
    assert ("step 2 'probe_radius' moves the points, but the residual (the form error) is made before "
            "it by step 1 'misalignment' and would no longer match them, and it would be written as the "
            "form error — move 'probe_radius' before 'misalignment', or make the residual again right "
            "after it (misalignment, register)") in err
    assert run_cli("--batch", r, DATA, "--out", tmp_path / "oc", "--check-only")[0] == 2
    # a step after it using the stale residual is named
    r = recipe(tmp_path, "misalignment: {}", "probe_radius: {radius: 4.0, side: 1}", "zernike: {terms: 4}",
               name="z.yaml")
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o3", "--figures", "none", "--quiet")
    assert code == 2 and "and step 3 'zernike' would use it — move 'probe_radius' before 'misalignment'" in err
    # a residual made again, but only after a step that uses the stale one: still refused
    late = recipe(tmp_path, "misalignment: {}", "probe_radius: {radius: 4.0, side: 1}", "zernike: {terms: 4}",
                  "misalignment: {}", name="late.yaml")
    code, _, err = run_cli("--batch", late, DATA, "--out", tmp_path / "o6", "--check-only")
    assert code == 2 and "step 3 'zernike' would use it" in err
    # made again right after the move (a review: refused at first), or a residual column in the input
    # that misalignment replaces (a PointsPro cloud.csv read again): fine
    again = recipe(tmp_path, "misalignment: {}", "probe_radius: {radius: 4.0, side: 1}", "misalignment: {}",
                   "zernike: {terms: 4}", name="again.yaml")
    assert run_cli("--batch", again, DATA, "--out", tmp_path / "o4", "--figures", "none", "--quiet")[0] == 0
    lines = DATA.read_text(encoding="utf-8").splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("x,"))
    rows = [ln + ",0.0" for ln in lines[head + 1:] if ln.strip()]
    with_res = write(tmp_path / "with_res.csv", "\n".join([lines[head] + ",residual", *rows]) + "\n")
    code, out, err = run_cli("--batch", EXAMPLE / "recipe.yaml", with_res, "--out", tmp_path / "o5",
                             "--figures", "none")
    assert code == 0, err
    # moved and the residual made again after it: fine
    ok = recipe(tmp_path, "probe_radius: {radius: 4.0, side: 1}", "misalignment: {}", name="ok.yaml")
    assert run_cli("--batch", ok, DATA, "--out", tmp_path / "o2", "--figures", "none", "--quiet")[0] == 0


def test_probe_radius_twice_is_refused(run_cli, tmp_path):
    r = recipe(tmp_path, "probe_radius: {radius: 4.0, side: 1}", "probe_radius: {radius: 4.0, side: 1}",
               "misalignment: {}")
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o", "--figures", "none", "--quiet")
    assert code != 0 and "step 2 'probe_radius': the points are contact points already" in err


def test_correction_of_heights_z_on_a_curved_part_with_a_residual_is_refused(run_cli, tmp_path):
    """A review: channel z after misalignment wrote dz ≈ −34 mm under a 'form error = residual' header."""
    r = recipe(tmp_path, "probe_radius: {radius: 4.0, side: 1}", "misalignment: {}", "correction: {channel: z}")
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o", "--figures", "none", "--quiet")
    assert code != 0 and "step 3 'correction': channel 'z' asked for, but z holds the part's heights" in err


@pytest.mark.parametrize("params, pattern", [
    ("{shape: circle, inner_diameter: 100}", "inner_diameter is for shape: annulus, not circle"),
    ("{shape: circle, vertices: [[0, 0], [100, 0], [0, 100]]}", "vertices are for shape: polygon"),
    ("{shape: annulus, diameter: 1200, inner_diameter: 100, vertices: [[0, 0], [1, 0], [0, 1]]}",
     "vertices are for shape: polygon, not annulus"),
    ("{shape: polygon, diameter: 100, vertices: [[0, 0], [100, 0], [0, 100]]}",
     "diameter: not used by shape: polygon"),
    ("{shape: polygon, vertices: [[0, 0], [100, 100], [100, 0], [0, 100]]}",
     "the polygon's edges 1 and 3 cross"),
])
def test_aperture_keys_of_another_shape_and_crossing_polygons_are_refused(tmp_path, params, pattern):
    with pytest.raises(RecipeError, match=rf"line 4: step 1 'aperture': .*{pattern}"):
        load_recipe(recipe(tmp_path, f"aperture: {params}"))


def test_simple_polygons_pass_the_crossing_test():
    from pointspro.core.geometry.polygon import self_intersection

    assert self_intersection([[0, 0], [4, 0], [4, 4], [2, 1], [0, 4]]) is None  # concave
    assert self_intersection([[0, 0], [1, 0], [0, 1]]) is None
    assert self_intersection([[0, 0], [1, 1], [1, 0], [0, 1]]) == (0, 2)
    # touching and running along are allowed (a review): a ring closed on its first vertex, a repeated
    # vertex, a keyhole (a hole joined to the outline by a cut walked both ways)
    assert self_intersection([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]) is None
    assert self_intersection([[0, 0], [1, 0], [1, 0], [1, 1], [0, 1]]) is None
    assert self_intersection([[0, 0], [10, 0], [10, 10], [0, 10], [0, 5], [4, 5], [4, 6], [6, 6], [6, 4],
                              [4, 4], [4, 5], [0, 5]]) is None
    assert self_intersection([[0, 0], [10, 0], [10, 10], [0, 10], [0, 5], [12, 6]]) is not None


@pytest.mark.parametrize("text, pattern", [
    ("pointspro: 1\n", r"missing `steps:`"),
    ("pointspro: 1\nsteps:\n", r"steps: is empty — give the list of steps, or `steps: \[\]` for none"),
])
def test_a_recipe_without_steps_is_refused_but_an_empty_list_is_a_choice(tmp_path, text, pattern):
    with pytest.raises(RecipeError, match=pattern):
        load_recipe(write(tmp_path / "r.yaml", text))
    assert load_recipe(write(tmp_path / "e.yaml", "pointspro: 1\nsteps: []\n")).steps == []


@pytest.mark.parametrize("name", ["..csv", "...csv"])
def test_an_input_whose_name_gives_no_folder_is_refused(run_cli, tmp_path, name):
    """A review: `..csv` (stem ".") wrote its results into --out itself, replacing another input's."""
    sub = tmp_path / "in"
    sub.mkdir()
    bad = sub / name
    bad.write_bytes(DATA.read_bytes())
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine", encoding="utf-8")
    code, _, err = run_cli("--batch", EXAMPLE / "recipe.yaml", DATA, bad, "--out", out, "--figures", "none")
    assert code != 0 and f"{bad}: its name gives no output folder name" in err
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"


def test_resume_runs_again_what_is_incomplete_or_drawn_with_fewer_figures(run_cli, tmp_path):
    rec, out = EXAMPLE / "recipe.yaml", tmp_path / "o"

    def status(*extra):
        code, _, err = run_cli("--batch", rec, DATA, "--out", out, "--resume", "--quiet", *extra)
        assert code == 0, err
        return json.loads((out / "summary.json").read_text(encoding="utf-8"))["inputs"][0]["status"]

    assert status("--figures", "none") == "ok"
    rep = json.loads((out / "asphere_cmm" / "report.json").read_text(encoding="utf-8"))
    assert set(rep["files"]) == {p.name for p in (out / "asphere_cmm").iterdir()}
    assert status("--figures", "none") == "skipped"
    (out / "asphere_cmm" / "map.csv").unlink()  # a review: reported "skipped" with map.csv missing
    assert status("--figures", "none") == "ok"
    assert (out / "asphere_cmm" / "map.csv").is_file()
    assert status("--figures", "all") == "ok"  # drawn with none before: run again to draw them
    assert (out / "asphere_cmm" / "map.png").is_file()
    (out / "asphere_cmm" / "form_error.png").unlink()  # the summary's figure, no step's (a review)
    assert status("--figures", "all") == "ok"
    assert (out / "asphere_cmm" / "form_error.png").is_file()
    assert status("--figures", "none") == "skipped"  # more figures than asked: still complete


def test_negative_line_numbers_are_refused(tmp_path):
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud

    f = write(tmp_path / "l.csv", "x,y,z,line\n0,0,0,0\n1,0,0,-1\n0,1,0,1\n")
    with pytest.raises(InputError, match=r"l\.csv, line 3, column 4 \(line\): -1\.0 is not a whole number "
                                         r"from 0 to below 2⁵³"):
        read_cloud(f)


def test_step_warnings_reach_the_terminal(run_cli, tmp_path):
    """A review: warnings were only in report.json; knn_denoise on the heights of a curved part (no
    residual yet) found 0 of the example's spikes and said nothing."""
    r = recipe(tmp_path, "knn_denoise: {window: 15.0}", "probe_radius: {radius: 4.0, side: 1}",
               "misalignment: {}")
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o", "--figures", "none")
    assert code == 0
    assert "asphere_cmm.csv: warning: 'knn_denoise': the cloud has no residual yet" in err
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o2", "--figures", "none", "--quiet")
    assert "warning" not in err


@pytest.mark.parametrize("value", ["1_290", "'1290'"])
def test_a_number_written_as_text_is_refused(tmp_path, value):
    """YAML 1.2 reads 1_290 and '1290' as text; pydantic's lax mode made them the number (a review)."""
    with pytest.raises(RecipeError, match=r"key 'diameter': Input should be a number, not text"):
        load_recipe(recipe(tmp_path, f"aperture: {{diameter: {value}}}"))


@pytest.mark.parametrize("step,where,got", [
    ("manual_edit: {remove: ['520', '3640']}", "key 'remove': item 1", "'520'"),
    ("manual_edit: {remove: [12, 5_20]}", "key 'remove': item 2", "'5_20'"),
    ("manual_edit: {remove_ranges: [[1, '5']]}", "key 'remove_ranges': item 1's item 2", "'5'"),
    ("transform: {matrix: [[1_0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}",
     "key 'matrix': item 1's item 1", "'1_0'"),
    ("aperture: {shape: polygon, vertices: [[0, 0], [100, 0], [100, '1e2'], [0, 100]]}",
     "key 'vertices': item 3's item 2", "'1e2'"),
    ("z_scale: {calibration: c.csv, heights: ['3', 3]}", "key 'heights': item 1", "'3'"),
])
def test_numbers_written_as_text_inside_lists_are_refused(tmp_path, step, where, got):
    """Inside a list or a matrix too (a review: `matrix: [[1_0, …]]` ran as a ×10 scale with exit 0,
    `remove: ['520']` removed row 520): the same refusal as a single value, naming the item."""
    with pytest.raises(RecipeError, match=rf"{re.escape(where)}: Input should be a number, not text .*\(got {re.escape(got)}\)"):
        load_recipe(recipe(tmp_path, step))


def test_text_where_text_is_allowed_is_judged_as_text(tmp_path):
    """Zernike's `remove` takes names and indices: "4" is an unknown name, said as such — not "a
    number, not text" (a review of the list check)."""
    with pytest.raises(RecipeError, match="unknown term name '4'"):
        load_recipe(recipe(tmp_path, "zernike: {terms: 15, remove: [piston, '4']}"))


def test_lists_of_numbers_and_words_still_read(tmp_path):
    r = load_recipe(recipe(tmp_path, "manual_edit: {remove: [3, 520], remove_ranges: [[1, 5]]}",
                           "zernike: {terms: 15, remove: [piston, tilt, 4]}"))
    assert list(r.steps[0].params.remove) == [3, 520]
    assert list(r.steps[1].params.remove) == ["piston", "tilt", 4]


def test_a_failed_rerun_says_the_folder_holds_the_earlier_outputs(run_cli, tmp_path):
    """Outputs are swapped in only when complete: after a failed re-run the folder still holds the last
    good run's files, which looked current beside a summary.json saying "failed" (a review)."""
    out = tmp_path / "o"
    assert run_cli("--batch", EXAMPLE / "recipe.yaml", DATA, "--out", out, "--figures", "none", "--quiet")[0] == 0
    bad = recipe(tmp_path, "aperture: {diameter: 1.0e-6}")
    code, _, err = run_cli("--batch", bad, DATA, "--out", out, "--figures", "none", "--quiet")
    assert code != 0
    assert f"asphere_cmm.csv: {out / 'asphere_cmm'} still holds an earlier run's outputs" in err


def test_a_ball_larger_than_the_parts_curvature_is_named_when_the_fit_fails():
    """A review: 55 mm on a 50 mm sphere read "outside the conic's domain … check units"."""
    import numpy as np

    from pointspro.core import PointCloud
    from pointspro.core.errors import StepError
    from pointspro.core.step import Context
    from pointspro.core.surfaces import surface_from_spec
    from pointspro.plugins.probe_radius import ProbeRadiusStep

    sphere = surface_from_spec({"type": "even_asphere", "c": 0.02, "k": 0, "aperture": 40})
    g = np.arange(-17.6, 17.7, 0.88)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    k = np.hypot(x, y) <= 18
    x, y = x[k], y[k]
    r = np.hypot(x, y)
    nz = np.sqrt(1 - (r / 50) ** 2)
    centres = PointCloud.from_xyz(x + 6 * x / 50, y + 6 * y / 50, sphere.sag(x, y) + 6 * nz)  # a 6 mm ball
    with pytest.raises(StepError, match=r"the probe radius 55 mm exceeds the part's local radius of "
                                        r"curvature \(50 mm"):
        ProbeRadiusStep().run(centres, ProbeRadiusStep.Params(radius=55, side=1), Context(surface=sphere))


def test_a_tiny_map_spacing_is_one_short_line(run_cli, tmp_path):
    """A review: spacing 1e-300 printed an overflow RuntimeWarning and a 600-digit node count."""
    code, _, err = run_cli("--batch", EXAMPLE / "recipe.yaml", DATA, "--out", tmp_path / "o", "--quiet",
                           "--figures", "none", "--set", "bspline_map.spacing=1e-300")
    assert code != 0 and "RuntimeWarning" not in err
    assert "a 1.29e+303 × 1.29e+303 map at spacing 1e-300 mm is too large (at most 25 million nodes)" in err  # the recipe's 1290 mm aperture


def test_one_wild_height_is_named_not_read_as_a_line(run_cli, tmp_path):
    """A review: one z of 1e12 mm among the example's points read "all points lie on a line"."""
    lines = DATA.read_text(encoding="utf-8").splitlines()
    k = next(i for i, ln in enumerate(lines) if ln[:1].isdigit() or ln[:1] == "-") + 5
    parts = lines[k].split(",")
    lines[k] = ",".join([*parts[:2], "1e12", *parts[3:]])
    wild = write(tmp_path / "wild.csv", "\n".join(lines) + "\n")
    code, _, err = run_cli("--batch", EXAMPLE / "recipe.yaml", wild, "--out", tmp_path / "o", "--figures", "none")
    assert code != 0
    assert "1 point(s) lie absurdly far from the others in z (z = 1e+12 mm" in err
    assert "line" not in err.split("absurdly")[0]


@pytest.mark.parametrize("step, name", [("zernike: {}", "zernike"), ("bspline_map: {}", "bspline_map")])
def test_the_sag_of_a_curved_part_is_not_taken_for_its_form_error(run_cli, tmp_path, step, name):
    """A review: zernike alone on the example (no misalignment) reported the sag less its Zernike terms
    as a 13.9 µm RMS form error, exit 0. An instrument's height map under a curved nominal (µm against
    the sag's mm) is still mapped (tests/test_pupil.py)."""
    code, _, err = run_cli("--batch", recipe(tmp_path, step), DATA, "--out", tmp_path / "o", "--figures", "none",
                           "--quiet")
    assert code != 0
    assert (f"step 1 '{name}': the cloud has no residual, and its heights z are the part's sag, not its "
            "form error") in err


def test_an_uncertainty_block_with_the_dynamic_step_is_refused(tmp_path):
    """The Monte Carlo adds noise to z, which dynamic rebuilds from xd and xc: every sample failed,
    blaming the data, or with tiny noise u read 4e-15 µm (a review)."""
    r = write(tmp_path / "d.yaml", "pointspro: 1\nuncertainty: {samples: 50, noise: \"5 nm\"}\nsteps:\n"
                                   "  - dynamic: {model: m.json}\n")
    (tmp_path / "m.json").write_text("{}", encoding="utf-8")
    with pytest.raises(RecipeError, match=r"d\.yaml, line 2: uncertainty: the Monte Carlo perturbs the heights "
                                          r"z, which the recipe's 'dynamic' step rebuilds"):
        load_recipe(r)


def test_a_bad_surface_in_a_measurement_model_is_one_line(run_cli, tmp_path):
    """A review: `R: 0` in a model file was "internal error: ValidationError" from explain and a
    multi-line pydantic dump from simulate."""
    m = write(tmp_path / "m.yaml", "pointspro_model: 1\nsurface: {type: even_asphere, R: 0, k: -0.5}\n"
                                   "scan: {type: raster, radius: 20.0}\n")
    code, _, err = run_cli("simulate", m, "--out", tmp_path / "s.csv")
    assert code == 2 and "internal error" not in err
    assert err.strip().splitlines() == [f"pointspro: {m}, line 2: surface: R must not be 0 "
                                        "(use c: 0 for a flat)"]


@pytest.mark.parametrize("edit, pattern", [
    (lambda rows: rows[:3] + [rows[2]] + rows[3:], r"fiducial 3 has 2 rows; give each ball's calibrated centre once"),
    (lambda rows: rows[:2] + [rows[2].replace("3,", "3.6,", 1)] + rows[3:], r"fiducial id 3\.6 \(row 3 of the data\) "
                                                                             r"is not a whole number"),
])
def test_a_reference_with_a_repeated_or_fractional_ball_id_is_refused(tmp_path, edit, pattern):
    """A review: of two rows of one id the first was taken (Ev 4.5 µm, χ² 1e9, exit 0); 3.6 became 3."""
    from pointspro.core import PointCloud
    from pointspro.core.calibration.fiducial_sim import case_000
    from pointspro.core.errors import InputError
    from pointspro.core.step import Context
    from pointspro.plugins.fiducials import FiducialsStep

    c = case_000(0, "fourier")
    head, *rows = c.reference_csv().strip().splitlines()
    assert rows[2].startswith("3,")
    (tmp_path / "reference.csv").write_text("\n".join([head, *edit(rows)]) + "\n", encoding="utf-8")
    cloud = PointCloud.from_xyz(*c.points.T, fiducial=c.ids)
    with pytest.raises(InputError, match=pattern):
        FiducialsStep().run(cloud, FiducialsStep.Params(reference="reference.csv"), Context(base_dir=tmp_path))


def test_a_noise_far_below_the_datas_is_warned_of(run_cli, tmp_path):
    """A review: noise "1e-9 nm" on the example (~0.3 µm of noise) gave U95 7e-13 µm and "conforms"."""
    text = (EXAMPLE / "recipe.yaml").read_text(encoding="utf-8") + 'uncertainty: {samples: 50, noise: "1e-9 nm"}\n'
    r = write(tmp_path / "u.yaml", text)
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o", "--figures", "none")
    assert code == 0
    assert "asphere_cmm.csv: warning: 'uncertainty': the given noise σ 1e-09 nm is below a tenth of" in err


def test_a_simulation_on_other_positions_is_carried_along_its_slope_and_must_cover_the_scan(tmp_path):
    """explain --simulated matched each measured point to the nearest simulated one and took its height
    as it was: 0.35 mm on a sloped part made an 8 µm "gap" and five effects named; a simulation of a
    5 mm disc "explained" a measurement 15 mm across (a review)."""
    import numpy as np

    from pointspro.core import PointCloud
    from pointspro.core.errors import InputError
    from pointspro.core.explain.workflow import against_simulation
    from pointspro.core.io import write_cloud

    def f(x, y):
        return 0.01 * x + 0.002 * (x * x + y * y)   # 10 mrad of slope, gentle curvature (mm)

    g = np.arange(-10.0, 10.01, 0.5)
    X, Y = (a.ravel() for a in np.meshgrid(g, g))
    t = np.arange(X.size) / 100.0
    sim = PointCloud.from_xyz(X, Y, f(X, Y), t=t, c=np.degrees(np.arctan2(Y, X)) % 360)
    sim.meta["channel_units"] = {"t": "s", "c": "deg"}
    write_cloud(sim, tmp_path / "sim.csv")
    xm, ym = X[:-60] + 0.2, Y[:-60] + 0.15
    meas = PointCloud.from_xyz(xm, ym, f(xm, ym))
    ctx, z_sim, match = against_simulation(meas, tmp_path / "sim.csv")
    assert "the simulation's heights there from its smooth fit" in match
    nearest_error = np.max(np.abs(f(X[:-60], Y[:-60]) - f(xm, ym)))   # what the nearest height was off by
    assert nearest_error > 2e-3 and np.max(np.abs(z_sim - f(xm, ym))) < 0.05 * nearest_error
    far = PointCloud.from_xyz(xm * 3, ym * 3, f(xm * 3, ym * 3))
    with pytest.raises(InputError, match=r"sim\.csv: \d+ measured point\(s\) lie up to .* mm from any simulated point"):
        against_simulation(far, tmp_path / "sim.csv")


def test_resume_runs_again_when_a_file_the_recipe_names_changed(run_cli, tmp_path):
    """A re-calibrated artefact's file under the same name: --resume kept the old amplification (3 %
    off, exit 0 — a review); now the recipe's files' digests are in report.json and compared, as the
    input's are. An unchanged file still lets the input be skipped."""
    import numpy as np

    from .test_z_scale import HEIGHTS_UM, artefact

    artefact(tmp_path)  # steps.csv beside the recipe
    part = tmp_path / "part.csv"
    x, y = np.meshgrid(np.linspace(-5, 5, 30), np.linspace(-5, 5, 30))
    np.savetxt(part, np.column_stack([x.ravel(), y.ravel(), 1e-3 * np.sin(x.ravel())]), delimiter=",",
               header="x,y,z", comments="")
    r = write(tmp_path / "zs.yaml", "pointspro: 1\nsteps:\n  - z_scale: {calibration: steps.csv, heights: "
              f"{HEIGHTS_UM.tolist()}}}\n")
    base = ("--batch", r, part, "--out", tmp_path / "o", "--figures", "none", "--quiet")

    def last():
        rep = json.loads((tmp_path / "o" / "part" / "report.json").read_text(encoding="utf-8"))
        status = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))["inputs"][0]["status"]
        return status, rep["steps"][0]["report"]["amplification"], rep["parameter_files_sha256"]

    assert run_cli(*base)[0] == 0
    status, amp, files = last()
    assert status == "ok" and abs(amp - 0.9754) < 1e-3 and list(files) == ["step 1 'z_scale': calibration"]
    assert run_cli(*base, "--resume")[0] == 0
    assert last()[0] == "skipped"
    cal = np.loadtxt(tmp_path / "steps.csv", delimiter=",", skiprows=1)
    cal[:, 1] *= 1.03  # the artefact measured again: 3 % more amplification
    np.savetxt(tmp_path / "steps.csv", cal, delimiter=",", header="x,z,scan", comments="", fmt="%.10g")
    assert run_cli(*base, "--resume")[0] == 0
    status, amp2, files2 = last()
    assert status == "ok" and abs(amp2 / amp - 1.03) < 1e-3 and files2 != files
    # a file this machine cannot read (a cluster's workers' own path): unknown here, not changed — the
    # input is not run again on every --resume (a review)
    from pointspro.core.batch import is_complete, load_batch_recipe, parameter_file_digests

    rec = load_batch_recipe(r, ())
    assert is_complete(tmp_path / "o", "part", part, rec, "auto", "none") is not None
    assert is_complete(tmp_path / "o", "part", part, rec, "auto", "none",
                       {what: None for what in parameter_file_digests(rec)}) is not None
    assert is_complete(tmp_path / "o", "part", part, rec, "auto", "none",
                       {what: "0" * 64 for what in parameter_file_digests(rec)}) is None
