"""cloud.csv written by a forked child while the figures are drawn (core/io/background.py)."""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.cloud import PointCloud
from pointspro.core.io import background, read_cloud, write_csv


def _cloud(n=20_000):
    rng = np.random.default_rng(4)
    return PointCloud(rng.normal(size=(n, 3)) * 100, channels={"residual": rng.normal(0, 1e-4, n)})


@pytest.fixture
def forking(monkeypatch):
    if not hasattr(os, "fork"):
        pytest.skip("os.fork does not exist on this platform (Windows): the writer is inline there")
    monkeypatch.setattr(background, "_can_fork", lambda: True)


def test_forked_writer_writes_the_same_bytes_as_inline(tmp_path, forking):
    c = _cloud()
    job = background.BackgroundWrite(write_csv, c, tmp_path / "forked.csv", what="forked.csv")
    assert job.forked
    job.wait()
    write_csv(c, tmp_path / "inline.csv")
    digest = [hashlib.sha256((tmp_path / f).read_bytes()).hexdigest() for f in ("forked.csv", "inline.csv")]
    assert digest[0] == digest[1]
    back = read_cloud(tmp_path / "forked.csv")
    assert np.array_equal(back.xyz, c.xyz) and np.array_equal(back["residual"], c["residual"])


def test_an_error_in_the_child_is_raised_by_wait_naming_the_file(tmp_path, forking):
    job = background.BackgroundWrite(write_csv, _cloud(100), tmp_path / "no" / "such" / "dir.csv",
                                     what="out/cloud.csv")
    with pytest.raises(OSError, match=r"writing out/cloud.csv failed: FileNotFoundError"):
        job.wait()


