"""Issue 21, everyday command line: `pointspro info`, --set overrides, --cloud-format, --help,
overall progress with workers, -v / --log-file with the steps' log (from workers too)."""
from __future__ import annotations

import io
import json
import logging
import re
import shutil

import numpy as np
import pytest

from pointspro.core.io import read_cloud

from .conftest import EXAMPLE, ROOT, write

RECIPE = EXAMPLE / "recipe.yaml"
DATA = EXAMPLE / "asphere_cmm.csv"
#: the example's recipe without the slow figures' steps: knn_denoise and its neighbours, for the log
LOG_RECIPE = ("pointspro: 1\n"
              "surface: {type: even_asphere, c: 3.3333333333333335e-4, k: -0.98, "
              "A: {4: 7.0e-13, 6: 1.0e-19}, aperture: 1300}\n"
              "steps:\n  - probe_radius: {radius: 4.0, side: +1}\n  - misalignment: {}\n"
              "  - knn_denoise: {window: 15.0, remove: auto}\n"
              "  - zernike: {ordering: fringe, terms: 36, remove: [piston, tilt]}\n")


def _grid_csv(tmp_path, name="plane.csv", h=2e-5):
    """A 20 × 20 mm grid, pitch 1 mm: a tilted plane plus a ±h checkerboard. On an even grid the
    checkerboard is orthogonal to piston and both tilts, so after the plane's removal RMS = h and
    PV = 2h exactly."""
    i, j = np.meshgrid(np.arange(20), np.arange(20))
    x, y = i.ravel() * 1.0, j.ravel() * 1.0
    z = 0.1 + 2e-3 * x - 3e-3 * y + h * (-1.0) ** (i + j).ravel()
    p = tmp_path / name
    np.savetxt(p, np.column_stack([x, y, z]), delimiter=",", header="x,y,z", comments="", fmt="%.12g")
    return p


# --- 1. pointspro info -------------------------------------------------------------------------------

