"""A review of the batch: two batches sharing one --out (the second deleted the first's temporary
folder and overwrote its summary.json), a SIGTERM in a batch's first moments (exit −15, the previous
summary.json left as if current), and --resume with the inputs named otherwise (a relative run, then
an absolute one, ran every input again)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from .conftest import EXAMPLE, write

RECIPE = EXAMPLE / "recipe.yaml"
LIGHT = "pointspro: 1\nsteps:\n  - knn_denoise: {window: 15.0}\n  - aperture: {diameter: 560}\n"


def _inputs(folder: Path, *names: str) -> list[Path]:
    src = (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8")
    folder.mkdir(parents=True, exist_ok=True)
    return [write(folder / f"{n}.csv", src) for n in names]


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))


def _script(tmp_path: Path, body: str, *argv) -> subprocess.Popen:
    """``pointspro`` (core.cli.main) in a child process, after ``body`` has patched it."""
    code = "import os, signal, sys\nfrom pointspro.core import cli\n" + textwrap.dedent(body) + \
        "\nsys.exit(cli.main(sys.argv[1:]))\n"
    return subprocess.Popen([sys.executable, "-c", code, *map(str, argv)], cwd=tmp_path, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


# -- 1. one live batch per output folder -------------------------------------------------------------

#: a batch that stops, holding its output folder, when its inputs are about to run, until its
#: stdin gives a line (it says "running" first): the night batch in the middle of its inputs
_HELD = """
real = cli._choose_runner
def held(*a, **k):
    print("running", flush=True)
    sys.stdin.readline()
    return real(*a, **k)
cli._choose_runner = held
"""


@pytest.fixture
def live_batch(tmp_path):
    """A batch of a.csv into tmp_path/o, live (see _HELD), with its temporary folder there; yields
    (out, the temporary folder, the process); let go and ended (exit 0) on the way out."""
    recipe = write(tmp_path / "light.yaml", LIGHT)
    a, = _inputs(tmp_path / "in", "a")
    out = tmp_path / "o"
    proc = _script(tmp_path, _HELD, "--batch", recipe, a, "--out", out, "--workers", "1", "--quiet")
    assert proc.stdout.readline() == "running\n", proc.communicate()
    partial = out / ".a.0a1b2c3d.partial"  # what it writes into meanwhile
    partial.mkdir()
    yield out, partial, proc
    partial.rmdir()
    _, err = proc.communicate("go\n", timeout=120)
    assert proc.returncode == 0, err


def test_a_second_batch_on_a_live_output_folder_is_refused(live_batch, run_cli, tmp_path):
    """`--resume` of other inputs while the night batch still ran deleted its temporary folder (that
    input failed, "….partial/zernike_removed.png No such file or directory") and the last to end
    overwrote the other's summary.json: now one line naming the folder, exit 2, nothing touched."""
    out, partial, proc = live_batch
    b, = _inputs(tmp_path / "in", "b")
    before = sorted(p.name for p in out.iterdir())
    code, _, err = run_cli("--batch", RECIPE, b, "--out", out, "--resume", "--quiet", "--figures", "none")
    assert code == 2, err
    assert err.strip() == (f"pointspro: {out}: another batch is writing this output folder (process "
                           f"{proc.pid}); wait for it to end or choose another --out")
    assert partial.is_dir() and sorted(p.name for p in out.iterdir()) == before
    # without --resume alike
    assert run_cli("--batch", RECIPE, b, "--out", out, "--quiet", "--figures", "none")[0] == 2
    assert not (out / "b").exists() and not (out / "summary.json").exists()


def test_check_only_reports_a_live_batch_and_creates_nothing(live_batch, run_cli, tmp_path):
    out, _, proc = live_batch
    b, = _inputs(tmp_path / "in", "b")
    before = sorted(p.name for p in out.iterdir())
    code, _, err = run_cli("--batch", RECIPE, b, "--out", out, "--check-only")
    assert code == 2
    assert err.strip() == f"pointspro: {out}: another batch is writing this output folder (process {proc.pid})"
    assert sorted(p.name for p in out.iterdir()) == before


