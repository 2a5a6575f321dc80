"""Bruker/Veeco Nanoscope .di maps in the file's own coordinates (review, 2026-11-28): the first stored
line is the bottom of the scan, y = 0 (Bruker: "Frame Up" starts at the bottom; Gwyddion's
nanoscope.c turns the lines upside down for its y-down image rows). SurfaceTopography 1.27's DI reader
flips dimension 1 (np.fliplr), so PointsPro put stored line q at y = (ny − 1 − q)·Δy — a y mirror of
the file: y tilt and the y-odd Zernike terms with the wrong sign, features at the wrong y.

Checked against the file decoded here by hand: a text header of backslash keys, the first
"\\*Ciao image list" giving `\\Data offset`, `\\Samps/line`, `\\Number of lines` and `\\Bytes/pixel`;
the lines stored one after the other from that offset, little-endian signed integers.

File (tests/data/realdata; LICENSE-SurfaceTopography.md beside it):
  di-3.di  SurfaceTopography test/file_format_examples/ (MIT), 256 × 256 int16
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pointspro.core.io import read_cloud

DI = Path(__file__).parent / "data" / "realdata" / "di-3.di"


def _di_by_hand(path):
    """The first image's stored lines as an (ny, nx) array of raw integers (line q = row q)."""
    b = path.read_bytes()
    header = b[: b.find(b"\\*File list end")].decode("latin-1")
    image = header.split("\\*Ciao image list")[1]

    def key(k, text=image):
        m = re.search(re.escape(k) + r":\s*([^\r\n]*)", text)
        return m.group(1) if m else None

    offset, nx, ny = int(key("\\Data offset")), int(key("\\Samps/line")), int(key("\\Number of lines"))
    bpp = int(key("\\Bytes/pixel") or key("\\Bytes/pixel", header))
    dtype = {2: "<i2", 4: "<i4"}[bpp]
    return np.frombuffer(b, dtype, count=nx * ny, offset=offset).reshape(ny, nx).astype(np.float64)


def test_a_nanoscope_files_first_line_is_at_y_zero():
    raw = _di_by_hand(DI)
    c = read_cloud(DI)
    assert c.meta["instrument_format"] == "di"
    row, col = np.asarray(c["row"], dtype=int), np.asarray(c["col"], dtype=int)
    ny, nx = raw.shape
    Z = np.full((ny, nx), np.nan)
    Z[row, col] = c.z
    ok = np.isfinite(Z)

    def corr(a, b):
        a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
        return float(a @ b / np.sqrt((a @ a) * (b @ b)))

    assert corr(raw, Z) > 0.999999  # line q at row q — linear in the raw counts, not mirrored
    assert corr(raw[::-1], Z) < 0.5  # (mirrored it read 1.000000)
    dy = float(c.meta["pixel_mm"][1])
    np.testing.assert_allclose(c.y[row == 0], 0.0, atol=1e-15)  # the first stored line at y = 0
    np.testing.assert_allclose(c.y, row * dy, rtol=1e-12, atol=1e-15)  # y up: line q at q·Δy


def test_a_truncated_nanoscope_file_is_named_as_one(tmp_path):
    """Its reader answers only "maybe" to a Nanoscope header, so a cut .di read "unknown file type
    '.di'" although the reader knew it was short (a review)."""
    import pytest

    from pointspro.core.errors import InputError

    cut = tmp_path / "cut.di"
    data = DI.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InputError, match="a damaged or truncated Bruker/Veeco/DI Nanoscope file"):
        read_cloud(cut)