def test_info_describes_a_scattered_cloud(run_cli, tmp_path):
    p = _grid_csv(tmp_path)
    code, out, err = run_cli("info", p)
    assert code == 0, err
    assert "points     400" in out
    assert "x [mm], y [mm], z [mm], index" in out
    assert "comma-delimited" in out
    assert "0 … 19 mm" in out  # x and y extents
    assert "mean nearest-neighbour spacing 1 mm (in x, y)" in out
    assert "RMS 20 nm, PV 40 nm after piston and tilt removal" in out

    code, out, err = run_cli("info", p, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["points"] == 400 and d["format"] == "text" and d["grid"] is None
    assert d["extent_mm"]["x"] == [0.0, 19.0] and d["extent_mm"]["y"] == [0.0, 19.0]
    assert d["spacing_mm"] == pytest.approx(1.0, rel=1e-4)
    assert d["z_plane_removed"]["rms_mm"] == pytest.approx(2e-5, rel=1e-6)
    assert d["z_plane_removed"]["pv_mm"] == pytest.approx(4e-5, rel=1e-6)
    assert {"name": "z", "unit": "mm"} in d["channels"]


def test_info_spacing_is_lateral(run_cli):
    """The sampling in x, y, as the steps see it: ISO 5436's sample 2 (16 points, 1 µm apart in x, y,
    heights over metres) read 40.6 mm in 3-D (a review)."""
    from .conftest import ROOT

    code, out, err = run_cli("info", ROOT / "tests" / "data" / "realdata" / "ISO5436-sample2.x3p", "--json")
    assert code == 0, err
    d = json.loads(out)
    ex = d["extent_mm"]
    assert d["spacing_mm"] <= max(ex["x"][1] - ex["x"][0], ex["y"][1] - ex["y"][0])
    assert d["spacing_mm"] < 0.01 * (ex["z"][1] - ex["z"][0])


def test_info_refuses_coordinates_beyond_any_machine(run_cli, tmp_path):
    """Coordinates of ~1e300 mm: the spacing was printed as "inf mm", then "spacing not computable";
    every reader now refuses a coordinate beyond 10¹² mm as corrupt, naming its line
    (docs/formats.md)."""
    p = tmp_path / "absurd.csv"
    p.write_text("x,y,z\n0,0,0\n1e300,0,1\n0,1e300,2\n-1e300,-1e300,3\n")
    code, out, err = run_cli("info", p)
    assert code == 2 and "inf mm" not in out
    assert "absurd.csv, line 3: x = 1e+300 mm lies beyond any measuring machine" in err


def test_info_describes_a_map_grid(run_cli):
    code, out, err = run_cli("info", ROOT / "tests" / "data" / "realdata" / "sdf-1.sdf", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["grid"] == {"rows": 4, "cols": 7, "pixel_mm": [pytest.approx(1e-3), pytest.approx(1e-3)]}
    assert d["points"] == 28 and d["spacing_mm"] is None and "SDF" in d["reader"]
    code, out, _ = run_cli("info", ROOT / "tests" / "data" / "realdata" / "sdf-1.sdf")
    assert "grid       4 rows × 7 cols, pixel 1 µm × 1 µm" in out


def test_info_bad_file_one_line_exit_2(run_cli, tmp_path):
    bad = write(tmp_path / "notes.csv", "hello\nworld\n")
    code, out, err = run_cli("info", bad)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "notes.csv" in err and "Traceback" not in err
    code, _, err = run_cli("info", tmp_path / "missing.csv")
    assert code == 2 and "file not found" in err and err.count("\n") == 1


# --- 2. --set ---------------------------------------------------------------------------------------

def _small_inputs(tmp_path, n=2):
    rng = np.random.default_rng(5)
    files = []
    for k in range(n):
        p = tmp_path / f"m{k}.csv"
        np.savetxt(p, rng.uniform(-50, 50, (400, 3)), delimiter=",", header="x,y,z", comments="",
                   fmt="%.9f")
        files.append(p)
    return files


def _report(folder):
    return json.loads((folder / "report.json").read_text(encoding="utf-8"))


def test_set_overrides_by_id_position_and_surface(run_cli, tmp_path):
    (m0,) = _small_inputs(tmp_path, 1)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsurface: {type: even_asphere, c: 0, k: 0, "
                   "aperture: 100}\nsteps:\n  - aperture: {}\n  - manual_edit: {remove: [1]}\n")
    assert run_cli("--batch", recipe, m0, "--out", tmp_path / "plain", "--quiet")[0] == 0
    n_plain = _report(tmp_path / "plain" / "m0")["summary"]["points_out"]
    code, _, err = run_cli("--batch", recipe, m0, "--out", tmp_path / "o", "--quiet",
                           "--set", "aperture.diameter=60", "--set", "2.remove=[1, 2, 3]",
                           "--set", "surface.k=-1")
    assert code == 0, err
    rep = _report(tmp_path / "o" / "m0")
    assert rep["overrides"] == ["aperture.diameter=60", "2.remove=[1, 2, 3]", "surface.k=-1"]
    steps = rep["recipe"]["steps"]
    assert steps[0]["aperture"]["diameter"] == 60.0 and steps[1]["manual_edit"]["remove"] == [1, 2, 3]
    assert rep["recipe"]["surface"]["k"] == -1
    m = read_cloud(m0)
    inside = int((np.hypot(m.x, m.y) <= 30).sum())
    assert rep["steps"][0]["points_out"] == inside < n_plain
    # surface.aperture reaches the step that uses it (no diameter: the surface's aperture)
    code, _, err = run_cli("--batch", recipe, m0, "--out", tmp_path / "s", "--quiet",
                           "--set", "surface.aperture=60")
    assert code == 0, err
    assert _report(tmp_path / "s" / "m0")["steps"][0]["points_out"] == inside


@pytest.mark.parametrize("override, says", [
    ("manual_edit.remove=[1]", "step 'manual_edit' occurs 2 times (steps 1, 3)"),
    ("zernike.terms=10", "the recipe has no step 'zernike'"),
    ("aperture.diam=10", "step 2 'aperture' has no parameter 'diam'"),
    ("7.remove=[1]", "no step 7; the recipe has 3 step(s)"),
    ("aperture.diameter=-5", "key 'diameter'"),
    ("aperture=5", "write STEP.KEY=VALUE"),
    ("aperture.diameter=[1, 2", "not valid YAML"),
    # a review's unclear messages: a nested key, a unit written into a length
    ("surface.A.4=1e-12", "KEY is one name — set the mapping whole: --set 'surface.A={4: …}'"),
    ("aperture.diameter=80 mm", "write a plain number, in the unit the key's help states (lengths in mm)"),
])
def test_set_errors_one_line_exit_2(run_cli, tmp_path, override, says):
    (m0,) = _small_inputs(tmp_path, 1)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsurface: {type: even_asphere, c: 1.0e-3, A: {4: 1.0e-12}}\n"
                   "steps:\n  - manual_edit: {remove: [1]}\n"
                   "  - aperture: {diameter: 80}\n  - manual_edit: {remove: [2]}\n")
    code, out, err = run_cli("--batch", recipe, m0, "--out", tmp_path / "o", "--set", override)
    assert code == 2, err
    assert says in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o" / "m0").exists()


def test_set_reaches_workers_and_resume_sees_it(run_cli, tmp_path):
    files = _small_inputs(tmp_path, 2)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 90}\n")
    args = ("--batch", recipe, *files, "--quiet", "--set", "aperture.diameter=50")
    assert run_cli(*args, "--out", tmp_path / "seq", "--workers", "1")[0] == 0
    code, _, err = run_cli(*args, "--out", tmp_path / "par", "--workers", "2")
    assert code == 0, err
    for k in range(2):
        a, b = _report(tmp_path / "seq" / f"m{k}"), _report(tmp_path / "par" / f"m{k}")
        assert a["summary"] == b["summary"] and b["recipe"]["steps"][0]["aperture"]["diameter"] == 50
        assert b["overrides"] == ["aperture.diameter=50"]

    def statuses():
        s = json.loads((tmp_path / "seq" / "summary.json").read_text(encoding="utf-8"))
        return [e["status"] for e in s["inputs"]]

    assert run_cli(*args, "--out", tmp_path / "seq", "--workers", "1", "--resume")[0] == 0
    assert statuses() == ["skipped", "skipped"]
    code, _, _ = run_cli("--batch", recipe, *files, "--quiet", "--set", "aperture.diameter=60",
                         "--out", tmp_path / "seq", "--workers", "1", "--resume")
    assert code == 0 and statuses() == ["ok", "ok"]


