"""PointsPro from Python (core/api.py, README "From Python", docs/api.md): the README's block runs as
written and gives the batch's numbers and files; clouds to and from pandas/numpy/pyvista; one step
on its own; progress, cancellation, one-line errors, nothing printed; rich display."""
from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import pointspro.core as pp
from pointspro.core.cli import main as cli_main

from .conftest import EXAMPLE

ROOT = Path(__file__).resolve().parents[1]
RECIPE = EXAMPLE / "recipe.yaml"
DATA = EXAMPLE / "asphere_cmm.csv"


def readme_python_block() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## From Python", 1)[1]
    m = re.search(r"```python\n(.*?)```", section, re.S)
    assert m, "README's 'From Python' section has no python block"
    return m.group(1)


@pytest.fixture(scope="module")
def example_run(tmp_path_factory):
    """The README's block executed as written in a folder laid out like the repository's root,
    and the batch run on the same input."""
    work = tmp_path_factory.mktemp("readme")
    shutil.copytree(EXAMPLE, work / "resources" / "example")
    code = readme_python_block()
    ns: dict = {}
    import os

    cwd = os.getcwd()
    os.chdir(work)
    try:
        exec(compile(code, "README.md (From Python)", "exec"), ns)
    finally:
        os.chdir(cwd)
    batch = work / "batch"
    assert cli_main(["--batch", str(RECIPE), str(DATA), "--out", str(batch), "--quiet"]) == 0
    return work, ns, batch / "asphere_cmm"


def test_readme_block_gives_the_batchs_numbers_and_files(example_run):
    work, ns, batch = example_run
    result = ns["result"]
    batch_report = json.loads((batch / "report.json").read_text(encoding="utf-8"))
    for key in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad", "points_in", "points_out"):
        assert result.summary[key] == batch_report["summary"][key], key
    assert result.summary["rms_um"] == pytest.approx(0.6446, abs=1e-3)  # over the area (a star scan)
    written = work / "out" / "example" / "asphere_cmm"
    assert {p.name for p in written.iterdir()} == {p.name for p in batch.iterdir()}
    # the cloud byte for byte, the report the same but for its time stamp and the step timings
    assert (written / "cloud.csv").read_bytes() == (batch / "cloud.csv").read_bytes()
    api_report = json.loads((written / "report.json").read_text(encoding="utf-8"))
    for rep in (api_report, batch_report):
        rep.pop("created")
        rep["input"] = Path(rep["input"]).name
        for st in rep["steps"]:
            st.pop("seconds")
    # the batch records the digest of the file it read (--resume); the README's run was given a cloud
    # read before, whose file the API does not hash again (pp.run(recipe, path) records it: below)
    assert "input_sha256" not in api_report
    assert batch_report.pop("input_sha256") == hashlib.sha256(DATA.read_bytes()).hexdigest()
    assert api_report == batch_report
    assert pp.run(RECIPE, DATA).input_sha256 == hashlib.sha256(DATA.read_bytes()).hexdigest()
    # result.report is report.json's content (plain JSON types)
    assert json.loads(json.dumps(result.report))["summary"] == result.summary
    assert [s["id"] for s in result.report["steps"]] == [r.id for r in result.steps]


def test_readme_block_pandas_pyvista_and_steps(example_run):
    _, ns, _ = example_run
    cloud, df, mesh = ns["result"].cloud, ns["df"], ns["mesh"]
    assert list(df.columns) == cloud.column_names
    assert "residual" in df and "omega" in df and df.attrs["frame"] == "part"
    for name in cloud.column_names:
        np.testing.assert_array_equal(df[name].to_numpy(), cloud[name])
    assert mesh.n_points == cloud.n and mesh.points.dtype == np.float64
    np.testing.assert_array_equal(mesh.points, cloud.xyz)
    np.testing.assert_array_equal(mesh.point_data["residual"], cloud["residual"])
    assert mesh.n_verts == cloud.n
    catalog = pp.steps()
    assert {"probe_radius", "misalignment", "knn_denoise", "zernike", "bspline_map"} <= set(catalog)
    knn = catalog["knn_denoise"]
    assert knn.Params.__name__ and "window" in knn.defaults()
    window = next(f for f in knn.fields if f.key == "window")
    assert window.unit == "mm"
    table = catalog.to_pandas()
    assert ((table.step == "knn_denoise") & (table.key == "window")).sum() == 1


