"""cloud.csv written by a forked child while the figures are drawn (core/io/background.py)."""
from __future__ import annotations

import hashlib
import os

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