def test_set_and_cloud_format_go_with_batch(run_cli):
    code, _, err = run_cli("--set", "aperture.diameter=5")
    assert code == 2 and "go with --batch" in err


# --- 3. --cloud-format ------------------------------------------------------------------------------

def test_cloud_formats_read_back_identical(run_cli, tmp_path):
    (m0,) = _small_inputs(tmp_path, 1)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 90}\n"
                   "  - knn_denoise: {method: statistical, neighbours: 8}\n")
    clouds = {}
    for fmt in ("csv", "ply", "npz"):
        code, _, err = run_cli("--batch", recipe, m0, "--out", tmp_path / fmt, "--quiet",
                               "--cloud-format", fmt, "--figures", "none")
        assert code == 0, err
        folder = tmp_path / fmt / "m0"
        assert sorted(p.name for p in folder.glob("cloud.*")) == [f"cloud.{fmt}"]
        assert _report(folder)["cloud_file"] == f"cloud.{fmt}"
        clouds[fmt] = read_cloud(folder / f"cloud.{fmt}")
    ref = clouds["csv"]
    assert "omega" in ref.channels and ref.n > 100
    for fmt in ("ply", "npz"):
        c = clouds[fmt]
        assert np.array_equal(c.xyz, ref.xyz)
        assert set(c.channels) == set(ref.channels)
        for name in ref.channels:
            assert np.array_equal(c[name], ref[name]), (fmt, name)
            assert c[name].dtype == ref[name].dtype
    # the npz loads with numpy alone: every column, float64 (integers int64), the metadata as JSON
    with np.load(tmp_path / "npz" / "m0" / "cloud.npz", allow_pickle=False) as z:
        meta = json.loads(str(z["pointspro_meta"]))
        assert meta["units"] == "mm" and meta["frame"] == "measuring"
        assert meta["columns"][:3] == ["x", "y", "z"] and "omega" in meta["columns"]
        assert z["omega"].dtype == np.float64 and z["index"].dtype == np.int64
        assert np.array_equal(z["z"], ref.z)