def test_cancel_stops_the_child_and_wait_after_it_is_a_no_op(tmp_path, forking):
    """cancel() kills and reaps a child that would never finish (an Event nobody sets)."""
    import threading

    job = background.BackgroundWrite(threading.Event().wait)
    pid = job.pid
    job.cancel()
    job.wait()
    assert not job.forked
    with pytest.raises(ChildProcessError):  # reaped: no such child any more
        os.waitpid(pid, os.WNOHANG)


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_child_signalled_with_its_group_ends_without_a_python_error(tmp_path, forking, sig):
    """Ctrl-C and `timeout` signal the whole process group: the child had the batch's SIGTERM handler
    (raise KeyboardInterrupt) and sent back "KeyboardInterrupt: " as its error (a review saw that line
    printed). It now ends at once, as a process without handlers does."""
    import signal
    import threading

    previous = signal.signal(signal.SIGTERM, lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    ready_r, ready_w = os.pipe()

    def work():  # runs after the child set its handlers: says so, then waits for ever
        os.write(ready_w, b"1")
        threading.Event().wait()
    try:
        job = background.BackgroundWrite(work, what="cloud.csv")
        assert os.read(ready_r, 1) == b"1"
        os.kill(job.pid, getattr(signal, sig))
        with pytest.raises(OSError) as e:
            job.wait()
    finally:
        signal.signal(signal.SIGTERM, previous)
        os.close(ready_r)
        os.close(ready_w)
    assert "KeyboardInterrupt" not in str(e.value) and "ended with" in str(e.value)


def test_inline_when_threads_are_running(tmp_path):
    """A process with other threads (the window) never forks: the write happens inline."""
    import threading

    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        job = background.BackgroundWrite(write_csv, _cloud(100), tmp_path / "c.csv")
        assert not job.forked and (tmp_path / "c.csv").is_file()
    finally:
        stop.set()
        t.join()


# --- share_out: one input's figures drawn by this process and forked ones (issue 17) ----------------

def _write_pid(path, pause=0.0):
    import time

    time.sleep(pause)
    path.write_text(str(os.getpid()))


def test_share_out_spreads_the_tasks_over_processes_and_returns_their_seconds(tmp_path, forking):
    from functools import partial

    tasks = [(f"f{k}.txt", partial(_write_pid, tmp_path / f"f{k}.txt", 0.15)) for k in range(6)]
    before = _children()
    seconds = background.share_out(tasks, workers=3)
    assert sorted(seconds) == sorted(name for name, _ in tasks)
    assert all(0.1 < s < 5 for s in seconds.values())
    pids = {(tmp_path / name).read_text() for name, _ in tasks}
    assert str(os.getpid()) in pids and len(pids) >= 2  # the parent drew some, a child the others
    _assert_no_unreaped_child(before)


def _children() -> set[int]:
    """The pids of this process's children, running or ended and unreaped (Linux /proc)."""
    me, kids = os.getpid(), set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # ended meanwhile
        if int(fields[1]) == me:
            kids.add(int(stat.parent.name))
    return kids


def _assert_no_unreaped_child(before: set[int]):
    """No child of this process but those it had ``before`` (multiprocessing's resource tracker, started
    by an earlier test's spawned pool, lives as long as this process: the check was "no child at all"
    and failed after tests/test_batch_scale.py in the same run), and none ended unreaped."""
    assert _children() <= before
    try:
        assert os.waitpid(-1, os.WNOHANG) == (0, 0)
    except ChildProcessError:
        pass  # no child at all


def test_share_out_inline_runs_in_order_in_this_process(tmp_path):
    from functools import partial

    order = []
    tasks = [(f"g{k}", partial(order.append, k)) for k in range(5)]
    assert sorted(background.share_out(tasks, workers=4, fork=False)) == [f"g{k}" for k in range(5)]
    assert order == list(range(5))


def _boom():
    raise ValueError("no such colour map")


def test_share_out_error_names_the_task_whoever_ran_it(tmp_path, forking):
    """A failing figure: raised as it is when this process drew it, as an OSError naming it when a
    child did; the other tasks still finish and no child is left behind."""
    from functools import partial

    before = _children()
    for _ in range(3):
        tasks = [("ok1.txt", partial(_write_pid, tmp_path / "ok1.txt", 0.05)), ("bad.png", _boom),
                 ("ok2.txt", partial(_write_pid, tmp_path / "ok2.txt", 0.05))]
        with pytest.raises((OSError, ValueError), match="no such colour map") as err:
            background.share_out(tasks, workers=2)
        if err.type is OSError:
            assert "writing bad.png failed: ValueError" in str(err.value)
        _assert_no_unreaped_child(before)


def test_batch_outputs_are_the_same_bytes_with_figures_shared_out(tmp_path, monkeypatch, forking):
    """write_outputs with the figures spread over forked processes writes the same files, byte for
    byte, as drawing them one after the other here (report.json/html carry time stamps)."""
    import hashlib
    from pathlib import Path

    from pointspro.core import batch
    from pointspro.core.maps.grid import read_x3p_map
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import load_recipe

    root = Path(__file__).resolve().parents[1] / "resources" / "example"
    rec = load_recipe(root / "recipe.yaml")
    cloud = read_cloud(root / "asphere_cmm.csv")
    result = run_pipeline(cloud, rec)
    digests, maps = [], []
    for k, fork in enumerate((True, False)):
        monkeypatch.setattr(batch, "thread_count", lambda: 3)
        timings = {}
        batch.write_outputs(tmp_path / f"o{k}", "asphere_cmm.csv", rec, result, fork_csv=fork, timings=timings)
        files = sorted(p for p in (tmp_path / f"o{k}").iterdir() if not p.name.startswith("report."))
        assert any(p.suffix == ".png" for p in files) and all(f"{p.name}" in timings or p.name.startswith("cloud.")
                                                             for p in files)
        # an X3P file holds its creation time: compared by the map it reads back
        digests.append({p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in files if p.suffix != ".x3p"})
        maps.append(read_x3p_map(tmp_path / f"o{k}" / "map.x3p"))
    assert digests[0] == digests[1]
    assert np.array_equal(maps[0].z, maps[1].z, equal_nan=True) and np.array_equal(maps[0].xs, maps[1].xs)
