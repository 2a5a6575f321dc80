"""A review of the twelfth session's changes: the order check at load matches the run's, `--set`
can mend what the file breaks, and the map's clear aperture from an `aperture` step is taken only in
the frame that step cut in."""
import csv
import json
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).resolve().parents[1] / "resources" / "example"
SURFACE = ("surface: {type: even_asphere, c: 3.3333333333333335e-4, k: -0.98, A: {4: 7.0e-13, 6: 1.0e-19}, "
           "aperture: 1300}\n")


def _recipe(tmp_path, *steps, name="r.yaml", surface=SURFACE):
    p = tmp_path / name
    p.write_text("pointspro: 1\n" + surface + "steps:\n" + "".join(f"  - {s}\n" for s in steps), encoding="utf-8")
    return p


def _bspline(out: Path) -> dict:
    report = json.loads((out / "asphere_cmm" / "report.json").read_text(encoding="utf-8"))
    return next(s for s in report["steps"] if s["id"] == "bspline_map")["report"]


def test_a_step_between_the_mover_and_the_new_residual_is_refused_with_the_recipe(run_cli, tmp_path):
    """The run refuses unless the step right after the move makes the residual again; the check at
    load asked only for the next step that makes or reads it, so --check-only said ready."""
    r = _recipe(tmp_path, "misalignment: {}", "probe_radius: {radius: 4.0, side: 1}",
                "aperture: {diameter: 1290}", "misalignment: {}")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--check-only")
    assert code == 2 and "step 2 'probe_radius' moves the points" in err and "step 3 'aperture' would use it" in err


def test_set_may_mend_what_the_file_as_written_breaks(run_cli, tmp_path):
    r = tmp_path / "r.yaml"
    r.write_text("pointspro: 1\n" + SURFACE + "steps:\n  - misalignment: {}\n  - probe_radius: {radius: 4.0, side: 1}\n"
                 "  - misalignment: {}\n    enabled: false\n  - zernike: {terms: 4}\n", encoding="utf-8")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--check-only")
    assert code == 2 and "moves the points" in err
    code, out, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--check-only",
                             "--set", "3.enabled=true")
    assert code == 0, err


def test_an_aperture_cut_before_the_pose_fit_stands_about_the_nominals_axis(run_cli, tmp_path):
    """Its centre is in the measuring frame, the map in the part frame, where the pose fit has put the
    part on the nominal's axis: the diameter about the axis (a 30 mm off-axis centre had cut the map
    30 mm off the part; then the surface's 1300 mm was taken, and `correction` refused a recipe that
    ran before — two reviews)."""
    r = _recipe(tmp_path, "probe_radius: {radius: 4.0, side: 1}", "aperture: {diameter: 1200, center_x: 30}",
                "misalignment: {}", "bspline_map: {spacing: 20.0}")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--figures", "none",
                           "--quiet")
    assert code == 0, err
    rep = _bspline(tmp_path / "o")
    assert rep["diameter"] == 1200.0 and rep["centre_mm"] == [0.0, 0.0]
    r = _recipe(tmp_path, "manual_edit: {remove: [520, 3640]}", "probe_radius: {radius: 4.0, side: 1}",
                "aperture: {diameter: 1000}", "misalignment: {}", "correction: {}", name="c.yaml")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "c", "--figures", "none",
                           "--quiet")
    assert code == 0, err
    report = json.loads((tmp_path / "c" / "asphere_cmm" / "report.json").read_text(encoding="utf-8"))
    corr = next(s for s in report["steps"] if s["id"] == "correction")["report"]
    assert corr["diameter_mm"] == 1000.0


def test_an_annular_aperture_leaves_no_map_in_its_hole(run_cli, tmp_path):
    r = _recipe(tmp_path, "manual_edit: {remove: [520, 3640]}", "probe_radius: {radius: 4.0, side: 1}",
                "misalignment: {}", "knn_denoise: {window: 15.0, remove: auto}",
                "aperture: {shape: annulus, diameter: 1290, inner_diameter: 400}", "bspline_map: {spacing: 10.0}")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--figures", "none",
                           "--quiet")
    assert code == 0, err
    rep = _bspline(tmp_path / "o")
    assert rep["diameter"] == 1290.0 and rep["inner_diameter"] == 400.0
    with open(tmp_path / "o" / "asphere_cmm" / "map.csv", encoding="utf-8") as f:
        rows = [r for r in csv.reader(ln for ln in f if not ln.startswith("#"))]
    xy = np.array([[float(v) for v in row[:2]] for row in rows[1:]])
    r_nodes = np.hypot(xy[:, 0], xy[:, 1])
    assert len(r_nodes) == rep["nodes"] and r_nodes.min() >= 200.0 - 1e-9 and r_nodes.max() <= 645.0 + 1e-9


def test_the_hole_is_taken_only_where_the_aperture_cut_it(run_cli, tmp_path):
    """A map given its own centre does not carry the annulus's hole there (as correction does not)."""
    r = _recipe(tmp_path, "manual_edit: {remove: [520, 3640]}", "probe_radius: {radius: 4.0, side: 1}",
                "misalignment: {}", "aperture: {shape: annulus, diameter: 1290, inner_diameter: 400}",
                "bspline_map: {spacing: 10.0, centre: [150, 0]}")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--figures", "none",
                           "--quiet")
    assert code == 0, err
    rep = _bspline(tmp_path / "o")
    assert rep["centre_mm"] == [150.0, 0.0] and "inner_diameter" not in rep


def test_the_python_api_and_the_window_refuse_design_dof_on_a_q_con_as_they_read_it():
    import pytest

    import pointspro.core as pp
    from pointspro.core.errors import RecipeError
    from pointspro.core.session.model import Session

    recipe = {"pointspro": 1, "surface": {"type": "qcon", "R": 3000, "k": -0.98, "norm_radius": 650,
                                          "a": [1e-4], "aperture": 1300},
              "steps": [{"misalignment": {"dof": ["alpha", "beta", "dx", "dy", "dz", "radius"]}}]}
    with pytest.raises(RecipeError, match="fitting radius needs an even_asphere nominal"):
        pp.load(recipe)
    with pytest.raises(RecipeError, match="fitting radius needs an even_asphere nominal"):
        Session().set_recipe(recipe)


def test_a_step_reading_the_residual_after_a_transform_dropped_it_is_refused(run_cli, tmp_path):
    r = _recipe(tmp_path, "misalignment: {}", "transform: {pose: {dz: 1.0}}", "zernike: {terms: 4}")
    code, _, err = run_cli("--batch", r, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--check-only")
    assert code == 2 and ("step 3 'zernike' works on the form error (the residual), which step 2 'transform' "
                          "drops") in err
    ok = _recipe(tmp_path, "misalignment: {}", "transform: {pose: {dz: 1.0}}", "misalignment: {}",
                 "zernike: {terms: 4}", name="ok.yaml")
    assert run_cli("--batch", ok, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o2", "--check-only")[0] == 0
