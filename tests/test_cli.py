"""`pointspro --batch` end to end: outputs, exit codes, one-line errors, atomicity, no Qt."""
from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.io import read_cloud
from pointspro.core.metrics.area_weights import area_weights, weighted_rms

from .conftest import EXAMPLE, EXAMPLE_OUTPUTS, write

RECIPE = EXAMPLE / "recipe.yaml"
DATA = EXAMPLE / "asphere_cmm.csv"


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_example_batch_writes_outputs_and_leaves_input_alone(run_cli, tmp_path):
    before = _sha(DATA)
    code, out, err = run_cli("--batch", RECIPE, DATA, "--out", tmp_path / "out")
    assert code == 0, err
    folder = tmp_path / "out" / "asphere_cmm"
    assert {p.name for p in folder.iterdir()} == EXAMPLE_OUTPUTS
    rep = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    assert set(rep) >= {"pointspro", "input", "recipe", "steps", "summary"}
    ids = [s["id"] for s in rep["steps"]]
    assert ids == ["manual_edit", "probe_radius", "misalignment", "knn_denoise", "aperture", "zernike",
                   "bspline_map"]
    steps = {s["id"]: s["report"] for s in rep["steps"]}
    assert steps["manual_edit"]["removed"] == 2
    truth = json.loads((EXAMPLE / "truth.json").read_text(encoding="utf-8"))
    mis = steps["misalignment"]
    # the pose of the simulation (the form error's projection on tilt/decenter limits dx, dy)
    assert abs(mis["alpha_deg"] - truth["pose"]["alpha_deg"]) < 0.005
    assert abs(mis["dx"] - truth["pose"]["dx"]) < 0.2 and abs(mis["dy"] - truth["pose"]["dy"]) < 0.2
    assert abs(mis["dz"] - truth["pose"]["dz"]) < 0.01
    s = rep["summary"]
    assert s["points_in"] == 4680 and s["points_out"] == rep["steps"][-1]["points_out"]
    # knn_denoise finds exactly the simulated outliers the optician did not delete by hand
    outliers = {int(k) for k in truth["outliers"]} - {520, 3640}
    assert set(steps["knn_denoise"]["removed_index"]) == outliers
    # what is left: form error 0.59 µm RMS over the area ⊕ 0.3 µm noise (the star's points crowd its
    # centre: their plain RMS, 0.47 µm of form error, is not the surface's — core/metrics/area_weights.py)
    assert s["rms_um"] == pytest.approx(np.hypot(truth["form_error_rms_um"], truth["noise_um"]), rel=0.05)
    assert s["rms_over"].startswith("area")
    assert s["pv_um"] < truth["form_error_pv_um"] + 8 * truth["noise_um"]
    cloud = read_cloud(folder / "cloud.csv")
    assert cloud.n == s["points_out"] and "residual" in cloud.channels and "probe_residual" in cloud.channels
    assert 520 not in cloud.index and 3640 not in cloud.index
    assert np.all(np.diff(cloud.index) > 0)  # input order kept
    w = area_weights(cloud.x, cloud.y)
    assert weighted_rms(cloud["residual"], w) * 1e3 == pytest.approx(s["rms_um"], rel=1e-9)
    html = (folder / "report.html").read_text(encoding="utf-8")
    assert "Clear aperture" in html and "asphere_cmm.csv" in html
    assert "RMS and slope RMS over the area" in html  # the star scan's weighting, said
    assert _sha(DATA) == before
    assert "asphere_cmm.csv: ok" in out
    assert not list((tmp_path / "out").glob(".*"))  # no temporary leftovers


def _two_inputs(tmp_path):
    good = write(tmp_path / "good.csv", "x,y,z\n0,0,0\n1,0,0\n0,1,0\n")
    bad = write(tmp_path / "bad.csv", "x,y,z\n0,0,0\n1,zz,0\n")
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - manual_edit: {remove: [1]}\n")
    return good, bad, recipe


def test_one_bad_input_among_several_fails_alone(run_cli, tmp_path):
    good, bad, recipe = _two_inputs(tmp_path)
    code, out, err = run_cli("--batch", recipe, bad, good, "--out", tmp_path / "o")
    assert code == 1
    assert "bad.csv, line 3, column 2: 'zz' is not a number" in err
    assert "Traceback" not in err
    assert (tmp_path / "o" / "good" / "report.json").is_file()
    assert not (tmp_path / "o" / "bad").exists()


