"""A bad-input review's findings: a Monte Carlo stopped by SIGTERM printed its workers' tracebacks;
a model's negative seed was refused in numpy's words; a surface took text for numbers; explain took
measurement models that simulate refuses."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import EXAMPLE, write

SURFACE = "{type: even_asphere, c: 3.3333333333333335e-4, k: -0.98, A: {4: 7.0e-13, 6: 1.0e-19}, aperture: 1300}"


# -- 1. SIGTERM during the Monte Carlo: the closing line, no worker's traceback -------------------------

def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                fields = f.read().rsplit(b")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if int(fields[1]) == pid:
            out.append(int(entry))
    return out


def _cpu_seconds(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="finds the pool's workers in /proc")
def test_sigterm_during_the_monte_carlo_prints_no_traceback(tmp_path):
    """`w/r2/term.sh`: the Monte Carlo's pool workers are forked from the batch, whose SIGTERM handler
    raises KeyboardInterrupt; the pool's terminate() sends them SIGTERM, and each printed "Process
    ForkPoolWorker-1: Traceback … KeyboardInterrupt" before the batch's closing line."""
    recipe = write(tmp_path / "unc.yaml", f"pointspro: 1\nsurface: {SURFACE}\nsteps:\n"
                   "  - misalignment: {}\n  - zernike: {terms: 15}\n"
                   "uncertainty: {samples: 100000, seed: 1, noise: 50 nm, workers: 2}\n")
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(EXAMPLE / "asphere_cmm.csv"),
           "--out", str(out), "--workers", "1", "--quiet", "--figures", "none"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # the Monte Carlo is under way once two forked workers have run samples for a while (their
        # initializer long done); 100,000 samples do not end before that on any machine
        deadline = time.monotonic() + 240
        running = False
        while time.monotonic() < deadline and proc.poll() is None:
            workers = _children(proc.pid)
            if len(workers) >= 2 and sum(_cpu_seconds(w) > 0.3 for w in workers) >= 2:
                running = True
                break
            time.sleep(0.1)
        assert running, proc.communicate(timeout=60) if proc.poll() is not None else "no Monte Carlo workers"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err and "ForkPoolWorker" not in err, err
    last = err.strip().splitlines()[-1]  # under LC_ALL=C the dash is written as "?"
    assert last.startswith("pointspro: interrupted") and "0 of 1 inputs complete" in last, err
    assert not list(out.glob(".*")) and not [p for p in out.iterdir() if p.is_dir()]  # nothing partial


# -- 2. a model's seed ------------------------------------------------------------------------------------

def _model(tmp_path, name: str, scan: str = "{type: spiral, radius: 20.0, rpm: 60.0, pitch: 0.4, fs: 400.0}",
           seed: str = "2") -> Path:
    return write(tmp_path / name, "pointspro_model: 1\n"
                 "surface: {type: even_asphere, R: 200.0, k: -0.5, aperture: 50.0}\n"
                 f"scan: {scan}\nprobe: {{noise: 2.0e-6}}\nseed: {seed}\neffects: []\n")


def _one_line(err: str) -> str:
    assert "Traceback" not in err and "internal error" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("seed", ["-1", '"3"', "1_000", "true"])
def test_a_model_seed_is_a_non_negative_integer(tmp_path, run_cli, seed):
    """seed: -1 was "…: expected non-negative integer" (numpy's words, no key); `seed: "3"` and
    `seed: 1_000` (a word in YAML 1.2) were read as numbers, `seed: true` as 1."""
    model = _model(tmp_path, "m.yaml", seed=seed)
    code, _, err = run_cli("simulate", model, "--out", tmp_path / "s.csv")
    line = _one_line(err)
    assert code == 2 and "m.yaml, line 5" in line and "key 'seed'" in line, err
    assert not (tmp_path / "s.csv").exists()


def test_a_model_scan_and_probe_take_numbers_not_text(tmp_path, run_cli):
    """`radius: "20.0"` and `fs: 4_00` were read as numbers, `radius: true` as 1 mm."""
    model = _model(tmp_path, "m.yaml", scan='{type: spiral, radius: "20.0", rpm: 60.0, pitch: 0.4, fs: 4_00}')
    code, _, err = run_cli("simulate", model, "--out", tmp_path / "s.csv")
    line = _one_line(err)
    assert code == 2 and "m.yaml, line 3" in line and "'scan.radius'" in line and "not text" in line, err
    model.write_text(model.read_text(encoding="utf-8").replace("radius: \"20.0\"", "radius: 20.0"), encoding="utf-8")
    code, _, err = run_cli("simulate", model, "--out", tmp_path / "s.csv")
    assert code == 2 and "'scan.fs'" in _one_line(err) and "'4_00'" in err, err
    model = _model(tmp_path, "b.yaml", scan="{type: spiral, radius: true, rpm: 60.0, pitch: 0.4, fs: 400.0}")
    code, _, err = run_cli("simulate", model, "--out", tmp_path / "s.csv")  # was a 1 mm scan
    assert code == 2 and "'scan.radius': should be a number (got true)" in _one_line(err), err
    model = write(tmp_path / "p.yaml", _model(tmp_path, "p.yaml").read_text(encoding="utf-8")
                  .replace("noise: 2.0e-6", "noise: \"2.0e-6\""))
    code, _, err = run_cli("simulate", model, "--out", tmp_path / "s.csv")
    assert code == 2 and "'probe.noise'" in _one_line(err) and "not text" in err, err
    assert not (tmp_path / "s.csv").exists()


