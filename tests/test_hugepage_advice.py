"""The console command stops numpy's transparent-huge-page advice (core/cli.py
``without_hugepage_advice``: a fresh process's first touch of each large temporary cost 0.8 s of the
10⁶-point raster's 8 s), unless the user set NUMPY_MADVISE_HUGEPAGE."""
import os
import subprocess
import sys

PROBE = """
import os, sys
import numpy as np
from pointspro.core.cli import without_hugepage_advice
without_hugepage_advice()
core = getattr(np, "_core", None) or np.core
before = core.multiarray._set_madvise_hugepage(True)  # returns the setting it replaces
print(os.environ.get("NUMPY_MADVISE_HUGEPAGE"), before)
"""


def _run(env_value):
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if env_value is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = env_value
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True,
                         check=True)
    return out.stdout.split()


def test_the_advice_is_off_for_this_process_and_the_ones_it_starts():
    value, before = _run(None)
    assert value == "0"  # spawned batch workers read it as numpy starts
    assert before == "False"


def test_a_users_own_setting_is_left_as_set():
    value, before = _run("1")
    assert value == "1"
    assert before == "True"