@pytest.mark.parametrize("make,pattern", [
    (lambda t: ("--batch", t / "r.yaml", t / "missing.csv"), r"missing.csv: file not found"),
    (lambda t: ("--batch", t / "r.yaml", write(t / "e.csv", "")), r"e.csv: empty file"),
    (lambda t: ("--batch", t / "r.yaml", write(t / "n.csv", "x,y,z\n1,2,nan\n")),
     r"n.csv, line 2, column 3 \(z\)"),
    (lambda t: ("--batch", t / "r.yaml", write(t / "w.csv", "x,y,z\n1,2,3\n1,2\n")),
     r"w.csv, line 3: 2 column"),
    (lambda t: ("--batch", t / "r.yaml", write(t / "a.csv", "a,b,c\n1,2,3\n")), r"no x/y/z column"),
    (lambda t: ("--batch", write(t / "u.yaml", "pointspro: 1\nsteps:\n  - knn_magic: {}\n"),
                write(t / "g.csv", "1 2 3\n")), r"u.yaml, line 3: step 1: unknown step 'knn_magic'"),
    (lambda t: ("--batch", write(t / "k.yaml", "pointspro: 1\nsteps:\n  - aperture: {diametr: 3}\n"),
                write(t / "g.csv", "1 2 3\n")), r"k.yaml, line 3: step 1 'aperture': key 'diametr': unknown key"),
    (lambda t: ("--batch", write(t / "v.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 0}\n"),
                write(t / "g.csv", "1 2 3\n")), r"key 'diameter': Input should be greater than 0"),
    (lambda t: ("--batch", t / "r.yaml"), r"--batch needs RECIPE and at least one INPUT"),
    (lambda t: ("--batch", t / "nope.yaml", write(t / "g.csv", "1 2 3\n")), r"nope.yaml: recipe file not found"),
    (lambda t: ("--batch", t, write(t / "g.csv", "1 2 3\n")), r": is a folder, not a recipe file"),
])
def test_bad_input_exit_2_one_line_no_output(run_cli, tmp_path, make, pattern):
    import re

    write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - manual_edit: {}\n")
    args = make(tmp_path)
    code, out, err = run_cli(*args, "--out", tmp_path / "o")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pointspro: "), err
    assert re.search(pattern, err), err
    assert "Traceback" not in err
    outdir = tmp_path / "o"
    # nothing but, once the inputs were reached, the batch's summary recording the failure
    left = sorted(p.name for p in outdir.iterdir()) if outdir.exists() else []
    assert left in ([], ["summary.json"])
    if left:
        summary = json.loads((outdir / "summary.json").read_text(encoding="utf-8"))
        assert [e["status"] for e in summary["inputs"]] == ["failed"]
        assert summary["inputs"][0]["error"] in err


def test_unwritable_output_folder(run_cli, tmp_path):
    good, _, recipe = _two_inputs(tmp_path)
    blocker = write(tmp_path / "file_not_dir", "x")
    code, _, err = run_cli("--batch", recipe, good, "--out", blocker / "sub")
    assert code == 2 and "cannot create the output folder" in err and "file_not_dir" in err
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):  # root ignores permissions: make the check meaningful anyway
            ro.chmod(0o700)
            code, _, err = run_cli("--batch", recipe, good, "--out", write(tmp_path / "f", "x"))
            assert code == 2 and "not a folder" in err
        else:
            code, _, err = run_cli("--batch", recipe, good, "--out", ro)
            assert code == 2 and "not writable" in err
    finally:
        ro.chmod(0o700)