def test_npz_states_the_units_its_numbers_are_in(run_cli, tmp_path):
    """A channel read in nm is held in mm: cloud.npz says mm beside it, as cloud.csv's header does (it
    said the input's nm beside numbers in mm — 10⁶ off for anyone reading the file by its metadata);
    a step's length channel (omega) says mm too, a non-length unit stays as stated; an npz written
    the old way reads back as mm."""
    rng = np.random.default_rng(5)
    rows = "".join(f"{a!r},{b!r},{i * 1e-6!r},{3.0 * i!r},{0.5 * i!r}\n"
                   for i, (a, b) in enumerate(rng.uniform(-60, 60, (300, 2)).tolist()))
    src = write(tmp_path / "in.csv", "x,y,z,dev [nm],t [s]\n" + rows)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - knn_denoise: {method: statistical, neighbours: 8}\n")
    for fmt in ("csv", "npz"):
        code, _, err = run_cli("--batch", recipe, src, "--out", tmp_path / fmt, "--quiet", "--cloud-format", fmt,
                               "--figures", "none")
        assert code == 0, err
    path = tmp_path / "npz" / "in" / "cloud.npz"
    with np.load(path, allow_pickle=False) as z:
        units = json.loads(str(z["pointspro_meta"]))["channel_units"]
        assert np.allclose(z["dev"][:3], [0.0, 3e-6, 6e-6], rtol=1e-12, atol=0)
    assert units == {"dev": "mm", "t": "s", "omega": "mm"}
    header = (tmp_path / "csv" / "in" / "cloud.csv").read_text(encoding="utf-8").splitlines()[0]
    assert "dev [mm]" in header and "t [s]" in header and "omega [mm]" in header
    # the former writer's metadata (the input's unit) read back as what the numbers are: mm
    from pointspro.core.io.npz import read_npz

    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["pointspro_meta"]))
    meta["channel_units"] = {"dev": "nm", "t": "s"}
    arrays["pointspro_meta"] = np.array(json.dumps(meta))
    old = tmp_path / "old.npz"
    np.savez(old, **arrays)
    assert read_npz(old)[2]["channel_units"] == {"dev": "mm", "t": "s"}
    assert read_cloud(old).meta["channel_units"]["dev"] == "mm"


def test_resume_reruns_an_output_of_another_cloud_format(run_cli, tmp_path):
    (m0,) = _small_inputs(tmp_path, 1)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 90}\n")
    base = ("--batch", recipe, m0, "--out", tmp_path / "o", "--quiet")
    assert run_cli(*base, "--cloud-format", "npz")[0] == 0
    summary = tmp_path / "o" / "summary.json"
    assert run_cli(*base, "--cloud-format", "npz", "--resume")[0] == 0
    assert json.loads(summary.read_text(encoding="utf-8"))["inputs"][0]["status"] == "skipped"
    assert run_cli(*base, "--resume")[0] == 0  # csv now: not the output asked for, run again
    assert json.loads(summary.read_text(encoding="utf-8"))["inputs"][0]["status"] == "ok"
    assert (tmp_path / "o" / "m0" / "cloud.csv").is_file()
    assert not (tmp_path / "o" / "m0" / "cloud.npz").exists()


# --- 4. --help ----------------------------------------------------------------------------------------

def test_help_lists_commands_formats_exit_codes_and_examples(run_cli):
    code, out, _ = run_cli("--help")
    assert code == 0
    for word in ("pointspro info FILE", "pointspro steps", "pointspro simulate", "pointspro explain",
                 "open the window", "--batch RECIPE INPUT", "--set", "--cloud-format", "--log-file",
                 "--verbose"):
        assert word in out, word
    for fmt in (".csv", ".ply", ".datx", ".sur", ".x3p", ".sdf", "cloud.npz"):
        assert fmt in out, fmt
    codes = out.split("exit codes:")[1]
    for line in ("0    all done", "1    some inputs failed", "2    usage, recipe or input error",
                 "130  interrupted"):
        assert line in codes
    assert "examples:" in out and "pointspro --batch recipe.yaml scans/*.csv --out results" in out
    code, out, _ = run_cli("info", "--help")
    assert code == 0 and "--json" in out


