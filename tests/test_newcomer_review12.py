"""A newcomer's review (2026-11-28): what `pointspro steps` and the recipe's errors tell a user who
has only the repository."""
import pytest

from pointspro.core.errors import RecipeError
from pointspro.core.recipe import load_recipe

GOOD_SURFACE = "surface: {type: even_asphere, R: 3000, k: -0.98, aperture: 1300}\n"


def _recipe(tmp_path, steps: str, surface: str = GOOD_SURFACE):
    p = tmp_path / "r.yaml"
    p.write_text("pointspro: 1\n" + surface + "steps:\n" + steps, encoding="utf-8")
    return p


def test_steps_lists_a_mappings_own_keys_and_a_union_as_what_it_takes(run_cli):
    code, out, _ = run_cli("steps", "misalignment", "transform", "knn_denoise")
    assert code == 0
    lines = out.splitlines()
    # misalignment's `initial` and transform's `pose`: their keys were written nowhere
    for key, unit in (("initial.alpha_deg", "deg"), ("initial.dz", "mm"), ("pose.beta_deg", "deg"),
                      ("pose.dx", "mm")):
        assert any(ln.strip().startswith(f"{key} [{unit}]: float") for ln in lines), key
    # `remove` takes 'auto' or a count — "one of ['auto']" read as "only auto"
    remove = next(ln for ln in lines if ln.strip().startswith("remove:"))
    assert "'auto' or a whole number" in remove and "one of" not in remove


def test_an_unknown_key_names_the_closest_and_the_keys_its_mapping_takes(tmp_path):
    with pytest.raises(RecipeError) as e:
        load_recipe(_recipe(tmp_path, "  - misalignment: {initial: {alpha: 0.1}}\n"))
    assert str(e.value).endswith("step 1 'misalignment': key 'initial.alpha': unknown key; did you mean "
                                 "'alpha_deg'? (initial takes alpha_deg, beta_deg, dx, dy, dz)")
    with pytest.raises(RecipeError) as e:
        load_recipe(_recipe(tmp_path, "  - knn_denoise: {windw: 3}\n"))
    assert "key 'windw': unknown key; did you mean 'window'? (the step takes method, window," in str(e.value)
    with pytest.raises(RecipeError) as e:  # nothing close: the keys alone
        load_recipe(_recipe(tmp_path, "  - aperture: {zzzz: 3}\n"))
    assert "key 'zzzz': unknown key (the step takes " in str(e.value) and "did you mean" not in str(e.value)


def test_a_surface_error_names_the_key_as_written_not_the_type(tmp_path):
    with pytest.raises(RecipeError) as e:
        load_recipe(_recipe(tmp_path, "  - misalignment: {}\n",
                            "surface: {type: even_asphere, R: 3000, kk: -0.98}\n"))
    assert str(e.value).endswith("line 2: surface: key 'kk': unknown key; did you mean 'k'? "
                                 "(even_asphere takes aperture, c, R, k, A)")
    with pytest.raises(RecipeError) as e:  # "key 'even_asphere': give exactly one of c and R"
        load_recipe(_recipe(tmp_path, "  - misalignment: {}\n",
                            "surface: {type: even_asphere, c: 3.33e-4, R: 3000}\n"))
    assert str(e.value).endswith("line 2: surface: give exactly one of c (1/mm) and R (mm)")


def test_the_map_takes_the_clear_aperture_the_recipe_applied(run_cli, tmp_path):
    """The example's recipe cuts the part to 1290 mm; its map said 1300 mm (the surface's), while
    `correction` took the recipe's — one clear aperture now."""
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "resources" / "example"
    code, _, err = run_cli("--batch", example / "recipe.yaml", example / "asphere_cmm.csv", "--out",
                           tmp_path / "o", "--figures", "none", "--quiet")
    assert code == 0, err
    import json

    report = json.loads((tmp_path / "o" / "asphere_cmm" / "report.json").read_text(encoding="utf-8"))
    by_id = {s["id"]: s for s in report["steps"]}
    assert by_id["aperture"]["points_out"] < by_id["aperture"]["points_in"]  # it cut the rim
    assert by_id["bspline_map"]["report"]["diameter"] == 1290.0


def test_a_residual_the_input_carried_is_not_blamed_on_a_fit():
    """The Python API with a residual and flat z: "a fit diverged" named a fit that never ran."""
    import numpy as np

    import pointspro.core as pp
    from pointspro.core.errors import PointsProError

    rng = np.random.default_rng(3)
    x, y = rng.uniform(-10, 10, (2, 2000))
    cloud = pp.PointCloud.from_numpy(np.c_[x, y, np.zeros_like(x)], residual=5e-4 * (x / 10) ** 2)
    with pytest.raises(PointsProError, match="no step of this run made that residual: the input carries it"):
        pp.step("zernike", terms=4)(cloud)


def test_fitting_the_nominals_radius_on_a_q_con_is_refused_with_the_recipe(tmp_path):
    """It passed --check-only and failed each input at run time."""
    qcon = "surface: {type: qcon, R: 3000, k: -0.98, norm_radius: 650, a: [1.0e-4], aperture: 1300}\n"
    with pytest.raises(RecipeError) as e:
        load_recipe(_recipe(tmp_path, "  - misalignment: {dof: [alpha, beta, dx, dy, dz, radius]}\n", qcon))
    assert str(e.value).endswith("line 4: step 1 'misalignment': key 'dof': fitting radius needs an "
                                 "even_asphere nominal (this recipe's surface is qcon); fit the pose "
                                 "alone (alpha, beta, dx, dy, dz)")
    load_recipe(_recipe(tmp_path, "  - misalignment: {dof: [alpha, beta, dx, dy, dz]}\n", qcon))  # the pose: fine
    load_recipe(_recipe(tmp_path, "  - misalignment: {dof: [alpha, beta, dx, dy, dz, radius]}\n"))  # even asphere


def test_hampel_reports_no_separation_it_cannot_measure():
    """hampel scores no point: its "separation" was 0/1e-300 = 0.0 (docs/report.md)."""
    import numpy as np

    import pointspro.core as pp

    rng = np.random.default_rng(5)
    x, y = rng.uniform(-50, 50, (2, 20000))
    r = rng.normal(0, 2e-5, x.size)
    r[:10] += 2e-3  # ten spikes of 2 µm on 20 nm of noise
    cloud = pp.PointCloud.from_numpy(np.c_[x, y, r], residual=r)
    res = pp.step("knn_denoise", method="hampel", window=3.0)(cloud)
    rep = res.report["steps"][-1]["report"]
    assert rep["removed"] >= 10 and "separation" not in rep
    res = pp.step("knn_denoise", window=3.0)(cloud)  # robust scores its points: separation above 1
    rep = res.report["steps"][-1]["report"]
    assert rep["separation"] > 1