def test_duplicate_output_stems_rejected(run_cli, tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    x1 = write(tmp_path / "a" / "m.csv", "1 2 3\n")
    x2 = write(tmp_path / "b" / "m.csv", "1 2 3\n")
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps: []\n")
    code, _, err = run_cli("--batch", recipe, x1, x2, "--out", tmp_path / "o")
    assert code == 2 and "would both write m/" in err


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize("case", ["input_in_its_own_folder", "input_is_summary", "stem_is_summary",
                                  "user_folder", "user_file", "user_summary"])
def test_outputs_never_destroy_what_is_not_theirs(run_cli, tmp_path, case):
    """Before this check each of these ran with exit 0 and deleted or overwrote the user's file;
    now one line names the path, exit 2, and nothing in the tree changes (no output folder made)."""
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps: []\n")
    data = "x,y,z\n1,2,3\n4,5,6\n7,8,10\n"
    out = tmp_path / "o"
    if case == "input_in_its_own_folder":
        (out / "part").mkdir(parents=True)
        inp, want = write(out / "part" / "part.csv", data), "lies in"
    elif case == "input_is_summary":
        out.mkdir()
        inp, want = write(out / "summary.json", data), "is the batch's own"
    elif case == "stem_is_summary":
        inp, want = write(tmp_path / "summary.json.csv", data), "would be the batch's own"
    else:
        inp = write(tmp_path / "part.csv", data)
        out.mkdir()
        if case == "user_folder":
            (out / "part").mkdir()
            write(out / "part" / "notes.txt", "precious")
            want = "is not a PointsPro output folder"
        elif case == "user_file":
            write(out / "part", "precious")
            want = "exists and is not a folder"
        else:
            write(out / "summary.json", "precious")
            want = "is not a PointsPro batch summary"
    before = _snapshot(tmp_path)
    code, _, err = run_cli("--batch", recipe, inp, "--out", out)
    assert code == 2 and want in err and len(err.strip().splitlines()) == 1, err
    assert _snapshot(tmp_path) == before


def test_a_second_run_into_the_same_folder_still_replaces_its_outputs(run_cli, tmp_path):
    """The check lets a batch replace its own folders and summary (and an empty folder)."""
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps: []\n")
    inp = write(tmp_path / "part.csv", "x,y,z\n1,2,3\n4,5,6\n7,8,10\n")
    (tmp_path / "o" / "other").mkdir(parents=True)
    for _ in range(2):
        code, _, err = run_cli("--batch", recipe, inp, write(tmp_path / "other.csv", "1 2 3\n4 5 6\n7 8 10\n"),
                               "--out", tmp_path / "o")
        assert code == 0, err


def test_rerun_replaces_a_complete_folder_atomically(run_cli, tmp_path):
    good, _, recipe = _two_inputs(tmp_path)
    assert run_cli("--batch", recipe, good, "--out", tmp_path / "o")[0] == 0
    first = (tmp_path / "o" / "good" / "cloud.csv").read_text(encoding="utf-8")
    assert run_cli("--batch", recipe, good, "--out", tmp_path / "o")[0] == 0
    assert (tmp_path / "o" / "good" / "cloud.csv").read_text(encoding="utf-8") == first
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["good", "summary.json"]


def test_a_file_added_to_an_earlier_output_is_not_deleted_by_a_rerun(run_cli, tmp_path):
    """An earlier output's folder is replaced as a whole: a user's notes put beside the results were
    deleted with it, exit 0 (a review). report.json lists the files it wrote; anything else is named."""
    good, _, recipe = _two_inputs(tmp_path)
    assert run_cli("--batch", recipe, good, "--out", tmp_path / "o")[0] == 0
    write(tmp_path / "o" / "good" / "notes.txt", "precious")
    code, _, err = run_cli("--batch", recipe, good, "--out", tmp_path / "o")
    assert code == 2 and "notes.txt: is not one of the files of the earlier output" in err
    assert (tmp_path / "o" / "good" / "notes.txt").read_text(encoding="utf-8") == "precious"
    # --resume: a complete folder is skipped, notes and all (a review: the whole batch was refused)
    code, _, err = run_cli("--batch", recipe, good, "--out", tmp_path / "o", "--resume")
    assert code == 0, err
    assert (tmp_path / "o" / "good" / "notes.txt").read_text(encoding="utf-8") == "precious"
    status = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))["inputs"][0]["status"]
    assert status == "skipped"
    code, _, err = run_cli("--batch", recipe, good, "--out", tmp_path / "o", "--resume", "--check-only")
    assert code == 0, err
    good.write_text(good.read_text(encoding="utf-8") + "\n", encoding="utf-8")  # changed: it runs again
    for extra in (("--check-only",), ()):  # --check-only says what the run then does (a review)
        code, _, err = run_cli("--batch", recipe, good, "--out", tmp_path / "o", "--resume", *extra)
        assert code == 2 and "notes.txt: is not one of the files of the earlier output" in err
    (tmp_path / "o" / "good" / "notes.txt").unlink()
    assert run_cli("--batch", recipe, good, "--out", tmp_path / "o")[0] == 0


