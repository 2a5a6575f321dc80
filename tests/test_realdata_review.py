"""Real instrument files an independent review found misread (review C, 2026-11-27), each checked
against an independent decode of the file — the header bytes or main.xml read by hand with struct /
numpy / ElementTree, and x3pio where it reads the file — never against the reader under test.

Files (tests/data/realdata; the licences beside them):
  nms-2.nms            SurfaceTopography test/file_format_examples/nms-2.nms (MIT)
  frt-1.frt.xz         SurfaceTopography test/file_format_examples/frt-1.frt (MIT), xz-compressed here
                       to stay small (1.5 MB → 233 kB); decompressed into tmp_path by the test
  ISO5436-sample2.x3p  openGPS x3p sample files, OpenFMC/x3p (LGPL-3.0, LICENSE-openGPS-x3p.txt)
  ISO5436-sample3.x3p  idem
  csafe-logo.x3p       x3ptools inst/csafe-logo.x3p, heike/x3ptools (MIT, LICENSE-x3ptools.txt)
"""
from __future__ import annotations

import lzma
import shutil
import struct
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

DATA = Path(__file__).parent / "data" / "realdata"


def _one_line(e, p):
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg and "internal error" not in msg
    assert "Traceback" not in msg and len(msg) < 400


def test_the_licences_travel_with_the_data():
    assert "GNU LESSER GENERAL PUBLIC LICENSE" in (DATA / "LICENSE-openGPS-x3p.txt").read_text("utf-8")
    assert "COPYRIGHT HOLDER: Heike Hofmann" in (DATA / "LICENSE-x3ptools.txt").read_text("utf-8")
    assert (DATA / "LICENSE-SurfaceTopography.md").exists()


# --- NanoFocus .nms: pixel in nm; chosen by its extension -------------------------------------------
def _nms_by_hand(path):
    """The .nms header and heights decoded with struct/numpy (layout of SurfaceTopography's and
    surfalize's readers, which agree on it): zmin, zmax (µm) float64 at byte 16; nx, ny uint32 at
    1368; dx, dy float64 at 1376; uint16 heights from byte 3468, row by row (x fastest), scaled
    zmin + v / 65534 · (zmax − zmin)."""
    b = Path(path).read_bytes()
    zmin, zmax = struct.unpack_from("<2d", b, 16)
    nx, ny, dx, dy = struct.unpack_from("<2I2d", b, 1368)
    v = np.frombuffer(b, "<u2", count=nx * ny, offset=3468).reshape(ny, nx).astype(np.float64)
    return nx, ny, dx, dy, zmin, zmax, zmin + v / 65534 * (zmax - zmin)


def test_nms_pixel_is_in_nanometres_and_the_file_is_read_as_nms():
    """Before: the file was refused ("cannot read this MATLAB file": SurfaceTopography's detection
    opened it with its MATLAB reader), and st_nms-1.nms, read, had a 312.5 mm pixel (a 160 m field).

    Truth: the header's pixel size is 312.4999911618964 (x and y). Its unit is nm: surfalize reads
    it so (nms.py: ``step_x = dx * 1e-3`` in µm → 0.3125 µm), and only nm fits the data — 512 pixels
    make a 160 µm confocal field over heights spanning zmax − zmin = 1.96 µm here (3.3 µm in
    nms-1); in mm the field would be 160 m."""
    p = DATA / "nms-2.nms"
    nx, ny, dx, dy, zmin, zmax, z_um = _nms_by_hand(p)
    assert (nx, ny) == (512, 512) and dx == dy == pytest.approx(312.5, abs=1e-4)
    c = read_cloud(p)
    assert c.meta["instrument_format"] == "nms"
    assert c.meta["grid"] == [512, 512] and c.meta["invalid_dropped"] == 0 and c.n == nx * ny
    assert c.meta["pixel_mm"] == pytest.approx([dx * 1e-6, dy * 1e-6], rel=1e-15)  # nm → mm
    assert c.meta["pixel_mm"][0] == pytest.approx(0.0003125, rel=1e-7)
    assert np.ptp(c.x) == pytest.approx(511 * dx * 1e-6, rel=1e-12)  # 0.1597 mm
    assert np.ptp(c.y) == pytest.approx(511 * dy * 1e-6, rel=1e-12)
    assert np.allclose(c.x, c["col"] * dx * 1e-6, rtol=1e-12, atol=0)
    assert np.allclose(c.y, c["row"] * dy * 1e-6, rtol=1e-12, atol=0)
    # heights: µm → mm, pixel by pixel (the heights were right before; the pixel was not)
    assert np.allclose(c.z, z_um[c["row"], c["col"]] * 1e-3, rtol=1e-12, atol=0)
    assert c.z.min() == pytest.approx(zmin * 1e-3, rel=1e-9)


