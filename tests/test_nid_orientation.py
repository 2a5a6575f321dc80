"""Nanosurf .nid maps in the file's own coordinates (review, 2026-11-27): SurfaceTopography 1.27's
easyScan reader flips dimension 1 (np.fliplr), so PointsPro put stored line q at
y = (ny − 1 − q)·Δy — a y mirror of the file (y-odd Zernike terms, a correction's side, flipped).
Stored line q lies at y = Dim1Min + q·Dim1Range/Lines (x = Dim0Min + p·Dim0Range/Points), y up.

Checked against the file decoded here by hand: an INI-like text header (sections [DataSet],
[DataSet-g:c] …), then "#!" and the data sets, in the order [DataSet] lists them (Gr0-Ch0, Gr0-Ch1 …
of each group, gaps skipped), each Lines × Points little-endian signed integers of SaveBits,
line after line; value = (raw + 2^(bits−1))·Dim2Range/2^bits + Dim2Min (Gwyddion's ezdfile.c and
Nanosurf's own readers scale so). The lines are stored by position, whatever the scan direction:
this "Up" file ends at CurLine=255 and holds the feedback's settling transient in its first lines,
the first ones scanned (at the bottom, Dim1Min, when scanning up); Nanosurf's "Down" examples end
at CurLine=0 (see core/io/instruments.py).

File (tests/data/realdata; LICENSE-SurfaceTopography.md beside it):
  nid-1.nid  SurfaceTopography test/file_format_examples/ (MIT): DriveAFM, 256 × 256 × 8 data sets
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pointspro.core.io import read_cloud

DATA = Path(__file__).parent / "data" / "realdata"
NID = DATA / "nid-1.nid"


def _nid_by_hand(path):
    """(header sections as {name: {key: value}}, [(section name, its keys, values[q, p])]), the
    values in the data set's Dim2Unit, q the stored line, p the point within it."""
    b = Path(path).read_bytes()
    start = b.index(b"#!")
    sections, cur = {}, None
    for line in b[:start].decode("latin-1").splitlines():
        line = line.strip()
        if line.startswith("[") and line.endswith("]"):
            cur = sections.setdefault(line[1:-1], {})
        elif "=" in line and cur is not None:
            k, v = line.split("=", 1)
            cur.setdefault(k, v.strip())
    ds = sections["DataSet"]
    p, out = start + 2, []
    for g in range(int(ds["GroupCount"])):
        for c in range(int(ds[f"Gr{g}-Count"])):
            name = ds.get(f"Gr{g}-Ch{c}")
            if not name:
                continue
            s = sections[name]
            assert s["SaveMode"] == "Binary" and s["SaveSign"] == "Signed"
            assert s["SaveOrder"] == "Intel"
            nx, ny, bits = int(s["Points"]), int(s["Lines"]), int(s["SaveBits"])
            raw = np.frombuffer(b, f"<i{bits // 8}", count=nx * ny, offset=p).reshape(ny, nx)
            p += nx * ny * bits // 8
            val = (raw.astype(np.float64) + 2.0 ** (bits - 1)) * float(s["Dim2Range"]) / 2.0 ** bits \
                + float(s["Dim2Min"])
            out.append((name, s, val))
    assert p == len(b)  # the data sets fill the file exactly
    return sections, out


def test_the_header_as_decoded():
    sections, sets = _nid_by_hand(NID)
    assert sections["DataSet-Info"]["Scan direction"] == "Up"
    assert [(s["Frame"], s["Dim2Name"]) for _, s, _ in sets] == [
        (f, n) for f in ("Scan forward", "Scan backward")
        for n in ("Deflection", "Z-Axis", "Friction force", "Z-AxisSensor")]
    for _, s, v in sets:
        assert v.shape == (256, 256) and s["CurLine"] == "255"  # a complete "Up" scan
        assert (s["Dim0Unit"], s["Dim1Unit"]) == ("m", "m")
        assert float(s["Dim0Min"]) == float(s["Dim1Min"]) == 0.0
        assert float(s["Dim0Range"]) == float(s["Dim1Range"]) == 2e-05  # "Image size=20" µm


def test_line_zero_was_scanned_first():
    """Scanning "Up" starts at the bottom: the first stored lines hold the feedback's settling
    (line-mean steps of 26, 14, 9 and 14 times the median step), the last ones none."""
    _, sets = _nid_by_hand(NID)
    z = next(v for _, s, v in sets if (s["Frame"], s["Dim2Name"]) == ("Scan forward", "Z-Axis"))
    step = np.abs(np.diff(z.mean(axis=1)))
    med = np.median(step)
    assert (step[:4] > 8 * med).all() and (step[-10:] < 2 * med).all()


def test_pointspro_puts_each_pixel_at_the_files_own_coordinates():
    sections, sets = _nid_by_hand(NID)
    name, s, z = next(t for t in sets if (t[1]["Frame"], t[1]["Dim2Name"]) == ("Scan forward",
                                                                                "Z-Axis"))
    assert name == "DataSet-0:1" and s["Dim2Unit"] == "m"
    c = read_cloud(NID)
    assert c.meta["instrument_format"] == "ezd" and c.meta["grid"] == [256, 256]
    assert c.n == z.size
    q, p = c["row"].astype(int), c["col"].astype(int)
    assert len(set(zip(q.tolist(), p.tolist()))) == z.size
    dx = float(s["Dim0Range"]) / int(s["Points"]) * 1e3  # mm
    dy = float(s["Dim1Range"]) / int(s["Lines"]) * 1e3
    assert np.allclose(c.x, float(s["Dim0Min"]) * 1e3 + p * dx, rtol=1e-12, atol=1e-15)
    assert np.allclose(c.y, float(s["Dim1Min"]) * 1e3 + q * dy, rtol=1e-12, atol=1e-15)
    # pixel by pixel: stored line q, point p at (x, y) = (p·Δx, q·Δy), heights m → mm
    assert np.allclose(c.z, z[q, p] * 1e3, rtol=1e-9, atol=1e-15)
    # and not its y mirror (the heights differ by up to 0.3 µm there)
    assert np.abs(c.z - z[255 - q, p] * 1e3).max() > 1e-4