def test_api_write_never_destroys_a_users_folder_or_the_input(tmp_path):
    """Result.write replaced out/<stem> without the batch's checks: a folder of the user's files was
    deleted, and so was the input lying in it (a review)."""
    import pointspro.core as pp
    from pointspro.core.errors import RecipeError

    good, _, recipe = _two_inputs(tmp_path)
    res = pp.run(recipe, good)
    (tmp_path / "o" / "good").mkdir(parents=True)
    write(tmp_path / "o" / "good" / "mine.txt", "precious")
    with pytest.raises(RecipeError, match="is not a PointsPro output folder"):
        res.write(tmp_path / "o")
    assert (tmp_path / "o" / "good" / "mine.txt").is_file()
    inside = tmp_path / "p" / "good" / "good.csv"
    inside.parent.mkdir(parents=True)
    inside.write_bytes(good.read_bytes())
    with pytest.raises(RecipeError, match="lies in"):
        pp.run(recipe, inside).write(tmp_path / "p")
    assert inside.read_bytes() == good.read_bytes()
    assert (res.write(tmp_path / "q") / "report.json").is_file()  # a new folder, and again over its own
    assert (res.write(tmp_path / "q") / "report.json").is_file()


def test_failure_while_writing_leaves_no_folder(tmp_path, monkeypatch):
    from pointspro.core import batch
    from pointspro.core.recipe import parse_recipe

    good, _, _ = _two_inputs(tmp_path)
    r = parse_recipe({"pointspro": 1, "steps": []})

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(batch, "render_html", boom)
    out = tmp_path / "o"
    out.mkdir()
    oc = batch.process_input(good, r, out, "good")  # the input fails alone, with one line
    assert not oc.ok and oc.error == f"{good}: writing the outputs: {out / 'good' / 'report.html'}: disk full"
    assert "OSError: disk full" in oc.traceback
    assert list(out.iterdir()) == []


def test_steps_command_lists_parameters_with_units(run_cli):
    code, out, _ = run_cli("steps")
    assert code == 0
    assert "aperture — Clear aperture" in out and "diameter [mm]: float" in out
    assert "manual_edit" in out and "transform" in out and "alpha" not in out.split("transform")[0][:0]
    code, _, err = run_cli("steps", "nope")
    assert code == 2 and "unknown step(s) nope" in err
    code, out, _ = run_cli("steps", "--help")  # a usage, not the whole catalogue
    assert code == 0 and out.startswith("usage: pointspro steps") and "aperture —" not in out
    code, _, err = run_cli("steps", "--bogus")
    assert code == 2 and "unknown option --bogus" in err


def test_usage_errors(run_cli):
    code, _, err = run_cli("--batch", "--frobnicate")
    assert code == 2 and "unrecognized arguments" in err


def test_batch_never_starts_qt_and_debug_shows_traceback(tmp_path):
    """In a fresh interpreter: a whole batch runs and PySide6/pyvistaqt were never imported."""
    code = (
        "import sys\n"
        "from pointspro.core.cli import main\n"
        f"rc = main(['--batch', {str(RECIPE)!r}, {str(DATA)!r}, '--out', {str(tmp_path / 'o')!r}, '--quiet'])\n"
        "bad = [m for m in ('PySide6', 'pyvistaqt', 'PyQt5', 'PyQt6', 'open3d', 'pyvista') if m in sys.modules]\n"
        "print(rc, bad)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.stdout.strip() == "0 []", res.stderr
    # --debug: the traceback of a user error is shown
    res = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(RECIPE),
                          str(tmp_path / "none.csv"), "--out", str(tmp_path / "o"), "--debug"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode != 0 and "Traceback" in res.stderr


def test_workers_give_identical_outputs(run_cli, tmp_path):
    """--workers 2 (spawned processes) writes byte-identical clouds and the same report numbers."""
    rng = np.random.default_rng(11)
    files = []
    for k in range(3):
        xyz = rng.uniform(-500, 500, (300, 3))
        p = tmp_path / f"m{k}.csv"
        np.savetxt(p, xyz, delimiter=",", header="x,y,z", comments="", fmt="%.9f")
        files.append(p)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - aperture: {diameter: 800}\n"
                   "  - manual_edit: {remove: [1, 2]}\n")
    assert run_cli("--batch", recipe, *files, "--out", tmp_path / "seq")[0] == 0
    code, out, err = run_cli("--batch", recipe, *files, "--out", tmp_path / "par", "--workers", "2")
    assert code == 0, err
    for k in range(3):
        a = tmp_path / "seq" / f"m{k}"
        b = tmp_path / "par" / f"m{k}"
        assert (a / "cloud.csv").read_bytes() == (b / "cloud.csv").read_bytes()
        ra, rb = json.loads((a / "report.json").read_text(encoding="utf-8")), json.loads((b / "report.json").read_text(encoding="utf-8"))
        assert ra["summary"] == rb["summary"]
        assert [s["report"] for s in ra["steps"]] == [s["report"] for s in rb["steps"]]


