"""Issue 25: a batch on a real Dask cluster, started as the README tells users to start one — a
`dask scheduler` and two `dask worker` processes on loopback (free ports), each its own process group,
every one stopped by its id at the end. Relative paths typed in another working directory, byte for
byte the outputs of a local run; the pre-flight (--check-only, a missing step, another version, an
output folder the workers cannot write); --ship; a worker killed mid-run; Ctrl-C then --resume; a
scheduler that does not answer."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from .conftest import write

DASK = Path(sys.executable).parent / "dask"
pytestmark = pytest.mark.skipif(not DASK.exists(), reason="the `dask` command is not installed")

RECIPE = """pointspro: 1
surface: {type: even_asphere, c: 1.0e-3, k: 0, aperture: 200}
inputs: {fiducials: ../calib/fid.csv}
steps:
  - misalignment: {dof: [dx, dy, dz]}
  - knn_denoise: {window: 60.0}
  - aperture: {diameter: 150}
"""
#: the recipe names ../calib/fid.csv: a folder the user allows (relative too: it travels resolved)
ALLOW = ("--allow-path", "calib")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(procs) -> None:
    """Every process started, by its process group (a worker's nanny and its worker die together)."""
    for p in procs:
        if p.poll() is None:
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=10)


@pytest.fixture(scope="module")
def real_cluster(tmp_path_factory):
    """`dask scheduler` + 2 × `dask worker --nworkers 1 --nthreads 1`, started in a folder of their
    own (a path sent as typed would be looked for there, and not found)."""
    from distributed import Client

    home = tmp_path_factory.mktemp("dask-home")
    address = f"tcp://127.0.0.1:{_free_port()}"
    procs = []
    log = open(home / "dask.log", "ab")  # noqa: SIM115 — closed in the finally below

    def start(*args):
        p = subprocess.Popen([str(DASK), *args], cwd=home, stdout=log, stderr=subprocess.STDOUT,
                             stdin=subprocess.DEVNULL, start_new_session=True)
        procs.append(p)
        return p

    def add_worker():
        return start("worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                     "--host", "127.0.0.1", "--local-directory", str(home))

    try:
        start("scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1], "--no-dashboard")
        workers = [add_worker(), add_worker()]
        with Client(address, timeout="60s") as c:
            c.wait_for_workers(2, timeout=90)
        yield SimpleNamespace(address=address, workers=workers, add_worker=add_worker, home=home)
    finally:
        _stop(procs)
        log.close()


def _data(root: Path, n: int = 4, side: int = 7) -> Path:
    """A working folder as a user has it: in/*.csv, recipes/r.yaml naming ../calib/fid.csv. Rasters
    of side + k points a side (small: a few tenths of a second each)."""
    for k in range(n):
        rng = np.random.default_rng(100 + k)
        g = np.linspace(-100, 100, side + k)  # a raster: inputs of different sizes
        x, y = (a.ravel() for a in np.meshgrid(g, g))
        r2 = x * x + y * y
        z = 1e-3 * r2 / (1 + np.sqrt(1 - 1e-6 * r2)) + 1e-5 * x + rng.normal(0, 2e-4, x.size)
        (root / "in").mkdir(parents=True, exist_ok=True)
        np.savetxt(root / "in" / f"p{k}.csv", np.column_stack([x, y, z]), fmt="%.9f", delimiter=",",
                   header="x,y,z", comments="")
    for d in ("calib", "recipes"):
        (root / d).mkdir(exist_ok=True)
    write(root / "calib" / "fid.csv", "fiducial,x,y,z\nA,0,0,0\n")
    write(root / "recipes" / "r.yaml", RECIPE)
    return root


def _normalised(folder: Path) -> dict:
    """Every file of an output folder; the report's time of writing and seconds blanked."""
    out = {}
    for p in sorted(folder.iterdir()):
        data = p.read_bytes()
        if p.name in ("report.json", "report.html"):
            text = data.decode("utf-8")
            text = re.sub(r'"created": "[^"]*"', '"created": ""', text)
            text = re.sub(r'"seconds": [0-9.e-]+', '"seconds": 0', text)
            text = re.sub(r"\d+-\d+-\d+T\d\d:\d\d:\d\d\+00:00", "", text)
            text = re.sub(r"[0-9.]+ s ·", "s ·", text)
            data = text.encode("utf-8")
        out[p.name] = data
    return out


def _inputs(work: Path) -> list[str]:
    return sorted(str(p.relative_to(work)) for p in (work / "in").glob("*.csv"))


def _same_as_local(work: Path, local: str, other: str) -> None:
    for name in _inputs(work):
        stem = Path(name).stem
        ref = _normalised(work / local / stem)
        assert set(ref) >= {"cloud.csv", "report.json", "report.html"}
        assert _normalised(work / other / stem) == ref, stem
        assert b"pointspro-recipe-" not in (work / other / stem / "report.json").read_bytes()


def test_relative_paths_from_another_folder_match_a_local_run(real_cluster, run_cli, tmp_path, monkeypatch):
    work = _data(tmp_path / "data")
    monkeypatch.chdir(work)  # the workers run in another folder: relative paths must travel
    files = _inputs(work)
    opts = ["--figures", "none", "--set", "knn_denoise.window=50"]
    code, _, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "local", "--workers", "1",
                           "--quiet", *opts)
    assert code == 0, err
    code, out, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "cl",
                             "--scheduler", real_cluster.address, *opts)
    assert code == 0, err
    assert "in/p0.csv: ok → cl/p0" in out  # named as typed, as a local run names them
    _same_as_local(work, "local", "cl")
    rep = json.loads((work / "cl" / "p0" / "report.json").read_text(encoding="utf-8"))
    assert rep["input"] == "in/p0.csv" and rep["overrides"] == ["knn_denoise.window=50"]
    assert rep["recipe"]["inputs"] == {"fiducials": "recipes/../calib/fid.csv"}
    s = json.loads((work / "cl" / "summary.json").read_text(encoding="utf-8"))
    assert s["counts"] == {"ok": len(files)} and s["scheduler"] == real_cluster.address
    assert not list((work / "cl").glob(".*"))
    # --resume on the cluster skips what is complete with the same recipe and --set
    code, _, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "cl", "--scheduler",
                           real_cluster.address, "--resume", "--quiet", *opts)
    assert code == 0, err
    s = json.loads((work / "cl" / "summary.json").read_text(encoding="utf-8"))
    assert s["counts"] == {"skipped": len(files)}


