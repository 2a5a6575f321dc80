"""Files named by a recipe's parameters (issue 18): a recipe is data shared between people and
machines, not a permission. A file outside the recipe's folder and the inputs' folders needs
`--allow-path DIR`; an error about a parameter file's content names the file, line and column and
quotes nothing of it (it would land in the terminal, the log and summary.json)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context, file_parameters

from . import paper004 as p4
from .conftest import write

SECRET = "w8tq:x:0:0:zz9Plural:/home/zz9Plural:/bin/qsh\nkq4v:x:1:1:kq4v:/usr/sbin:/usr/sbin/nologin\n"
#: fragments of SECRET (and of the other bad files) that must never appear in a message
LEAKS = ("w8tq", "zz9Plural", "kq4v", "nologin", "/bin/qsh")


def _no_leak(text: str) -> None:
    for s in LEAKS:
        assert s not in text, f"{s!r} quoted in: {text}"


@pytest.fixture
def layout(tmp_path):
    """recipes/, data/ (one input) and elsewhere/passwd (outside both)."""
    (tmp_path / "recipes").mkdir()
    (tmp_path / "data").mkdir()
    (tmp_path / "elsewhere").mkdir()
    g = np.linspace(-5.0, 5.0, 6)
    x, y = np.meshgrid(g, g)
    rows = "\n".join(f"{a:.3f},{b:.3f},{0.01 * a * b:.5f}" for a, b in zip(x.ravel(), y.ravel()))
    write(tmp_path / "data" / "part.csv", "x,y,z\n" + rows + "\n")
    write(tmp_path / "elsewhere" / "passwd", SECRET)
    return tmp_path


def _recipe(folder: Path, calibration: str) -> Path:
    return write(folder / "recipes" / "r.yaml",
                 f"pointspro: 1\nsteps:\n  - dynamic_id: {{calibration: {calibration}}}\n")


def test_file_outside_is_refused_naming_allow_path(run_cli, layout):
    secret = layout / "elsewhere" / "passwd"
    for spelled in (str(secret), "../elsewhere/passwd"):
        recipe = _recipe(layout, spelled)
        code, out, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", layout / "o")
        assert code == 2
        line = err.strip()
        assert "\n" not in line
        assert "r.yaml, line 3: step 1 'dynamic_id': parameter 'calibration'" in line
        assert re.search(r"passwd( \(→ \S+/elsewhere/passwd\))? is outside the recipe's folder and "
                         "the inputs' folders", line)
        assert f"--allow-path {secret.parent}" in line
        _no_leak(line)
        assert not (layout / "o" / "part").exists()  # refused before any input ran


def test_allow_path_accepts_it_and_the_content_is_never_quoted(run_cli, layout):
    recipe = _recipe(layout, str(layout / "elsewhere" / "passwd"))
    out_dir = layout / "o"
    code, out, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", out_dir,
                             "--allow-path", layout / "elsewhere")
    assert code == 2  # the only input failed — on the file's content, not on where it lies
    assert "outside" not in err and "passwd: no numeric data rows found (from line 1 on)" in err
    _no_leak(err + out)
    summary = (out_dir / "summary.json").read_text(encoding="utf-8")
    assert "no numeric data rows" in summary
    _no_leak(summary)


def test_allow_path_runs_a_good_file_from_another_folder(run_cli, layout):
    t, xd, ref = p4.calibration()
    np.savetxt(layout / "elsewhere" / "cal.csv", np.column_stack([t, xd, ref]), delimiter=",",
               header="t,xd,ref", comments="", fmt="%.10g")
    recipe = _recipe(layout, str(layout / "elsewhere" / "cal.csv"))
    code, out, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", layout / "o",
                             "--allow-path", layout / "elsewhere", "--quiet")
    assert code == 0, err
    assert (layout / "o" / "part" / "dynamic_model.json").is_file()


def test_files_beside_the_recipe_or_an_input_need_no_flag(run_cli, layout):
    t, xd, ref = p4.calibration()
    for folder in ("recipes", "data"):
        np.savetxt(layout / folder / "cal.csv", np.column_stack([t, xd, ref]), delimiter=",",
                   header="t,xd,ref", comments="", fmt="%.10g")
        rel = "cal.csv" if folder == "recipes" else "../data/cal.csv"
        recipe = _recipe(layout, rel)
        out_dir = layout / f"o_{folder}"
        code, _, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", out_dir,
                               "--quiet")
        assert code == 0, err


def test_a_link_out_of_the_recipe_folder_is_followed_and_refused(run_cli, layout):
    (layout / "recipes" / "cal.csv").symlink_to(layout / "elsewhere" / "passwd")
    recipe = _recipe(layout, "cal.csv")
    code, _, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", layout / "o")
    assert code == 2 and "is outside the recipe's folder" in err and "--allow-path" in err
    _no_leak(err)


def test_recipe_inputs_and_mesh_surface_are_checked_too(run_cli, layout):
    write(layout / "elsewhere" / "ref.csv", "fiducial,x,y,z\n1,0,0,0\n")
    recipe = write(layout / "recipes" / "r.yaml", "pointspro: 1\ninputs: {fiducials: "
                   f"{layout / 'elsewhere' / 'ref.csv'}}}\nsteps: []\n")
    code, _, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", layout / "o")
    assert code == 2 and "inputs: key 'fiducials'" in err and "--allow-path" in err
    recipe = write(layout / "recipes" / "r.yaml", "pointspro: 1\nsurface: {type: mesh, path: "
                   f"{layout / 'elsewhere' / 'passwd.stl'}}}\nsteps: []\n")
    code, _, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", layout / "o")
    assert code == 2 and "surface: key 'path'" in err and "--allow-path" in err


def test_allow_path_must_be_a_folder_and_goes_with_batch(run_cli, layout):
    recipe = _recipe(layout, "cal.csv")
    code, _, err = run_cli("--batch", recipe, layout / "data" / "part.csv", "--out", layout / "o",
                           "--allow-path", layout / "nope")
    assert code == 2 and "--allow-path" in err and "not a folder" in err
    code, _, err = run_cli("--allow-path", layout)
    assert code == 2 and "go with --batch" in err


def test_context_resolve_checks_when_allowed_dirs_are_set(layout):
    secret = layout / "elsewhere" / "passwd"
    ctx = Context(base_dir=layout / "recipes", allowed_dirs=(layout / "data",))
    assert ctx.resolve("x.csv", "calibration") == layout / "recipes" / "x.csv"
    assert ctx.resolve(layout / "data" / "y.csv") == layout / "data" / "y.csv"
    with pytest.raises(StepError, match=r"parameter 'calibration': .*passwd is outside .* --allow-path"):
        ctx.resolve(str(secret), "calibration")
    with pytest.raises(StepError, match="is outside"):
        ctx.resolve("../elsewhere/passwd", "calibration")
    # the window and scripts: no limit unless asked (the user chose the file)
    assert Context(base_dir=layout / "recipes").resolve(secret) == secret
    assert Context().allowed_dirs is None


def test_steps_declare_their_file_parameters():
    from pointspro.core.registry import Registry

    reg = Registry()
    found = {}
    for step_id in ("dynamic", "dynamic_id", "fiducials", "volumetric", "z_scale", "kinematic",
                    "kinematic_map", "register"):
        cls = reg.load(step_id)
        found[step_id] = {n for n, f in cls.Params.model_fields.items()
                          if isinstance(f.json_schema_extra, dict) and f.json_schema_extra.get("file")}
    assert found == {"dynamic": {"calibration", "model"}, "dynamic_id": {"calibration"},
                     "fiducials": {"reference"}, "volumetric": {"model"}, "z_scale": {"calibration"},
                     "kinematic": {"map"}, "kinematic_map": {"straightness", "facial", "squareness"},
                     "register": {"mesh"}}
    p = reg.load("dynamic").Params(model="m.json")
    assert file_parameters(p) == {"model": "m.json"}


# --- no content of a parameter file in any message -----------------------------------------------
BAD_TABLES = {
    "passwd": SECRET,
    "header_then_words": "t,xd,ref\n1,2,3\nw8tq,kq4v,x\n",
    "ragged": "t,xd,ref\n1,2,3\n4,5\n",
    "damaged_header": "1,2,3\n4,w8tq,6\n",
    "nan": "t,xd,ref\n1,2,3\n4,nan,6\n",
    "dup": "w8tq,w8tq,ref\n1,2,3\n",
    "unknown_columns": "w8tq,kq4v,nologin\n1,2,3\n",
    "binary": "\x00\x01w8tq\xff\xfe",
}


@pytest.mark.parametrize("name", sorted(BAD_TABLES))
def test_table_errors_quote_nothing(tmp_path, name):
    from pointspro.core.io.text import read_table

    p = tmp_path / "cal.csv"
    p.write_bytes(BAD_TABLES[name].encode("latin-1"))
    with pytest.raises(InputError) as e:
        read_table(p, ("t", "xd", "ref"))
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg
    _no_leak(msg)


def test_table_errors_name_line_and_column(tmp_path):
    from pointspro.core.io.text import read_table

    p = write(tmp_path / "cal.csv", "t,xd,ref\n1,2,3\n4,w8tq,6\n")
    with pytest.raises(InputError, match=r"cal.csv, line 3, column 2: is not a number$"):
        read_table(p, ("t", "xd", "ref"))
    p = write(tmp_path / "cal.csv", "t,xd,ref\n1,2,3\n4,nan,6\n")
    with pytest.raises(InputError, match=r"cal.csv, line 3, column 2: not a finite number"):
        read_table(p, ("t", "xd", "ref"))
    p = write(tmp_path / "cal.csv", "a,b\n1,2\n")
    with pytest.raises(InputError, match=r"cal.csv, line 1: no t/xd/ref column$"):
        read_table(p, ("t", "xd", "ref"))
    with pytest.raises(InputError, match="nope.csv: file not found"):
        read_table(tmp_path / "nope.csv", ("t",))
    with pytest.raises(InputError, match="is a folder"):
        read_table(tmp_path, ("t",))


def test_measurement_errors_still_quote_the_input(tmp_path):
    """The user's own measurement may be quoted (it helps to find the bad token)."""
    from pointspro.core.io import read_cloud

    p = write(tmp_path / "m.csv", "x,y,z\n1,2,3\n4,abc,6\n")
    with pytest.raises(InputError, match=r"m.csv, line 3, column 2: 'abc' is not a number"):
        read_cloud(p)