def test_magic_bytes_still_outrank_the_extension(tmp_path):
    """The extension's reader goes first only when no reader's magic bytes claim the file."""
    shutil.copy(DATA / "sur-2.sur", tmp_path / "map.nms")  # a Digital Surf file named .nms
    assert read_cloud(tmp_path / "map.nms").meta["instrument_format"] == "sur"
    p = tmp_path / "not.nms"
    p.write_bytes(b"\x00\x01\x02\xff" * 300)  # binary; no NMS (too small for its raster) nor other
    with pytest.raises(InputError) as e:
        read_cloud(p)
    _one_line(e, p)


# --- FRT MicroProf: stored values outside the header's valid range are invalid ----------------------
def _frt_by_hand(path):
    """Block list of an FRT file decoded with struct (Gwyddion's microprof.c): 16-byte magic +
    version, uint16 block count, then blocks of uint16 tag + uint32 size (version 1.00) + data.
    0x0066: nx, ny, bits; 0x006C: measuring range, height scale (m per count); 0x0070: first_valid,
    last_valid ("the smallest / largest valid value"); 0x000B: the heights, uint16, the first
    stored row being the image's bottom line (y = 0 after the flip that Gwyddion and
    SurfaceTopography make)."""
    b = Path(path).read_bytes()
    assert b[:16] == b"FRTM_GLIDERV1.00"
    (n,), pos, blocks = struct.unpack_from("<H", b, 16), 18, {}
    for _ in range(n):
        tag, size = struct.unpack_from("<HI", b, pos)
        blocks[tag] = b[pos + 6:pos + 6 + size]
        pos += 6 + size
    assert pos == len(b)
    nx, ny, bits = struct.unpack_from("<3I", blocks[0x66])
    scale = struct.unpack_from("<Id", blocks[0x6C])[1]
    lo, hi = struct.unpack_from("<2I", blocks[0x70])
    raw = np.frombuffer(blocks[0x0B], "<u2").reshape(ny, nx)  # stored line j = y index (the first is
    # the bottom of the picture: docs/formats.md)
    return bits, scale, lo, hi, raw


def _plane_rms(x, y, z):
    a = np.column_stack([np.ones_like(x), x, y])
    r = z - a @ np.linalg.lstsq(a, z, rcond=None)[0]
    return float(np.sqrt(np.mean(r ** 2)))


def test_frt_values_outside_the_valid_range_are_invalid(tmp_path):
    """Before: the last stored row, at y max (500 stored zeros → heights of exactly 0.0, next to rows of value 1
    that both readers mask) was read as valid: 173,544 points, RMS after tilt 4.396 µm where the
    surface gives 1.610 µm. The header's block 0x0070 says the valid stored values are 5 … 65529."""
    p = tmp_path / "frt-1.frt"
    p.write_bytes(lzma.decompress((DATA / "frt-1.frt.xz").read_bytes()))
    bits, scale, lo, hi, raw = _frt_by_hand(p)
    assert (bits, lo, hi) == (16, 5, 65529) and raw.shape == (500, 500)
    assert (raw[-1] == 0).all() and (raw == 0).sum() == 500  # the suspect row, y max
    ok = (raw >= lo) & (raw <= hi)
    assert ok.sum() == 173044 and (raw == 1).sum() == 76456
    c = read_cloud(p)
    assert c.n == ok.sum() and c.meta["invalid_dropped"] == 500 * 500 - ok.sum()
    assert not (c["row"] == raw.shape[0] - 1).any() and c.z.min() > 0
    assert np.allclose(c.z, raw[c["row"], c["col"]] * scale * 1e3, rtol=1e-12, atol=0)  # m → mm
    assert c.z.mean() * 1e3 == pytest.approx(78.958308, rel=1e-7)  # µm
    j, i = np.nonzero(ok)  # the truth's own RMS after piston and tilt, with the file's pixel
    pix = c.meta["pixel_mm"]
    rms = _plane_rms(i * pix[0], j * pix[1], raw[ok] * scale * 1e3)
    assert rms * 1e3 == pytest.approx(1.6099, abs=1e-4)  # µm; 4.396 µm with the zero row
    assert _plane_rms(c.x, c.y, c.z) == pytest.approx(rms, rel=1e-9)