def test_ship_sends_inputs_and_writes_outputs_here(real_cluster, run_cli, tmp_path, monkeypatch):
    work = _data(tmp_path / "data", n=3)
    monkeypatch.chdir(work)
    files = _inputs(work)
    assert run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "local", "--workers", "1", "--quiet")[0] == 0
    code, out, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "shipped", "--scheduler",
                             real_cluster.address, "--ship", "--quiet")
    assert code == 0, err
    _same_as_local(work, "local", "shipped")
    assert not list((work / "shipped").glob(".*"))
    # an input larger than --ship sends: one line, before anything runs
    from pointspro.core import cluster

    monkeypatch.setattr(cluster, "SHIP_LIMIT", 1000)
    code, out, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "big", "--scheduler",
                             real_cluster.address, "--ship")
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert re.search(r"in/p\d\.csv: .* KiB is more than --ship sends \(1000 bytes per input\)", err)
    assert not [p for p in (work / "big").iterdir()] if (work / "big").exists() else True


def test_a_shipped_input_needs_no_file_on_the_worker(tmp_path):
    """The worker side of --ship, in this process: the input exists only as bytes, the outputs come
    back as {name: bytes}; nothing is left in the worker's temporary folders."""
    from pointspro.core import cluster
    from pointspro.core.recipe import load_recipe

    work = _data(tmp_path / "data", n=1)
    bundle = cluster.recipe_bundle(work / "recipes" / "r.yaml", load_recipe(work / "recipes" / "r.yaml"))
    assert set(bundle["files"]) == {"calib/fid.csv"} and bundle["name"] == "recipes/r.yaml"
    data = (work / "in" / "p0.csv").read_bytes()
    oc, files = cluster.cluster_job(bundle, "p0.csv", "in/p0.csv", str(tmp_path / "nowhere"), "p0", None,
                                    "none", {}, data)
    assert oc.ok, oc.error
    assert {"cloud.csv", "report.json", "report.html"} <= set(files)
    assert json.loads(files["report.json"])["input"] == "in/p0.csv"
    assert not (tmp_path / "nowhere").exists()
    # a corrupt input's message names it as typed, never the worker's temporary copy
    oc, files = cluster.cluster_job(bundle, "p0.csv", "in/p0.csv", str(tmp_path / "nowhere"), "p0", None,
                                    "none", {}, data.replace(b"\n-", b"\n8x", 1))
    assert not oc.ok and files is None
    assert oc.error.startswith("in/p0.csv") and "pointspro-input-" not in oc.error, oc.error


