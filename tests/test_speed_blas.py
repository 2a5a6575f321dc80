"""Issue 17: the batch's own process runs BLAS on one thread (core.parallel.single_threaded_blas).

OpenBLAS's spinning threads made narrow calls (the B-spline's banded solve, PVr's 36-column
chunks) 30–60× slower when another process shared the cores; the numbers must not change."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from pointspro.core import executors
from pointspro.core.metrics import form_metrics
from pointspro.core.parallel import single_threaded_blas


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_context_limits_blas_and_restores():
    with threadpool_limits(2, user_api="blas"):
        saved = dict(os.environ)
        assert set(_blas_threads()) == {2}
        with single_threaded_blas():
            assert set(_blas_threads()) == {1}
            assert dict(os.environ) == saved  # not touched (single_threaded_blas' doc)
        assert set(_blas_threads()) == {2}


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_a_child_forked_while_the_lock_is_held_can_enter_the_context():
    """A figure process or a Monte Carlo worker forked at the moment another thread held the
    context's lock inherited it locked and hung on entering (a review): the child gets a fresh one."""
    import signal

    single_threaded_blas._lock.acquire()  # as another thread of the parent would, at the fork
    try:
        pid = os.fork()
        if pid == 0:  # the child: must enter and leave within 20 s
            code = 1
            try:
                signal.alarm(20)
                with single_threaded_blas():
                    code = 0 if set(_blas_threads()) == {1} else 2
            finally:
                os._exit(code)
    finally:
        single_threaded_blas._lock.release()
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0


def test_sequential_batch_runs_each_input_on_one_blas_thread(monkeypatch, tmp_path):
    seen = []

    def fake_process_input(path, recipe, out_dir, stem, **kw):
        seen.append((stem, _blas_threads()))
        return stem

    monkeypatch.setattr(executors, "process_input", fake_process_input)
    jobs = [(Path(tmp_path / "a.csv"), "a"), (Path(tmp_path / "b.csv"), "b")]
    with threadpool_limits(2, user_api="blas"):
        between = []
        for oc in executors.run_sequential(None, None, jobs, tmp_path):
            between.append(set(_blas_threads()))  # the caller's code between inputs: its own limit
        assert [s for s, _ in seen] == ["a", "b"]
        assert all(set(t) == {1} for _, t in seen)
        assert between == [{2}, {2}]


@pytest.mark.parametrize("seed,n", [(0, 3000), (1, 12_000), (2, 30_000)])
def test_form_metrics_same_on_one_blas_thread(seed, n):
    """PV, RMS, PVr and slope RMS with one BLAS thread equal those with two (to rounding)."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-100, 100, n)
    y = rng.uniform(-100, 100, n)
    keep = x * x + y * y < 100.0 ** 2
    x, y = x[keep], y[keep]
    r = (2e-4 * np.sin(x / (13 + seed)) * np.cos(y / 9) + 3e-5 * (x * x - y * y) / 1e4
         + 1e-6 * rng.standard_normal(len(x)))
    with threadpool_limits(2, user_api="blas"):
        many = form_metrics(x, y, r, 100.0)
    with single_threaded_blas():
        one = form_metrics(x, y, r, 100.0)
    for k in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad"):
        assert one[k] == pytest.approx(many[k], rel=1e-12, abs=0), k


def test_pipeline_and_summary_run_on_one_blas_thread(monkeypatch):
    """The window and the Python API call run_pipeline and result.summary() directly, outside the
    batch's context: they set one BLAS thread themselves and give the caller's setting back."""
    from pointspro.core.io import read_cloud
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import load_recipe
    from pointspro.plugins.zernike import ZernikeStep

    from .conftest import EXAMPLE

    seen = []
    real_run = ZernikeStep.run

    def spy(self, cloud, params, ctx):
        seen.append(set(_blas_threads()))
        return real_run(self, cloud, params, ctx)

    monkeypatch.setattr(ZernikeStep, "run", spy)
    import pointspro.core.pipeline as pipeline

    real_summarize = pipeline.summarize

    def spy_summary(*a, **k):
        seen.append(set(_blas_threads()))
        return real_summarize(*a, **k)

    monkeypatch.setattr(pipeline, "summarize", spy_summary)
    rec = load_recipe(EXAMPLE / "recipe.yaml")
    cloud = read_cloud(EXAMPLE / "asphere_cmm.csv", **rec.input)
    with threadpool_limits(2, user_api="blas"):
        result = run_pipeline(cloud, rec)
        assert set(_blas_threads()) == {2}
        result.summary()
        assert set(_blas_threads()) == {2}
    assert seen == [{1}, {1}]


def test_context_shared_between_threads_restores_once_all_have_left():
    """Two pipelines in two threads (the window): the one that leaves first must not give the
    other its two BLAS threads back half-way; the last to leave restores the caller's setting."""
    import threading

    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    during_b = []

    def a():
        with single_threaded_blas():
            a_in.set()
            b_in.wait(10)
        a_out.set()

    def b():
        a_in.wait(10)
        with single_threaded_blas():
            b_in.set()
            a_out.wait(10)
            during_b.append(set(_blas_threads()))

    with threadpool_limits(2, user_api="blas"):
        ts = [threading.Thread(target=f) for f in (a, b)]
        for t in ts:
            t.start()
        for t in ts:
            t.join(20)
        assert during_b == [{1}]
        assert set(_blas_threads()) == {2}
        with single_threaded_blas():
            with single_threaded_blas():
                assert set(_blas_threads()) == {1}
            assert set(_blas_threads()) == {1}
        assert set(_blas_threads()) == {2}


def test_a_fresh_process_gets_every_blas_back_after_run_pipeline():
    """The Python API in a fresh process: scipy's own OpenBLAS is loaded by the pipeline; it used to
    load while OPENBLAS_NUM_THREADS was 1 and keep one thread for the rest of the process (a review).
    After run_pipeline and the summary every BLAS has the threads numpy's had before."""
    import subprocess
    import sys

    from .conftest import EXAMPLE

    code = ("import sys, json; from threadpoolctl import threadpool_info\n"
            "import numpy\n"
            "def blas(): return sorted((i['prefix'], i['num_threads']) for i in threadpool_info() "
            "if i['user_api'] == 'blas')\n"
            "before = blas()\n"
            "from pointspro.core.io import read_cloud\n"
            "from pointspro.core.pipeline import run_pipeline\n"
            "from pointspro.core.recipe import load_recipe\n"
            "rec = load_recipe(sys.argv[1] + '/recipe.yaml')\n"
            "run_pipeline(read_cloud(sys.argv[1] + '/asphere_cmm.csv', **rec.input), rec).summary()\n"
            "print(json.dumps([before, blas()]))")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                           "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code, str(EXAMPLE)], capture_output=True, text=True,
                         encoding="utf-8", env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    import json

    before, after = json.loads(out.stdout.strip().splitlines()[-1])
    n = {t for _, t in before}
    assert len(n) == 1 and len(after) >= len(before), (before, after)
    assert {t for _, t in after} == n, (before, after)