# --- 5. progress with workers -----------------------------------------------------------------------

def test_workers_show_overall_progress_lines_not_on_a_tty(run_cli, tmp_path):
    files = _small_inputs(tmp_path, 3)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 90}\n")
    code, out, err = run_cli("--batch", recipe, *files, "--out", tmp_path / "o", "--workers", "2")
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("[")]
    assert [ln.split("]")[0] + "]" for ln in lines] == ["[1/3]", "[2/3]", "[3/3]"]
    assert lines[-1].startswith("[3/3] 3 done, 0 failed")
    assert "left" in lines[0]  # an ETA while inputs remain
    code, out, err = run_cli("--batch", recipe, *files, "--out", tmp_path / "q", "--workers", "2",
                             "--quiet")
    assert code == 0 and err == "" and out == ""


class _FakeTTY(io.StringIO):
    def isatty(self):
        return True


def test_workers_progress_bar_on_a_tty_counts_done_and_failed():
    from pointspro.core.terminal import BatchProgress

    tty = _FakeTTY()
    bar = BatchProgress(3, stream=tty)
    bar.advance(True, "a.csv")
    bar.advance(False, "b.csv")
    out = io.StringIO()
    bar.write("a.csv: ok", out)
    bar.close()
    text = tty.getvalue()
    assert "\r" in text and "2/3" in text and "1 done, 1 failed" in text
    assert "a.csv: ok\n" in out.getvalue()
    plain = io.StringIO()  # not a TTY: one plain line per input, no carriage returns
    bar = BatchProgress(2, stream=plain)
    bar.advance(True, "a.csv")
    bar.advance(False, "b.csv")
    assert "\r" not in plain.getvalue()
    assert plain.getvalue().splitlines()[-1] == "[2/2] 1 done, 1 failed — b.csv failed"


# --- 6. logging ---------------------------------------------------------------------------------------

def test_verbose_shows_the_steps_log_and_log_file_keeps_it(run_cli, tmp_path):
    recipe = write(tmp_path / "r.yaml", LOG_RECIPE)
    data = shutil.copy(DATA, tmp_path / "part.csv")
    code, out, err = run_cli("--batch", recipe, data, "--out", tmp_path / "q", "--quiet", "--figures", "none")
    assert code == 0 and "pointspro.knn_denoise" not in err  # WARNING by default
    log = tmp_path / "run.log"
    logger = logging.getLogger("pointspro")
    before = (list(logger.handlers), logger.level, logger.propagate)
    code, out, err = run_cli("--batch", recipe, data, "--out", tmp_path / "o", "--quiet", "--figures", "none", "-v",
                             "--log-file", log)
    assert code == 0, err
    assert re.search(r"pointspro\.knn_denoise: part\.csv: \d+ of 4680 points removed", err)
    assert "pointspro.misalignment: part.csv: pose alpha_deg" in err
    assert "pointspro.probe_radius: part.csv: probe radius 4 mm" in err
    assert "pointspro.zernike: part.csv: 36 terms fitted" in err
    text = log.read_text(encoding="utf-8")
    assert re.search(r"INFO pointspro\.knn_denoise: part\.csv: \d+ of 4680 points removed", text)
    # the loggers are as they were (main() may run again in this process)
    assert (list(logger.handlers), logger.level, logger.propagate) == before
    # --log-file alone: the file has the INFO lines, the terminal does not
    code, out, err = run_cli("--batch", recipe, data, "--out", tmp_path / "f", "--quiet", "--figures", "none",
                             "--log-file", tmp_path / "only.log")
    assert code == 0 and "pointspro.knn_denoise" not in err
    assert "pointspro.knn_denoise: part.csv:" in (tmp_path / "only.log").read_text(encoding="utf-8")