# -- 3. a surface's numbers are numbers, as a step's are ----------------------------------------------------

@pytest.mark.parametrize("surface,key,got", [
    (SURFACE.replace("aperture: 1300", "aperture: 1_300"), "aperture", "'1_300'"),
    (SURFACE.replace("c: 3.3333333333333335e-4", 'c: "3.33e-4"'), "c", "'3.33e-4'"),
    (SURFACE.replace("k: -0.98", 'k: "-0.98"'), "k", "'-0.98'"),
    (SURFACE.replace("A: {4: 7.0e-13", 'A: {4: "7.0e-13"'), "A.4", "'7.0e-13'"),
    ("{type: qcon, R: 500, k: -1, norm_radius: 50, a: [1e-4, \"-2e-5\"]}", "a", "item 2: Input should be a number, not text"),
    ("{type: xy_polynomial, norm_radius: 50, terms: {x2y0: 1_0}}", "terms.x2y0", "'1_0'"),
])
def test_a_surface_takes_numbers_not_text(tmp_path, run_cli, surface, key, got):
    """`aperture: 1_300` and `c: "3.33e-4"` ran (rc 0) where a step's `diameter: 1_290` is refused."""
    recipe = write(tmp_path / "r.yaml", f"pointspro: 1\nsurface: {surface}\nsteps:\n  - misalignment: {{}}\n")
    code, _, err = run_cli("--batch", recipe, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o", "--quiet")
    line = _one_line(err)
    assert code == 2 and "r.yaml, line 2" in line and f"key '{key}'" in line, err
    assert "not text" in line and got in line, err
    assert not (tmp_path / "o").exists()


def test_a_surface_still_takes_its_numbers_and_text_keys(tmp_path):
    from pointspro.core.surfaces.spec import parse_surface_spec

    s = parse_surface_spec({"type": "even_asphere", "c": 3e-4, "k": -1, "A": {"4": 1e-13, 6: 0}, "aperture": 10})
    assert s.A == {4: 1e-13, 6: 0.0} and s.aperture == 10.0
    assert parse_surface_spec({"type": "xy_polynomial", "terms": {"x2y0": 1}}).terms == {"x2y0": 1.0}


# -- 4. explain refuses the models simulate refuses ---------------------------------------------------------

MODELS = {
    "radbig": ("{type: spiral, radius: 2000, rpm: 60.0, pitch: 0.4, fs: 400.0}", "2",
               "lie outside the conic's domain"),
    "pitchtiny": ("{type: spiral, radius: 20.0, rpm: 60.0, pitch: 1e-9, fs: 400.0}", "2",
                  "the spiral has 8000000000000 samples"),
    "seedneg": ("{type: spiral, radius: 20.0, rpm: 60.0, pitch: 0.4, fs: 400.0}", "-1", "key 'seed'"),
    "fiducials": ("{type: fiducials, radius: 20.0}", "2", "a fiducial scan needs `centers`"),
}


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A measurement of the example spiral model (simulated once)."""
    from pointspro.core.cli import main

    folder = tmp_path_factory.mktemp("meas")
    assert main(["simulate", str(EXAMPLE / "spiral_model.yaml"), "--out", str(folder / "meas.csv")]) == 0
    return folder / "meas.csv"


@pytest.mark.parametrize("name", sorted(MODELS))
def test_explain_refuses_the_models_simulate_refuses(tmp_path, run_cli, measured, name):
    """w/ex/mm/radbig.yaml, pitchtiny.yaml, seedneg.yaml: simulate refused them, explain ran (rc 0) and
    wrote a model.updated.yaml that would not simulate — it evaluates the model at the measured points
    and never built the model's own scan."""
    scan, seed, words = MODELS[name]
    model = _model(tmp_path, f"{name}.yaml", scan=scan, seed=seed)
    code, _, err_sim = run_cli("simulate", model, "--out", tmp_path / "s.csv")
    line = _one_line(err_sim)
    assert code == 2 and words in line, err_sim
    code, _, err = run_cli("explain", "--model", model, "--measured", measured, "--out", tmp_path / "e")
    assert code == 2 and _one_line(err) == line, (err, err_sim)
    assert not (tmp_path / "e").exists() and not (tmp_path / "s.csv").exists()


# --- a step's parameter file is checked before any input runs ------------------------------------
@pytest.mark.parametrize("step,value,says", [
    ("volumetric: {model: missing.json}", "missing.json", "file not found"),
    ("kinematic: {map: gone/kinematic_map.json}", "kinematic_map.json", "file not found"),
    ("dynamic: {model: dynamic_model.json}", "dynamic_model.json", "file not found"),
    ("volumetric: {model: sub}", "sub", "a folder, not a file"),
    ("volumetric: {model: \"\"}", "parameter 'model' is empty", "give a file name"),
])
def test_a_missing_parameter_file_is_refused_before_any_input(tmp_path, run_cli, step, value, says):
    """A review: a missing `dynamic.model` or `kinematic.map` was reported at run time, on each input,
    behind "the scan has no t channel"; `volumetric: {model: ""}` read as the folder "." ("file not
    found"). The README says the whole recipe is validated before anything runs: one line naming the
    step and the parameter, and no output folder written."""
    import shutil

    (tmp_path / "sub").mkdir()
    data = tmp_path / "asphere_cmm.csv"
    shutil.copy(EXAMPLE / "asphere_cmm.csv", data)
    recipe = tmp_path / "r.yaml"
    recipe.write_text(f"pointspro: 1\nsteps:\n  - {step}\n", encoding="utf-8")
    out = tmp_path / "out"
    code, _, err = run_cli("--batch", recipe, data, "--out", out)
    assert code == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "r.yaml" in lines[0] and "line 3" in lines[0] and value in lines[0] and says in lines[0], lines[0]
    assert not out.exists()


@pytest.mark.parametrize("header,refused", [
    ("x [µm],y [µm],z", True), ("x [um],y,z [um]", True), ("x,y,z [nm]", True),
    ("x [mm],y [mm],z", False), ("x,y,z", False), ("x [µm],y [µm],z [µm]", False),
])
def test_a_coordinate_without_its_unit_beside_others_in_another_unit_is_refused(tmp_path, header, refused):
    """A review: `x [µm],y [µm],z` read z in mm without a word — 1000× off if the writer meant µm for
    all three. A coordinate without a unit beside one stated in another length is refused, naming
    both; beside mm (the default) it is read as mm."""
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud

    f = write(tmp_path / "p.csv", header + "\n" + "\n".join(f"{i},{i % 7},{i % 3}" for i in range(30)) + "\n")
    if refused:
        with pytest.raises(InputError, match=r"line 1: .* no unit .*read as mm"):
            read_cloud(f)
    else:
        c = read_cloud(f)
        assert c.n == 30


def test_a_model_whose_effect_overflows_is_refused_not_written(tmp_path, run_cli):
    """`volumetric: {cxx: 1.0e+308}` wrote 20,000 heights of inf with exit 0 and numpy's overflow
    warning on stderr (a review): refused in one line naming the model, the effect and its value."""
    m = tmp_path / "m.yaml"
    m.write_text("pointspro_model: 1\nsurface: {type: even_asphere, R: 200.0, k: -0.5, aperture: 50.0}\n"
                 "scan: {type: spiral, radius: 20.0, rpm: 60.0, pitch: 0.4, fs: 400.0}\n"
                 "effects: [volumetric: {cxx: 1.0e+308}]\n", encoding="utf-8")
    code, _, err = run_cli("simulate", m, "--out", tmp_path / "x.csv")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Warning" not in err, err
    assert f"{m}: effect 1 'volumetric': its parameters give heights beyond any number (cxx 1e+308)" in err
    assert not (tmp_path / "x.csv").exists()


def test_an_effect_in_the_wrong_unit_is_warned_of(tmp_path, run_cli):
    """`vibration: {amplitude: 8}` — 8 mm, meant as 8 nm — simulated with exit 0 and no word (a review):
    now a warning names the effect and how much it moves the heights against the part's sag; a model of
    nm-sized effects says nothing."""
    head = ("pointspro_model: 1\nsurface: {type: even_asphere, R: 200.0, k: -0.5, aperture: 50.0}\n"
            "scan: {type: spiral, radius: 20.0, rpm: 60.0, pitch: 0.4, fs: 400.0}\n")
    m = tmp_path / "m.yaml"
    m.write_text(head + "effects: [pose: {dz: 0.5}, vibration: {frequency_hz: 61, amplitude: 8}]\n", encoding="utf-8")
    code, out, err = run_cli("simulate", m, "--out", tmp_path / "x.csv")
    assert code == 0 and (tmp_path / "x.csv").is_file()
    assert f"{m}: warning: effect 2 'vibration' changes the heights by 5.66 mm RMS" in err, err
    assert "pose" not in err  # a part may sit far off
    m.write_text(head + "effects: [vibration: {frequency_hz: 61, amplitude: 8.0e-6}]\n", encoding="utf-8")
    code, out, err = run_cli("simulate", m, "--out", tmp_path / "y.csv")
    assert code == 0 and "warning" not in err, err