def test_check_only_and_problems_on_the_workers(real_cluster, run_cli, tmp_path, monkeypatch):
    work = _data(tmp_path / "data", n=2)
    monkeypatch.chdir(work)
    files = _inputs(work)
    code, out, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "o", "--scheduler",
                             real_cluster.address, "--check-only")
    assert code == 0, err
    assert "ready on 2 worker(s)" in out and not (work / "o").exists()  # nothing left behind
    # another PointsPro version here than there: one line per worker, nothing run
    import pointspro.core as core

    monkeypatch.setattr(core, "__version__", "9.9.9")
    code, out, err = run_cli("--batch", "recipes/r.yaml", *files, *ALLOW, "--out", "o", "--scheduler",
                             real_cluster.address)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 2, err
    assert all(re.match(r"pointspro: worker tcp://127\.0\.0\.1:\d+: PointsPro \S+ is installed there, "
                        r"9\.9\.9 here", line) for line in lines), err
    assert not (work / "o").exists()
    monkeypatch.undo()


def test_preflight_names_the_worker_and_the_problem(real_cluster, tmp_path):
    """A step installed here only, an output folder and inputs the workers cannot reach."""
    from distributed import Client

    from pointspro.core import __version__, cluster

    expect = {"version": __version__, "ids": ["buggy", "aperture"], "ship": False,
              "steps": {"buggy": "buggy-step 0.1", **cluster.step_versions(["aperture"])},
              "inputs": [str(tmp_path / "gone" / "a.csv"), str(tmp_path / "b.csv")],
              "out": str(tmp_path / "no" / "out"), "absolute": [str(tmp_path / "calib.csv")]}
    with Client(real_cluster.address, timeout="30s") as c:
        lines = cluster.check_workers(c, expect)
    assert len(lines) == 2 * 5, lines
    for what in ("step 'buggy' is not installed there (buggy-step 0.1 here)",
                 f"cannot read the input folder {tmp_path / 'gone'}",
                 f"cannot read the input {tmp_path / 'b.csv'}",
                 f"cannot write the output folder {tmp_path / 'no' / 'out'} (no such folder)",
                 f"cannot read {tmp_path / 'calib.csv'}, which the recipe names"):
        hits = [line for line in lines if line.endswith(what)]
        assert len(hits) == 2 and all(re.match(r"worker tcp://127\.0\.0\.1:\d+: ", h) for h in hits), (what, lines)


def test_unreachable_scheduler_is_one_line(run_cli, tmp_path):
    work = _data(tmp_path / "data", n=1)
    address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    code, out, err = run_cli("--batch", work / "recipes" / "r.yaml", work / "in" / "p0.csv", "--out",
                             tmp_path / "o", "--scheduler", address, "--allow-path", work / "calib")
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"pointspro: --scheduler {address}: no Dask scheduler answers there")


def _batch_cmd(work: Path, address: str, out: str) -> list[str]:
    return [sys.executable, "-m", "pointspro.core.cli", "--batch", "recipes/r.yaml", *_inputs(work), *ALLOW,
            "--out", out, "--scheduler", address, "--figures", "none", "--quiet"]