def test_pandas_and_numpy_round_trip_bit_exact():
    rng = np.random.default_rng(7)
    xyz = rng.normal(size=(500, 3)) * [100, 100, 1]
    r = rng.normal(scale=1e-4, size=500)
    cloud = pp.PointCloud.from_numpy(xyz, residual=r, meta={"frame": "part"})
    back = pp.PointCloud.from_pandas(cloud.to_pandas())
    assert back.equals(cloud) and back.frame == "part"
    np.testing.assert_array_equal(cloud.to_numpy(), xyz)
    out = cloud.to_numpy()
    out[0, 0] = 1e9  # a writable copy; the cloud is untouched
    assert cloud.x[0] == xyz[0, 0]
    df = cloud.to_pandas()
    df.loc[0, "z"] = 5.0  # writable
    assert cloud.z[0] == xyz[0, 2]


@pytest.mark.parametrize("make, words", [
    (lambda pd: pd.DataFrame({"x": [0.0], "y": [0.0]}), ["z", "missing"]),
    (lambda pd: pd.DataFrame({"x": [0.0], "y": [0.0], "z": [0.0], "name": ["a"]}), ["'name'", "numeric"]),
    (lambda pd: pd.DataFrame({"x": [0.0], "y": [0.0], "z": [0.0], "bad col": [1.0]}), ["bad col"]),
])
def test_from_pandas_refuses_in_one_line(make, words):
    import pandas as pd

    with pytest.raises(pp.InputError) as e:
        pp.PointCloud.from_pandas(make(pd))
    msg = str(e.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


def test_one_step_on_its_own_equals_the_same_step_in_a_recipe():
    cloud = pp.read(DATA)
    res = pp.run(RECIPE, cloud)
    before = res.cloud.replace(drop=["omega"])
    alone = pp.step("knn_denoise", window=15, remove="auto")(before)
    in_recipe = pp.run({"steps": [{"knn_denoise": {"window": 15.0, "remove": "auto"}}]}, before)
    assert alone.cloud.equals(in_recipe.cloud)
    assert alone.steps[0].report == in_recipe.steps[0].report
    assert repr(pp.step("knn_denoise", window=15)) == "step('knn_denoise', window=15.0)"


def test_step_needing_the_nominal_takes_the_surface():
    surface = {"type": "even_asphere", "c": 3.3333333e-4, "k": -0.98, "A": {4: 7.0e-13, 6: 1.0e-19},
               "aperture": 1300}
    cloud = pp.read(DATA)
    with pytest.raises(pp.PointsProError, match="needs the recipe's nominal"):
        pp.step("misalignment")(cloud)
    res = pp.step("misalignment")(cloud, surface=surface)
    assert "residual" in res.cloud.channels and res.cloud.frame == "part"


@pytest.mark.parametrize("call, words", [
    (lambda: pp.step("knn_denoise", window=-1), ["knn_denoise", "window", "greater than 0"]),
    (lambda: pp.step("no_such_step"), ["unknown step", "no_such_step"]),
    (lambda: pp.run({"steps": [{"aperture": {"diameterr": 5}}]}, pp.read(DATA)), ["diameterr", "unknown key"]),
    (lambda: pp.read("no/such/file.csv"), ["no/such/file.csv"]),
    (lambda: pp.run(RECIPE, "no/such/file.csv"), ["no/such/file.csv"]),
    (lambda: pp.run(RECIPE, 42), ["PointCloud"]),
    (lambda: pp.run({"pointspro": 2, "steps": []}, pp.read(DATA)), ["format 2"]),
])
def test_errors_are_one_line_pointspro_errors(call, words):
    with pytest.raises(pp.PointsProError) as e:
        call()
    msg = str(e.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


def test_progress_callable_and_nothing_printed(capfd):
    seen = []
    res = pp.run(RECIPE, DATA, progress=lambda f, m: seen.append((f, m)))
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # nothing printed by a run (library warnings are kept instead)
    assert isinstance(res.warnings, list)
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == pytest.approx(1.0)
    assert any("Misalignment" in m for _, m in seen)


def test_progress_true_draws_a_bar(capfd):
    pp.run({"steps": [{"manual_edit": {"remove": [1]}}]}, DATA, progress=True)
    err = capfd.readouterr().err
    assert "100%" in err


def test_cancel_by_event_and_by_callable():
    ev = threading.Event()
    ev.set()
    with pytest.raises(pp.Cancelled):
        pp.run(RECIPE, DATA, cancel=ev)
    calls = []

    def stop_after_two():
        calls.append(1)
        return len(calls) > 2

    with pytest.raises(pp.Cancelled):
        pp.run(RECIPE, DATA, cancel=stop_after_two)
    assert len(calls) > 2
    token = pp.CancelToken()
    res = pp.run({"steps": [{"manual_edit": {"remove": [1]}}]}, DATA, cancel=token)
    assert res.cloud.n == 4679


def test_rich_display_of_cloud_result_and_steps(example_run):
    _, ns, _ = example_run
    result = ns["result"]
    h = result._repr_html_()
    assert "4,680 → 4,640" in h and "RMS" in h and "<img" in h and "knn_denoise" in h
    assert "645 nm" in h  # 0.6446 µm RMS, in the unit its size asks for
    c = ns["cloud"]._repr_html_()
    assert "4,680" in c and "<img" in c and "heights, piston and tilt removed" in c
    assert "probe_radius" in pp.steps()._repr_html_()
    assert "rms_um=0.644603" in repr(result)


def test_write_figures_none_and_in_memory_stem(tmp_path):
    xy = np.random.default_rng(1).uniform(-10, 10, size=(400, 2))
    z = 1e-4 * xy[:, 0] ** 2 / 100
    cloud = pp.PointCloud.from_numpy(np.column_stack([xy, z]))
    res = pp.run({"steps": [{"zernike": {"terms": 4, "remove": ["piston", "tilt"]}}]}, cloud)
    folder = res.write(tmp_path / "o", figures="none")
    assert folder == tmp_path / "o" / "cloud"
    assert not list(folder.glob("*.png"))
    assert json.loads((folder / "report.json").read_text(encoding="utf-8"))["figures"]["mode"] == "none"
    with pytest.raises(pp.PointsProError, match="figures"):
        res.write(tmp_path / "o", figures="some")


def test_api_reference_page_is_current():
    r = subprocess.run([sys.executable, str(ROOT / "docs" / "make_api.py"), "--check"],
                       capture_output=True, text=True, encoding="utf-8")
    assert r.returncode == 0, r.stderr
    page = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    assert "figures: str = 'all'" in page  # a default keeps its quotes: the signature is Python
    assert "-> Result`" in page and "**`StepError`**" in page and "``warnings``" in page


def test_importing_the_package_stays_light():
    code = ("import sys, pointspro.core as pp; "
            "print(sorted(m for m in ('pydantic', 'scipy', 'matplotlib', 'pointspro.core.api') "
            "if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, encoding="utf-8")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_a_cloud_with_nan_rows_is_refused_naming_the_first():
    """A review: 3 NaN rows in an in-memory cloud made the uncertainty fail with an internal error
    (ZeroDivisionError), left summary.rms_um None without a word, and said "400 residuals are
    NaN/inf"; the file readers drop such rows and count them, the API now says what to do."""
    import numpy as np

    import pointspro.core as pp
    from pointspro.core.errors import InputError

    rng = np.random.default_rng(2)
    x, y = np.meshgrid(np.linspace(-10, 10, 20), np.linspace(-10, 10, 20))
    z = 1e-5 * rng.standard_normal(x.size)
    z[[3, 50, 51]] = [np.nan, np.inf, np.nan]
    cloud = pp.PointCloud.from_numpy(np.column_stack([x.ravel(), y.ravel(), z]))
    recipe = {"pointspro": 1, "steps": [{"zernike": {"terms": 4, "remove": ["piston", "tilt"]}}],
              "uncertainty": {"noise": "10 nm", "samples": 50}}
    with pytest.raises(InputError, match=r"3 of 400 points have a NaN or infinite x, y or z \(the first: row 3\)"):
        pp.run(recipe, cloud)
    ok = cloud.select(np.isfinite(cloud.xyz).all(axis=1))
    r = pp.run(recipe, ok)
    assert r.summary["rms_um"] is not None and r.cloud.n == 397


def test_a_repeated_index_is_refused_where_a_caller_gives_one():
    """pd.concat of two to_pandas() frames repeats `index`; manual_edit then removed every row so
    numbered (remove: [3] took 468 of 4680 points, silently — a review)."""
    import numpy as np

    from pointspro.core import PointCloud
    from pointspro.core.errors import InputError

    xyz = np.zeros((10, 3))
    with pytest.raises(InputError, match=r"from_numpy: the index column must name each input row once; "
                                         r"5 repeat\(s\) \(first: 0, 2 times\)"):
        PointCloud.from_numpy(xyz, index=np.arange(10) % 5)
    df = PointCloud.from_numpy(xyz).to_pandas()
    import pandas as pd

    with pytest.raises(InputError, match="from_pandas: the index column"):
        PointCloud.from_pandas(pd.concat([df, df]))
    assert PointCloud.from_pandas(df).n == 10
    # from_xyz too; the first repeat in row order (a review)
    with pytest.raises(InputError, match=r"from_xyz: .*first: 9, 2 times"):
        PointCloud.from_xyz(np.zeros(5), np.zeros(5), np.zeros(5), index=np.array([9, 9, 1, 2, 1]))


def test_writing_into_a_missing_folder_names_it(tmp_path):
    """pp.write into a folder that does not exist raised FileNotFoundError naming the writer's hidden
    temporary file (a review)."""
    import numpy as np

    from pointspro.core import PointCloud, api
    from pointspro.core.errors import InputError

    with pytest.raises(InputError, match=r"the folder .*no_such_dir does not exist"):
        api.write(PointCloud.from_numpy(np.zeros((3, 3))), tmp_path / "no_such_dir" / "c.csv")


def test_integers_beyond_int64_are_refused_not_wrapped():
    """A uint64 channel of 2⁶³ or more (or an integer channel given as floats beyond ±2⁶³) became a
    negative int64 with no word (a review); it is refused, naming the channel and the value."""
    from pointspro.core.cloud import PointCloud

    g = np.zeros(3)
    with pytest.raises(ValueError, match=r"channel 'flag' holds 18446744073709551615, beyond the 64-bit"):
        PointCloud.from_xyz(g, g, g, flag=np.array([1, 2, 2**64 - 1], dtype=np.uint64))
    with pytest.raises(ValueError, match=r"channel 'index' holds 1e\+19, beyond the 64-bit"):
        PointCloud.from_xyz(g, g, g, index=np.array([1.0, 2.0, 1e19]))
    assert int(PointCloud.from_xyz(g, g, g, line=np.array([1.0, 2.0, -(2.0**63)]))["line"][2]) == -(2**63)
    kept = PointCloud.from_xyz(g, g, g, flag=np.array([1, 2, 2**63 - 1], dtype=np.uint64))
    assert kept["flag"].dtype == np.int64 and int(kept["flag"][2]) == 2**63 - 1
