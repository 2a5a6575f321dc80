"""Shared fixtures: surfaces from the papers, generated clouds, a CLI runner."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.surfaces import EvenAsphere

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# the window's tests: errors go to the log, not to modal dialogs; autosave into a scratch folder
os.environ.setdefault("POINTSPRO_NO_DIALOGS", "1")
import atexit as _atexit  # noqa: E402
import shutil as _shutil  # noqa: E402
import tempfile as _tempfile  # noqa: E402

# one scratch folder for the whole run, removed at its end: the steps' example parameters (fiducials,
# volumetric, kinematic, dynamic calibrations) and the subprocesses' temporary files went to the
# system's temporary folder and stayed there (~200 folders a run of the suite)
_SCRATCH = _tempfile.mkdtemp(prefix="pointspro-tests-")
_tempfile.tempdir = _SCRATCH
os.environ["TMPDIR"] = _SCRATCH
_atexit.register(_shutil.rmtree, _SCRATCH, ignore_errors=True)
os.environ.setdefault("POINTSPRO_AUTOSAVE_DIR", _tempfile.mkdtemp(prefix="pointspro-autosave-"))
os.environ.setdefault("POINTSPRO_SETTINGS", os.path.join(os.environ["POINTSPRO_AUTOSAVE_DIR"], "settings.ini"))

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "resources" / "example"
#: what `pointspro --batch` writes for the example recipe, per input
EXAMPLE_OUTPUTS = {"cloud.csv", "report.json", "report.html", "form_error.png", "omega_map.png",
                   "zernike.csv", "zernike.png", "zernike_removed.png", "misalignment.png", "map.csv", "map.x3p", "map.asc",
                   "map.png", "profiles.png", "psd.png", "profiles.csv", "psd.csv"}


@pytest.fixture
def asphere_002():
    """Paper 002 Table 1: D 1300 mm, C = 1/3000, k = −0.98, a4 = 7e−13, a6 = 1e−19."""
    return EvenAsphere(c=1 / 3000, k=-0.98, A={4: 7e-13, 6: 1e-19}, aperture=1300)


@pytest.fixture
def raster_cloud(asphere_002):
    """A 100 mm-pitch raster on the 002 asphere with a line channel and a residual-like channel."""
    g = np.arange(-600.0, 601.0, 100.0)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    keep = np.hypot(x, y) <= 640
    x, y = x[keep], y[keep]
    z = asphere_002.sag(x, y)
    rng = np.random.default_rng(7)
    return PointCloud.from_xyz(x, y, z + rng.normal(0, 1e-4, len(x)),
                               line=np.round(y / 100).astype(int) + 6,
                               weight=np.ones(len(x)))


@pytest.fixture
def run_cli(capsys):
    """Run `pointspro` in-process; returns (exit code, stdout, stderr)."""
    from pointspro.core.cli import main

    def run(*args):
        code = main([str(a) for a in args])
        out = capsys.readouterr()
        return code, out.out, out.err

    return run


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path