# --- X3P: point cloud, absolute axis, main.xml in a folder ------------------------------------------
def _main_xml(path, name="main.xml"):
    with zipfile.ZipFile(path) as zf:
        root = ET.fromstring(zf.read(name))
    for el in root.iter():  # drop the namespace of the openGPS files
        if isinstance(el.tag, str):
            el.tag = el.tag.rsplit("}", 1)[-1]
    return root


def _axis(root, a):
    node = root.find(f"Record1/Axes/{a}")
    return (node.findtext("AxisType").strip(), float(node.findtext("Increment") or 1.0),
            float(node.findtext("Offset") or 0.0))


def test_x3p_point_cloud_reads_its_16_points():
    """Before: an internal error (x3pio 2.0's ``points`` is a method). Truth: main.xml's DataList by
    hand: 16 ``x;y;z`` triples on absolute axes (Increment 1), each + its axis' Offset (0.1, 2, 2 m);
    x3pio's ``points()`` gives the same."""
    p = DATA / "ISO5436-sample2.x3p"
    root = _main_xml(p)
    assert root.findtext("Record1/FeatureType").strip() == "PCL"
    axes = [_axis(root, a) for a in ("CX", "CY", "CZ")]
    assert [t for t, _, _ in axes] == ["A", "A", "A"]
    stored = np.array([[float(v) for v in d.text.split(";")] for d in root.iter("Datum")])
    truth = (stored * [inc for _, inc, _ in axes] + [off for _, _, off in axes]) * 1e3  # m → mm
    assert truth.shape == (16, 3)
    c = read_cloud(p)
    assert c.meta["instrument_format"] == "x3p point cloud" and c.n == 16
    assert np.allclose(c.xyz, truth, rtol=1e-12, atol=0)
    import x3pio

    assert np.allclose(c.xyz, x3pio.read(str(p)).layers[0].points() * 1e3, rtol=1e-12, atol=0)


def test_x3p_absolute_y_axis_uses_the_stored_values():
    """Before: y = Offset + row × Increment = 1, 3, 5, 7 m, as if CY were incremental. Truth (ISO
    25178-72 Amd 1, x3pio): an absolute axis's coordinate is stored value × Increment + Offset — CY
    has Increment 2, Offset 1 and stores 1, 2, 3, 4 → y = 3, 5, 7, 9 m. CX is incremental (Offset +
    column × Increment); CZ absolute (Offset 2). The empty ``<Datum/>`` is a missing point."""
    p = DATA / "ISO5436-sample3.x3p"
    root = _main_xml(p)
    (tx, ix, ox), (ty, iy, oy), (tz, iz, oz) = (_axis(root, a) for a in ("CX", "CY", "CZ"))
    assert (tx, ty, tz, iy, oy) == ("I", "A", "A", 2.0, 1.0)
    data = [d.text for d in root.iter("Datum")]
    assert len(data) == 16 and data.count(None) == 1
    truth = np.array([[ox + (k % 4) * ix, oy + float(t.split(";")[0]) * iy,
                       oz + float(t.split(";")[1]) * iz] for k, t in enumerate(data) if t]) * 1e3
    c = read_cloud(p)
    assert c.n == 15 and c.meta["invalid_dropped"] == 1 and c.meta["grid"] == [4, 4]
    assert sorted(set(c.y.tolist())) == [3000.0, 5000.0, 7000.0, 9000.0]
    assert np.allclose(c.xyz, truth, rtol=1e-12, atol=0)
    assert "pixel_mm" not in c.meta  # the rows need not be evenly spaced along an absolute axis
    import x3pio

    pts = x3pio.read(str(p)).layers[0].points().reshape(-1, 3) * 1e3
    assert np.allclose(c.xyz, pts[np.isfinite(pts).all(axis=1)], rtol=1e-12, atol=0)