JSON_FILES = {
    "passwd": SECRET,
    "list": '["w8tq", "kq4v"]',
    "strings": '{"pointspro_dynamic_model": 1, "pointspro_kinematic_map": 1, '
               '"pointspro_volumetric_model": 1, "b": ["w8tq"], "a": ["kq4v"], "fs_hz": "w8tq", '
               '"r_mm": ["w8tq"], "c_deg": [1], "e_mm": [[1]]}',
    "marker": '{"pointspro_dynamic_model": "w8tq", "pointspro_kinematic_map": "w8tq", '
              '"pointspro_volumetric_model": "w8tq"}',
    "extra_key": '{"pointspro_volumetric_model": 1, "w8tq": 1, "transform": {}, "workspace": [], '
                 '"gp": {"kq4v": {}}, "loo_rms_um": {}, "sha256": "w8tq"}',
    "binary": "\x00\xffw8tq",
}


@pytest.mark.parametrize("name", sorted(JSON_FILES))
@pytest.mark.parametrize("step", ["dynamic", "kinematic", "volumetric"])
def test_model_file_errors_quote_nothing(tmp_path, name, step):
    p = tmp_path / "m.json"
    p.write_bytes(JSON_FILES[name].encode("latin-1"))
    ctx = Context(base_dir=tmp_path)
    cloud = PointCloud.from_xyz(np.arange(5.0), np.zeros(5), np.zeros(5), t=np.arange(5.0) / 1000,
                                xd=np.zeros(5), xc=np.zeros(5), c=np.zeros(5))
    if step == "dynamic":
        from pointspro.plugins.dynamic import DynamicStep as S
    elif step == "kinematic":
        from pointspro.plugins.kinematic import KinematicStep as S
    else:
        from pointspro.plugins.volumetric import VolumetricStep as S
    params = S.Params(**({"map": "m.json"} if step == "kinematic" else {"model": "m.json"}))
    with pytest.raises(InputError) as e:
        S().run(cloud, params, ctx)
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg
    _no_leak(msg)


