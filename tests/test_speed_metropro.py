"""Issue 17: MetroPro maps read by core/io/metropro.py (numpy) give SurfaceTopography's numbers bit for
bit; files outside its common case still go to SurfaceTopography with its messages."""
from __future__ import annotations

import struct
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import instruments, read_cloud
from pointspro.core.io.metropro import read_metropro

REAL = Path(__file__).parent / "data" / "realdata" / "metropro-1.dat"
W, H, DATA = 640, 480, 834 + 2 * 640 * 480  # this file: format 1, one intensity frame


def _via_surface_topography(path):
    with mock.patch("pointspro.core.io.metropro.read_metropro", return_value=None):
        return instruments.read_surface_topography(path)


def _same(a, b):
    assert a[0].dtype == b[0].dtype == np.float64
    assert np.array_equal(a[0], b[0])  # bit for bit (no NaN in either)
    assert a[1].keys() == b[1].keys()
    for k in b[1]:
        assert a[1][k].dtype == b[1][k].dtype and np.array_equal(a[1][k], b[1][k])
    assert a[2] == b[2]


def _variant(tmp_path, name, *, magic=None, sign=None, phase_res=None, invalid=0, seed=0, lateral=None):
    raw = bytearray(REAL.read_bytes())
    if magic is not None:
        raw[:4] = magic
    if sign is not None:
        struct.pack_into(">h", raw, 232, sign)
    if phase_res is not None:
        struct.pack_into(">h", raw, 218, phase_res)
    if lateral is not None:
        struct.pack_into(">f", raw, 184, lateral)
    if invalid:
        rng = np.random.default_rng(seed)
        for k in rng.choice(W * H, invalid, replace=False):
            struct.pack_into(">i", raw, DATA + 4 * int(k), 2147483640 + int(rng.integers(0, 8)))
    p = tmp_path / f"{name}.dat"
    p.write_bytes(bytes(raw))
    return p


def test_real_file_bit_exact():
    got = read_metropro(REAL)
    assert got is not None
    _same(got, _via_surface_topography(REAL))


@pytest.mark.parametrize("kw", [
    dict(sign=1),
    dict(phase_res=0, invalid=1000, seed=1),
    dict(phase_res=2, sign=-1, invalid=37, seed=2),
    dict(magic=b"\x88\x1b\x03\x70", invalid=5000, seed=3),
])
def test_header_variants_bit_exact(tmp_path, kw):
    p = _variant(tmp_path, "v", **kw)
    got = read_metropro(p)
    assert got is not None
    _same(got, _via_surface_topography(p))
    if kw.get("invalid"):
        assert got[2]["invalid_dropped"] == kw["invalid"]


def test_read_cloud_uses_direct_reader_without_importing_surface_topography():
    with mock.patch.object(instruments, "_topography_to_cloud", side_effect=AssertionError("ST used")):
        cloud = read_cloud(REAL)
    assert cloud.n == W * H


def test_uncalibrated_file_falls_back_with_its_message(tmp_path):
    p = _variant(tmp_path, "nolateral", lateral=0.0)
    assert read_metropro(p) is None
    with pytest.raises(InputError, match="lateral calibration"):
        read_cloud(p)


def test_truncated_file_falls_back(tmp_path):
    p = tmp_path / "short.dat"
    p.write_bytes(REAL.read_bytes()[: DATA + 1000])
    assert read_metropro(p) is None
    with pytest.raises(InputError, match=str(p.name)):
        read_cloud(p)