def _wait_first_output(proc, out: Path) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and not (
            out.exists() and any(p.is_dir() and not p.name.startswith(".") for p in out.iterdir())):
        time.sleep(0.02)
    assert proc.poll() is None, "the batch ended before it could be stopped in the middle"


def test_a_worker_killed_mid_run_the_batch_still_completes(real_cluster, tmp_path):
    """A third worker joins, and is killed (its whole process group, SIGKILL) once the first input
    is written: Dask runs its inputs again on the others; every output is complete."""
    from distributed import Client

    work = _data(tmp_path / "data", n=10, side=16)
    extra = real_cluster.add_worker()
    with Client(real_cluster.address, timeout="30s") as c:
        c.wait_for_workers(3, timeout=90)
    proc = subprocess.Popen(_batch_cmd(work, real_cluster.address, "o"), cwd=work, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _wait_first_output(proc, work / "o")
        os.killpg(extra.pid, signal.SIGKILL)
        extra.wait(timeout=10)
        _, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    s = json.loads((work / "o" / "summary.json").read_text(encoding="utf-8"))
    assert s["counts"] == {"ok": 10}
    assert not list((work / "o").glob(".*"))  # the killed worker's temporary folder is removed
    for name in _inputs(work):
        assert {"cloud.csv", "report.json"} <= {q.name for q in (work / "o" / Path(name).stem).iterdir()}


def test_ctrl_c_on_the_cluster_then_resume(real_cluster, tmp_path):
    work = _data(tmp_path / "data", n=8, side=16)
    cmd = _batch_cmd(work, real_cluster.address, "o")
    proc = subprocess.Popen(cmd, cwd=work, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _wait_first_output(proc, work / "o")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "run the same command with --resume" in err and "Traceback" not in err, err
    out = work / "o"
    assert not list(out.glob(".*")), list(out.glob(".*"))
    done = [p for p in out.iterdir() if p.is_dir()]
    assert 1 <= len(done) < 8
    for d in done:
        assert {"cloud.csv", "report.json", "report.html"} <= {q.name for q in d.iterdir()}
    res = subprocess.run(cmd + ["--resume"], cwd=work, capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stderr
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert s["counts"].get("ok", 0) + s["counts"].get("skipped", 0) == 8
    assert s["counts"].get("skipped", 0) >= len(done)


def test_check_only_without_a_cluster_checks_this_machine(run_cli, tmp_path, monkeypatch):
    work = _data(tmp_path / "data", n=2)
    monkeypatch.chdir(work)
    code, out, err = run_cli("--batch", "recipes/r.yaml", *_inputs(work), *ALLOW, "--out", "o", "--check-only")
    assert code == 0 and "ready on this machine" in out, err
    assert not (work / "o").exists()  # nothing ran, no folder left
    code, out, err = run_cli("--batch", "recipes/r.yaml", "in/p0.csv", "in/gone.csv", *ALLOW, "--out", "o",
                             "--check-only")
    assert code == 2 and err.strip().splitlines() == [
        f"pointspro: this machine: cannot read the input {work / 'in' / 'gone.csv'}"], err
    code, out, err = run_cli("--batch", "recipes/r.yaml", "in/p0.csv", "--out", "o", "--ship")
    assert code == 2 and "--ship goes with --scheduler" in err


def test_dask_internal_callback_errors_are_not_shown(real_cluster, caplog):
    """distributed logs its own callbacks' exceptions on tornado's "application" logger with their
    traceback (a Ctrl-C raced its sync() and printed a NameError above the "interrupted" line): quiet
    while the batch is connected (shown with -vv), its level restored afterwards."""
    import logging

    from pointspro.core.executors import DaskSession

    app = logging.getLogger("tornado.application")
    before = app.level
    session = DaskSession(real_cluster.address)
    try:
        with caplog.at_level(logging.DEBUG):
            app.error("Exception in callback", exc_info=(NameError, NameError("future"), None))
        assert not [r for r in caplog.records if r.name == "tornado.application"]
    finally:
        session.close()
    assert app.level == before