def test_workers_send_their_log_records_to_the_parent(run_cli, tmp_path):
    recipe = write(tmp_path / "r.yaml", LOG_RECIPE)
    a = shutil.copy(DATA, tmp_path / "a.csv")
    b = shutil.copy(DATA, tmp_path / "b.csv")
    log = tmp_path / "run.log"
    code, out, err = run_cli("--batch", recipe, a, b, "--out", tmp_path / "o", "--workers", "2",
                             "--quiet", "--figures", "none", "-v", "--log-file", log)
    assert code == 0, err
    for name in ("a.csv", "b.csv"):
        assert re.search(rf"pointspro\.knn_denoise: {name}: \d+ of 4680 points removed", err)
        assert f"INFO pointspro.misalignment: {name}: pose" in log.read_text(encoding="utf-8")


def test_log_file_never_appends_to_what_the_run_reads_or_writes(run_cli, tmp_path):
    """--log-file appended its lines to the input or the recipe it was pointed at (the next read of
    the CSV then failed on a log line; the recipe became invalid YAML), and inside --out it vanished
    with the folder the batch replaced: refused, nothing changed, nothing written (review 2026-11-26)."""
    import hashlib

    recipe = write(tmp_path / "r.yaml", LOG_RECIPE)
    data = shutil.copy(DATA, tmp_path / "part.csv")
    before = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (recipe, data)}
    for log, says in ((data, "is an input"), (recipe, "is the recipe"),
                      (tmp_path / "o" / "part" / "run.log", "is inside --out")):
        code, _, err = run_cli("--batch", recipe, data, "--out", tmp_path / "o", "--quiet", "--figures", "none",
                               "--log-file", log)
        assert code == 2 and says in err and err.count("\n") == 1, err
        assert {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (recipe, data)} == before
        assert not (tmp_path / "o").exists()


def test_screenshot_never_overwrites_an_input_and_needs_an_image_name(run_cli, tmp_path):
    """--screenshot part.csv part.csv emptied the input (Qt truncates, then fails on the suffix) and
    exited 0; a .txt name or a missing folder wrote nothing and said nothing."""
    data = shutil.copy(DATA, tmp_path / "part.csv")
    size = data.stat().st_size
    for shot, says in ((data, "is a file the window opens"), (tmp_path / "shot.txt", "give an image file name"),
                       (tmp_path / "no" / "shot.png", "does not exist")):
        code, _, err = run_cli("--screenshot", shot, data)
        assert code == 2 and says in err, err
    assert data.stat().st_size == size and not (tmp_path / "shot.txt").exists()


@pytest.mark.parametrize("recipe,key", [
    ("steps:\n  - transform: {pose: {dx: .inf}}\n", "key 'pose.dx': Input should be a finite number"),
    ("steps:\n  - misalignment: {initial: {alpha_deg: .nan}}\n", "key 'initial.alpha_deg'"),
    ("surface: {type: even_asphere, c: .nan, k: -0.98}\nsteps:\n  - misalignment: {}\n", "surface: key"),
    ("surface: {type: even_asphere, c: 0.0003, k: 0, A: {4: .inf}}\nsteps:\n  - misalignment: {}\n",
     "surface: key"),
    ("steps:\n  - zernike: {norm_radius: .inf}\n", "key 'norm_radius'"),
])
def test_nan_and_inf_parameters_are_refused_at_load(run_cli, tmp_path, recipe, key):
    """A pose dx of .inf wrote a cloud of inf/NaN with exit 0; a NaN conic or initial tilt reached
    LAPACK ("SVD did not converge — please report"); norm_radius .inf gave 4.8e16 nm uncertainties:
    NaN and ±inf are never a parameter (review 2026-11-26)."""
    r = write(tmp_path / "r.yaml", "pointspro: 1\n" + recipe)
    code, _, err = run_cli("--batch", r, DATA, "--out", tmp_path / "o", "--quiet")
    assert code == 2 and key in err and "line" in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_simulate_refuses_non_finite_effect_values(run_cli, tmp_path):
    """A NaN vibration frequency simulated 20,000 NaN heights with exit 0; a list was an internal error."""
    for value, says in ((".nan", "frequency_hz = nan is not a finite number"),
                        ("true", "frequency_hz = True is not a finite number"),
                        ("[1, 2]", "frequency_hz = [1, 2] is not a finite number")):
        m = write(tmp_path / "m.yaml", "pointspro_model: 1\nsurface: {type: sphere, R: 100}\n"
                  "scan: {type: raster, radius: 10, pitch: 1}\n"
                  f"effects:\n  - vibration: {{frequency_hz: {value}, amplitude: 8.0e-6}}\n")
        code, _, err = run_cli("simulate", m, "--out", tmp_path / "s.csv")
        assert code == 2 and says in err and "line 4" in err, err
        assert not (tmp_path / "s.csv").exists()