def test_json_syntax_error_names_line_and_column(tmp_path):
    from pointspro.core.dynamics.identify import LoopModel

    with pytest.raises(InputError, match=r"m.json: not a PointsPro dynamic model \(not JSON: .* at "
                                         r"line 2, column 2\)"):
        LoopModel.from_json('{"a": 1,\n w8tq}', "m.json")


def test_summary_of_a_failed_batch_quotes_no_parameter_file(run_cli, layout):
    """Several inputs, a recipe whose calibration is a bad file: each input fails alone with one
    line, and neither the terminal nor summary.json holds the file's content."""
    write(layout / "recipes" / "cal.csv", SECRET)
    recipe = _recipe(layout, "cal.csv")
    second = layout / "data" / "part2.csv"
    second.write_bytes((layout / "data" / "part.csv").read_bytes())
    code, out, err = run_cli("--batch", recipe, layout / "data" / "part.csv", second, "--out",
                             layout / "o", "--workers", "1")
    assert code == 1
    _no_leak(out + err)
    summary = json.loads((layout / "o" / "summary.json").read_text(encoding="utf-8"))
    _no_leak(json.dumps(summary))
    assert all(e["status"] == "failed" for e in summary["inputs"])


def test_workers_apply_the_allowed_folders_they_are_sent(layout):
    """Each job carries the batch's allowed folders (process pool and Dask alike): a worker refuses a
    file outside them even if the up-front check was skipped, and quotes none of it."""
    from pointspro.core.batch import process_job

    recipe = _recipe(layout, str(layout / "elsewhere" / "passwd"))
    oc = process_job(str(recipe), str(layout / "data" / "part.csv"), str(layout / "o"), "part",
                     [str(layout / "data")])
    assert not oc.ok and "is outside the recipe's folder" in oc.error and "--allow-path" in oc.error
    _no_leak(oc.error)
    oc = process_job(str(recipe), str(layout / "data" / "part.csv"), str(layout / "o2"), "part",
                     [str(layout / "data"), str(layout / "elsewhere")])
    assert not oc.ok and "is outside" not in oc.error  # allowed: now read, and refused by content
    _no_leak(oc.error)