def test_the_output_folder_is_free_again_after_any_end(run_cli, tmp_path, monkeypatch):
    """The lock goes with the batch however it ends — done, an input failed, an internal error,
    interrupted — and its file too; one a killed batch left (the system released its lock) blocks
    nothing. Two workers: only the batch's own process holds it."""
    from pointspro.core import cli
    from pointspro.core.batch import LOCK_FILE, lock_output_folder

    recipe = write(tmp_path / "light.yaml", LIGHT)
    a, b = _inputs(tmp_path / "in", "a", "b")
    bad = write(tmp_path / "in" / "bad.csv", "x,y,z\n1,2\n")
    out = tmp_path / "o"

    def free():
        assert not (out / LOCK_FILE).exists()
        lock_output_folder(out).release()

    assert run_cli("--batch", recipe, a, b, "--out", out, "--workers", "2", "--quiet")[0] == 0
    free()
    assert run_cli("--batch", recipe, bad, "--out", out, "--quiet")[0] == 2
    free()
    write(out / LOCK_FILE, "999999999\n")  # left by a batch killed with SIGKILL
    assert run_cli("--batch", recipe, a, "--out", out, "--quiet", "--resume")[0] == 0
    free()
    real = cli._choose_runner

    def boom(*args, **kw):
        raise RuntimeError("a bug")

    monkeypatch.setattr(cli, "_choose_runner", boom)
    code, _, err = run_cli("--batch", recipe, a, "--out", out, "--quiet")
    assert code == 2 and "internal error: RuntimeError: a bug" in err
    free()

    def ctrl_c(*args, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_choose_runner", ctrl_c)
    code, _, err = run_cli("--batch", recipe, a, b, "--out", out, "--quiet")
    assert code == 130 and "interrupted — 0 of 2 inputs complete" in err
    assert [e["status"] for e in _summary(out)["inputs"]] == ["not run", "not run"]
    free()
    monkeypatch.setattr(cli, "_choose_runner", real)
    # --check-only leaves no lock file either, nor a folder it made
    assert run_cli("--batch", recipe, a, "--out", tmp_path / "new", "--check-only")[0] == 0
    assert not (tmp_path / "new").exists()


def test_a_forked_child_left_behind_does_not_hold_the_folder(tmp_path):
    """A batch killed with SIGKILL while a process it forked (a writer, a Monte Carlo worker) still
    runs: the child never held the lock, so the next batch is not refused; while the batch lived,
    the child's closing its copy left the lock held."""
    from pointspro.core.batch import lock_output_folder
    from pointspro.core.errors import RecipeError

    out = tmp_path / "o"
    out.mkdir()
    code = textwrap.dedent("""
        import os, signal, sys
        from pathlib import Path
        from pointspro.core.batch import lock_output_folder
        lock = lock_output_folder(Path(sys.argv[1]))
        if os.fork() == 0:  # a child busy until the test lets it go
            os.read(int(sys.argv[2]), 1)
            os._exit(0)
        print("forked", flush=True)
        sys.stdin.readline()
        os.kill(os.getpid(), signal.SIGKILL)
        """)
    r, w = os.pipe()
    proc = subprocess.Popen([sys.executable, "-c", code, str(out), str(r)], pass_fds=(r,), text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    os.close(r)
    try:
        assert proc.stdout.readline() == "forked\n"
        with pytest.raises(RecipeError, match=f"another batch is writing this output folder \\(process {proc.pid}\\)"):
            lock_output_folder(out)
        proc.stdin.write("\n")
        proc.stdin.flush()
        assert proc.wait(timeout=60) == -signal.SIGKILL
        lock_output_folder(out).release()  # the child still runs, and holds nothing
    finally:
        os.write(w, b"x")
        os.close(w)
        proc.stdout.close()
        proc.stdin.close()


def test_resume_removes_the_leftovers_of_its_own_inputs_alone(run_cli, tmp_path):
    """What a killed run left is removed for the batch's own inputs (and its summary.json), never
    another input's: a batch of other inputs may be writing there (a review)."""
    recipe = write(tmp_path / "light.yaml", LIGHT)
    a, = _inputs(tmp_path / "in", "a")
    out = tmp_path / "o"
    out.mkdir()
    for name in (".a.0a1b2c3d.partial", ".a.1a1b2c3d.old", ".summary.json.2a1b2c3d.partial",
                 ".other.0a1b2c3d.partial", ".a.b.0a1b2c3d.partial"):
        (out / name).mkdir()
    assert run_cli("--batch", recipe, a, "--out", out, "--quiet", "--resume")[0] == 0
    assert sorted(p.name for p in out.glob(".*")) == [".a.b.0a1b2c3d.partial", ".other.0a1b2c3d.partial"]


# -- 2. SIGTERM (and Ctrl-C) from the batch's first moment -----------------------------------------

@pytest.mark.parametrize("where", ["load_batch_recipe", "start_pool"])
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_signal_while_the_batch_starts(tmp_path, sig, where):
    """The signal reaches the batch while its pool starts or its recipe is read (the first 0.3–0.5 s):
    exit 130 with the closing line, and summary.json says that nothing ran — before, SIGTERM ended it
    with status −15 and the previous summary.json stayed as if current."""
    recipe = write(tmp_path / "light.yaml", LIGHT)
    files = _inputs(tmp_path / "in", "a", "b")
    out = tmp_path / "o"
    done = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe),
                           *map(str, files), "--out", str(out), "--workers", "1", "--quiet"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and _summary(out)["counts"] == {"ok": 2}, done.stderr
    module = "batch" if where == "load_batch_recipe" else "executors"
    proc = _script(tmp_path, f"""
        from pointspro.core import {module} as module
        real = module.{where}
        def signalled(*a, **k):
            os.kill(os.getpid(), signal.{sig})
            return real(*a, **k)
        module.{where} = signalled
        """, "--batch", recipe, *files, "--out", out, "--workers", "2", "--quiet")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    # the dash as the child's locale writes it (C locale in CI: "\u2014")
    assert "pointspro: interrupted" in err and "0 of 2 inputs complete" in err and "Traceback" not in err
    s = _summary(out)
    assert s["interrupted"] is True and s["counts"] == {"not run": 2}
    assert sorted(p.name for p in out.iterdir()) == ["a", "b", "summary.json"]  # nothing left over


def test_the_signal_handler_comes_first(monkeypatch):
    """In this process: SIGTERM raises KeyboardInterrupt from the batch's start (before its logging,
    pool and recipe), and the handler before is back afterwards."""
    from pointspro.core import cli

    seen = []

    def first(args, fn):
        seen.append(signal.getsignal(signal.SIGTERM))
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_with_logging", first)
    before = signal.getsignal(signal.SIGTERM)
    assert cli.main(["--batch", "r.yaml", "a.csv", "--out", "o"]) == 130
    assert seen and seen[0] not in (signal.SIG_DFL, signal.SIG_IGN, before)
    with pytest.raises(KeyboardInterrupt):
        seen[0](signal.SIGTERM, None)
    assert signal.getsignal(signal.SIGTERM) is before


# -- 3. --resume knows an input however it is named -------------------------------------------------

def test_resume_skips_an_input_named_otherwise(run_cli, tmp_path, monkeypatch):
    """A relative run, then the same inputs by absolute path (a cron job), from another folder, or
    through a link: skipped; report.json keeps the name as typed first. A copy elsewhere is another
    input: run."""
    recipe = write(tmp_path / "light.yaml", LIGHT)
    _inputs(tmp_path / "in", "a")
    monkeypatch.chdir(tmp_path)
    assert run_cli("--batch", "light.yaml", "in/a.csv", "--out", "o", "--quiet")[0] == 0

    def status(*args):
        code, _, err = run_cli("--batch", *args, "--quiet", "--resume")
        assert code == 0, err
        return [e["status"] for e in _summary(tmp_path / "o")["inputs"]]

    assert status(recipe, tmp_path / "in" / "a.csv", "--out", tmp_path / "o") == ["skipped"]
    rep = json.loads((tmp_path / "o" / "a" / "report.json").read_text(encoding="utf-8"))
    assert rep["input"] == "in/a.csv" and rep["input_abspath"] == str(tmp_path / "in" / "a.csv")
    monkeypatch.chdir(tmp_path / "in")
    assert status("../light.yaml", "a.csv", "--out", "../o") == ["skipped"]
    (tmp_path / "link").symlink_to(tmp_path / "in")
    assert status(recipe, tmp_path / "link" / "a.csv", "--out", tmp_path / "o") == ["skipped"]
    rep = json.loads((tmp_path / "o" / "a" / "report.json").read_text(encoding="utf-8"))
    assert rep["input"] == "in/a.csv"
    # a report written before input_abspath was recorded: its name, from here
    rep.pop("input_abspath")
    (tmp_path / "o" / "a" / "report.json").write_text(json.dumps(rep), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert status(recipe, tmp_path / "in" / "a.csv", "--out", tmp_path / "o") == ["skipped"]
    # the same bytes in another folder: another input
    _inputs(tmp_path / "in2", "a")
    assert status(recipe, "in2/a.csv", "--out", "o") == ["ok"]
    assert json.loads((tmp_path / "o" / "a" / "report.json").read_text(encoding="utf-8"))["input"] == "in2/a.csv"
    assert os.path.isfile(tmp_path / "o" / "summary.json")