def test_a_probe_radius_in_the_model_is_refused_as_not_simulated(run_cli, tmp_path):
    """`probe: {radius: 0.5}` was accepted and changed nothing (byte-identical simulations): it names
    the effect that simulates an uncompensated tip radius instead."""
    m = write(tmp_path / "m.yaml", "pointspro_model: 1\nsurface: {type: sphere, R: 100}\n"
              "scan: {type: raster, radius: 10, pitch: 1}\nprobe: {noise: 1.0e-6, radius: 0.5}\n")
    code, _, err = run_cli("simulate", m, "--out", tmp_path / "s.csv")
    assert code == 2 and "line 4" in err and "probe_radius: {radius: 0.5}" in err, err
    assert "Value error" not in err  # the validator's own words
    assert not (tmp_path / "s.csv").exists()


def test_the_same_key_set_twice_is_refused(run_cli, tmp_path):
    """A review: of `--set 5.diameter=1000 --set aperture.diameter=1200` the last won silently; the same
    key named twice — by position or by id — is refused naming both."""
    base = ("--batch", EXAMPLE / "recipe.yaml", EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--quiet",
            "--figures", "none")
    code, _, err = run_cli(*base, "--set", "5.diameter=1000", "--set", "aperture.diameter=1200")
    assert code == 2 and "--set aperture.diameter=1200: sets what --set 5.diameter=1000 set already" in err, err
    code, _, err = run_cli(*base, "--set", "surface.k=-1", "--set", "surface.k=-0.98")
    assert code == 2 and "sets what --set surface.k=-1 set already" in err, err
    assert not (tmp_path / "o").exists()
    code, _, err = run_cli(*base, "--set", "surface.k=-0.98", "--set", "knn_denoise.window=12")
    assert code == 0, err


def test_unclear_messages_a_review_found(run_cli, tmp_path):
    """Inputs written before the recipe; `enabled` among a step's parameters; a measurement model that
    is not UTF-8; a sub-command's usage error pointing to the top-level help; "nothing was written"
    beside a summary.json that was."""
    (m0,) = _small_inputs(tmp_path, 1)
    code, _, err = run_cli("--batch", RECIPE, m0, "--out", tmp_path / "o", "--set", "misalignment.initial.dx=1")
    assert code == 2 and "KEY is one name — set the mapping whole: --set 'misalignment.initial={dx: …}'" in err
    code, _, err = run_cli("--batch", m0, RECIPE, "--out", tmp_path / "o")
    assert code == 2 and "--batch takes the recipe first" in err and f"{RECIPE} looks like the recipe" in err
    r = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 80, enabled: false}\n")
    code, _, err = run_cli("--batch", r, m0, "--out", tmp_path / "o")
    assert code == 2 and "line 3: step 1 'aperture': key 'enabled' belongs beside the step" in err
    (tmp_path / "m.yaml").write_bytes("pointspro_model: 1\n# caf\u00e9\n".encode("latin-1"))
    code, _, err = run_cli("simulate", tmp_path / "m.yaml", "--out", tmp_path / "s.csv")
    assert code == 2 and "m.yaml, line 2: not UTF-8 text (byte 0xe9); save the measurement model as UTF-8" in err
    code, _, err = run_cli("explain", "--measured", m0)
    assert code == 2 and "(see pointspro explain --help)" in err
    bad = write(tmp_path / "bad.csv", "not numbers\n")
    bad2 = write(tmp_path / "bad2.csv", "neither\n")
    code, _, err = run_cli("--batch", RECIPE, bad, bad2, "--out", tmp_path / "f", "--quiet")
    assert code == 1 and "all 2 inputs failed; no input's outputs were written" in err
    assert (tmp_path / "f" / "summary.json").is_file()