def test_named_files_is_the_one_list_of_a_recipes_files(tmp_path):
    """The allowed-folder check and --resume's digests read one enumeration (core/recipe.named_files):
    the mesh surface, each step's file parameters with position, id and line, then ``inputs:`` —
    relative names resolved against the recipe's folder, absolute ones kept."""
    from pointspro.core.batch import parameter_file_digests
    from pointspro.core.recipe import load_recipe, named_files

    write(tmp_path / "cal.csv", "x,z,scan\n0,0,0\n")
    write(tmp_path / "fid.csv", "fiducial,x,y,z\n1,0,0,0\n")
    (tmp_path / "sub").mkdir()
    recipe = load_recipe(write(tmp_path / "sub" / "r.yaml",
                               "pointspro: 1\nsurface: {type: mesh, path: part.stl}\n"
                               f"inputs: {{fiducials: {tmp_path / 'fid.csv'}}}\nsteps:\n"
                               "  - aperture: {diameter: 10}\n"
                               "  - z_scale: {calibration: ../cal.csv, heights: [1, 2]}\n"))
    files = named_files(recipe)
    assert [(f.section, f.key, f.step, f.step_id) for f in files] == [
        ("surface", "path", 0, ""), ("step", "calibration", 2, "z_scale"), ("inputs", "fiducials", 0, "")]
    assert files[0].path == tmp_path / "sub" / "part.stl" and files[1].path == tmp_path / "sub" / ".." / "cal.csv"
    assert files[1].line == 6 and files[2].path == tmp_path / "fid.csv"
    digests = parameter_file_digests(recipe)  # the same files, by the labels report.json keeps
    assert list(digests) == ["surface: path", "step 2 'z_scale': calibration", "inputs: fiducials"]
    assert digests["surface: path"] is None and digests["step 2 'z_scale': calibration"] is not None