def _csafe_by_hand():
    """csafe-logo.x3p: main.xml in csafe-logo/, SizeX × SizeY float64 heights in
    csafe-logo/bindata/data.bin (x fastest), CX/CY incremental."""
    p = DATA / "csafe-logo.x3p"
    root = _main_xml(p, "csafe-logo/main.xml")
    nx, ny = (int(root.findtext(f"Record3/MatrixDimension/{k}")) for k in ("SizeX", "SizeY"))
    link = root.findtext("Record3/DataLink/PointDataLink").strip()
    with zipfile.ZipFile(p) as zf:
        z = np.frombuffer(zf.read("csafe-logo/" + link), "<f8").reshape(ny, nx)
    return nx, ny, _axis(root, "CX")[1], _axis(root, "CY")[1], z


def test_x3p_zipped_with_its_folder_is_read(tmp_path):
    """Before: "not a X3P file … damaged or truncated?". The archive holds csafe-logo/main.xml and
    csafe-logo/bindata/data.bin (x3ptools zipped the folder); the links of main.xml are relative to
    it (x3pio 2.0 reads it so too). Truth: data.bin by hand. Heights: the stored float64 values in
    metres, which the namespace-less reader takes as they are (it scales only integer heights by
    CZ's Increment, here 1e-6; x3pio, with verify=False — the file's main.xml checksum is stale —
    multiplies them too)."""
    nx, ny, dx, dy, z = _csafe_by_hand()
    assert (nx, ny) == (741, 419) and np.isfinite(z).all()
    c = read_cloud(DATA / "csafe-logo.x3p")
    assert c.n == nx * ny and c.meta["grid"] == [nx, ny]
    assert c.meta["pixel_mm"] == pytest.approx([dx * 1e3, dy * 1e3], rel=1e-15)
    assert np.allclose(c.x, c["col"] * dx * 1e3, rtol=1e-12, atol=0)
    assert np.allclose(c.y, c["row"] * dy * 1e3, rtol=1e-12, atol=0)
    assert np.array_equal(c.z, z[c["row"], c["col"]] * 1e3)
    assert "csafe-logo/" in c.meta["instrument_reader"]
    # the same files at the archive's root read the same
    flat = tmp_path / "flat.x3p"
    with zipfile.ZipFile(DATA / "csafe-logo.x3p") as zi, zipfile.ZipFile(flat, "w") as zo:
        for n in zi.namelist():
            if not n.endswith("/"):
                zo.writestr(n.split("/", 1)[1], zi.read(n))
    assert np.array_equal(read_cloud(flat).xyz, c.xyz)


@pytest.mark.parametrize("layout,pattern", [
    ({"a/main.xml", "b/main.xml"}, r"the archive holds main.xml in 2 folders \(a/, b/\), where "
                                   r"ISO 25178-72 puts one main.xml at the archive's root"),
    ({"a/b/main.xml"}, r"main.xml is in folder a/b/ of the archive, where ISO 25178-72 puts it at "
                       r"the root"),
])
def test_x3p_main_xml_where_it_cannot_be_read_is_named(tmp_path, layout, pattern):
    with zipfile.ZipFile(DATA / "csafe-logo.x3p") as zi:
        xml = zi.read("csafe-logo/main.xml")
    p = tmp_path / "odd.x3p"
    with zipfile.ZipFile(p, "w") as zo:
        for name in sorted(layout):
            zo.writestr(name, xml)
    with pytest.raises(InputError, match=r"odd.x3p: not a readable X3P file — " + pattern) as e:
        read_cloud(p)
    _one_line(e, p)