@pytest.mark.parametrize("mode", ["summary", "none"])
def test_figures_option_skips_pictures_and_says_which(run_cli, tmp_path, mode):
    """--figures summary draws only form_error.png, none draws no PNG; the numbers and the other
    files are those of a full run, and the report lists what was not drawn."""
    code, _, err = run_cli("--batch", RECIPE, DATA, "--out", tmp_path / "all", "--quiet")
    assert code == 0, err
    code, _, err = run_cli("--batch", RECIPE, DATA, "--out", tmp_path / mode, "--quiet", "--figures", mode)
    assert code == 0, err
    full, part = tmp_path / "all" / "asphere_cmm", tmp_path / mode / "asphere_cmm"
    pngs = {p.name for p in full.glob("*.png")}
    kept = {"form_error.png"} if mode == "summary" else set()
    assert len(pngs) >= 5 and {p.name for p in part.glob("*.png")} == kept
    assert {p.name for p in part.iterdir()} == {p.name for p in full.iterdir()} - (pngs - kept)
    rep = json.loads((part / "report.json").read_text(encoding="utf-8"))
    assert rep["figures"] == {"mode": mode, "skipped": sorted(pngs - kept)}
    assert all(a not in pngs - kept for st in rep["steps"] for a in st["artifacts"])
    assert rep["summary"] == json.loads((full / "report.json").read_text(encoding="utf-8"))["summary"]
    assert _sha(part / "cloud.csv") == _sha(full / "cloud.csv")
    assert "not drawn" in (part / "report.html").read_text(encoding="utf-8")


@pytest.mark.parametrize("extra", [(), ("--check-only",)])
def test_a_step_needing_the_nominal_without_surface_is_the_recipes_error(run_cli, tmp_path, extra):
    """Was: --check-only said "ready", the run failed every input with the step's message."""
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - manual_edit: {}\n  - misalignment: {}\n")
    inp = write(tmp_path / "part.csv", "x,y,z\n1,2,3\n4,5,6\n7,8,10\n")
    code, _, err = run_cli("--batch", recipe, inp, "--out", tmp_path / "o", *extra)
    assert code == 2 and "r.yaml, line 4: step 2 'misalignment' needs the recipe's nominal `surface:`" in err
    assert not (tmp_path / "o").exists()


def test_the_window_without_a_display_says_what_to_do(run_cli, monkeypatch):
    """Qt aborted the process (exit 134) with plugin noise when no display was there."""
    import sys as _sys

    if not _sys.platform.startswith("linux"):
        pytest.skip("the check is for Linux's DISPLAY/WAYLAND_DISPLAY")
    for k in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(k, raising=False)
    code, _, err = run_cli(EXAMPLE / "asphere_cmm.csv")
    assert code == 2 and "no display to open the window on" in err and "xvfb-run" in err
    # --screenshot too (it was let through: Qt's abort, exit 134)
    code, _, err = run_cli("--screenshot", "/tmp/pointspro-never-written.png", EXAMPLE / "asphere_cmm.csv")
    assert code == 2 and "no display to render the window on" in err and "xvfb-run -a" in err


def test_explain_bootstrap_out_of_range(run_cli, tmp_path):
    code, _, err = run_cli("explain", "--model", tmp_path / "m.yaml", "--measured", tmp_path / "x.csv",
                           "--out", tmp_path / "o", "--bootstrap", "-1")
    assert code == 2 and "--bootstrap -1: replicates from 0" in err


def test_the_command_ends_without_teardown_yet_everything_is_written(tmp_path):
    """A finished local batch ends with os._exit (core.cli.exit_now: the interpreter's teardown took
    0.3–0.55 s of a 3 s command): the table on stdout (a pipe here, block-buffered), the summary
    and the outputs are all there, and the exit status is the batch's."""
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z\n1,2\n", encoding="utf-8")
    res = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(RECIPE), str(DATA), str(bad),
                          "--out", str(tmp_path / "o"), "--figures", "none", "--workers", "1"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 1, res.stderr
    assert "asphere_cmm.csv" in res.stdout and "failed" in res.stdout and "bad.csv" in res.stderr
    summary = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert [e["status"] for e in summary["inputs"]] == ["ok", "failed"]
    assert (tmp_path / "o" / "asphere_cmm" / "report.json").is_file()


def test_an_ascii_terminal_gets_its_lines_not_an_internal_error(tmp_path):
    """Under a C/POSIX locale stdout is ASCII: the "ok → folder" line raised UnicodeEncodeError after
    the outputs were written — "internal error", exit 2 (found by CI's LC_ALL=C run)."""
    import os

    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0"}
    env.pop("PYTHONIOENCODING", None)
    res = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(RECIPE), str(DATA),
                          "--out", str(tmp_path / "o"), "--figures", "none"],
                         capture_output=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr.decode("ascii", "replace")
    assert b"asphere_cmm.csv: ok ? " in res.stdout and b"internal error" not in res.stderr


def test_a_full_disk_is_one_line_naming_the_file_not_an_internal_error(tmp_path):
    """A file-size limit (as a full disk: EFBIG/ENOSPC on write) fails each input's outputs and then
    summary.json itself — that was "internal error: OSError … please report it" (a review)."""
    import resource

    def limit():  # 2 KiB a file: the figures and summary.json cannot be written
        resource.setrlimit(resource.RLIMIT_FSIZE, (2048, 2048))

    res = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(RECIPE), str(DATA),
                          "--out", str(tmp_path / "o"), "--workers", "1", "--quiet"],
                         capture_output=True, text=True, timeout=300, preexec_fn=limit)
    assert res.returncode == 2, res.stderr
    assert "internal error" not in res.stderr and "Traceback" not in res.stderr
    assert "summary.json: cannot be written (File too large); 0 of 1 input(s) have their folder complete" \
        in res.stderr
    # the input's line names the file it was writing, where it was going (not the temporary folder)
    assert re.search(r"asphere_cmm.csv: writing the outputs: \S*/o/asphere_cmm/[\w.]+: File too large",
                     res.stderr), res.stderr
    assert not (tmp_path / "o" / "asphere_cmm").exists()  # no half-written folder
    assert [p.name for p in (tmp_path / "o").iterdir()] == []  # nor a temporary one


def test_an_interrupted_batch_whose_summary_cannot_be_written_still_exits_130(run_cli, tmp_path,
                                                                               monkeypatch):
    """An interruption and a full disk at once: summary.json's error turned the exit status into 2
    (a usage error) — the batch was interrupted, and says both (a review's leftover)."""
    import pointspro.core.cli as cli
    import pointspro.core.summary as summary
    from pointspro.core.errors import PointsProError

    def interrupted(runner, report, out, stems):
        return True  # as when Ctrl-C stopped the inputs' run

    def full(out_dir, *a, **k):
        raise PointsProError(f"{out_dir / 'summary.json'}: cannot be written (File too large); 0 of 1 "
                             "input(s) have their folder complete")

    monkeypatch.setattr(cli, "_drain", interrupted)
    monkeypatch.setattr(summary, "write_summary", full)
    code, out, err = run_cli("--batch", RECIPE, DATA, "--out", tmp_path / "o", "--workers", "1", "--quiet")
    assert code == 130, err
    assert "summary.json: cannot be written (File too large)" in err
    assert "pointspro: interrupted — 0 of 1 inputs complete" in err
