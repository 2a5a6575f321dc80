"""Which way up an instrument map lies: the first stored line of a Park Systems TIFF, WSxM, FRT
MicroProf, Molecular Imaging and Wyko OPD file is the bottom of the instrument's picture, y = 0 in
PointsPro's y-up frame (docs/formats.md, Pixel convention). SurfaceTopography 1.27 reverses those
lines to look like Gwyddion's y-down rows, and PointsPro put the first line at y max: every such map
mirrored — a freeform's y-odd terms and a correction's side flipped (an independent review,
2026-11-28). Each file's lines are decoded here from its bytes, without SurfaceTopography, and
compared with the cloud gridded by its own x, y coordinates."""
import lzma
import struct
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

DATA = Path(__file__).parent / "data" / "realdata"


def _file(tmp_path, name):
    """The file itself (an .xz one decompressed into tmp_path, keeping its own name)."""
    p = DATA / name
    if p.suffix != ".xz":
        return p
    out = tmp_path / p.stem
    out.write_bytes(lzma.decompress(p.read_bytes()))
    return out


def _gridded(path):
    """PointsPro's map as Z[j, i] at x = i·Δx, y = j·Δy (y up; NaN where no point)."""
    c = read_cloud(path)
    dx, dy = c.meta["pixel_mm"]
    nx, ny = c.meta["grid"]
    i = np.rint(c.x / dx).astype(int)
    j = np.rint(c.y / dy).astype(int)
    z = np.full((ny, nx), np.nan)
    z[j, i] = c.z
    return z


def _corr(a, b):
    m = np.isfinite(a) & np.isfinite(b)
    a, b = a[m] - a[m].mean(), b[m] - b[m].mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


# --- the files' lines by hand (byte layouts as the formats' readers in Gwyddion and SurfaceTopography)
def _mi_lines(path):
    """Molecular Imaging .mi: a text header (14-character keys), then int16/int32 buffers of
    yPixels lines × xPixels points, the first buffer the topography."""
    b = path.read_bytes()
    end = b.index(b"\n", b.index(b"\ndata ") + 1) + 1
    kv = {ln[:14].strip(): ln[14:].strip() for ln in b[:end].decode("latin-1").splitlines()}
    nx, ny = int(kv["xPixels"]), int(kv["yPixels"])
    dt = "<i4" if kv["data"] == "BINARY_32" else "<i2"
    return np.frombuffer(b, dt, count=nx * ny, offset=end).reshape(ny, nx).astype(float)


def _opd_lines(path):
    """Wyko OPD: a directory of 24-byte entries (name 16 s, type u16, size u32, flags u16); the
    raster block holds nx, ny, item size, then nx columns of ny values each (column i, value k)."""
    b = path.read_bytes()
    size = struct.unpack_from("<16sHIH", b, 2)[2]
    entries = [struct.unpack_from("<16sHIH", b, 2 + 24 * k) for k in range(size // 24)]
    off = 2 + size
    for name, typ, sz, _ in entries[1:]:
        if typ == 3 and name.split(b"\0")[0] in (b"RAW DATA", b"RAW_DATA", b"OPD", b"Raw", b"SAMPLE_DATA"):
            nx, ny, item = struct.unpack_from("<3H", b, off)
            a = np.frombuffer(b, {1: "u1", 2: "<i2", 4: "<f4"}[item], count=nx * ny,
                              offset=off + 6).reshape(nx, ny).astype(float).T
            a[a >= 1e10] = np.nan  # the invalid marker
            return a
        off += sz
    raise AssertionError("no raster block")


def _frt_lines(path):
    """FRT MicroProf: tagged blocks (tag u16, size u32 in version 1.00); 0x66 holds nx, ny, bits,
    0x0B the lines; stored values outside 5 … 65529 are invalid (block 0x70)."""
    b = path.read_bytes()
    pos, dims = 18, None
    for _ in range(struct.unpack_from("<H", b, 16)[0]):
        tag, size = struct.unpack_from("<HI", b, pos)
        if tag == 0x66:
            dims = struct.unpack_from("<3I", b, pos + 6)
        if tag == 0x0B:
            nx, ny, _ = dims
            a = np.frombuffer(b, "<u2", count=nx * ny, offset=pos + 6).reshape(ny, nx).astype(float)
            a[(a < 5) | (a > 65529)] = np.nan
            return a
        pos += 6 + size
    raise AssertionError("no data block")


def _wsxm_lines(path):
    """WSxM: a text header of the size it states, then rows × columns values."""
    b = path.read_bytes()
    hs = int(b.split(b"Image header size:")[1].split(b"\n")[0])
    kv = {ln.split(":")[0].strip(): ln.split(":", 1)[1].strip()
          for ln in b[:hs].decode("latin-1").splitlines() if ":" in ln}
    rows, cols = int(kv["Number of rows"]), int(kv["Number of columns"])
    dt = {"double": "<f8", "float": "<f4", "short": "<i2", "integer": "<i4"}[kv["Image Data Type"]]
    return np.frombuffer(b, dt, count=rows * cols, offset=hs).reshape(rows, cols).astype(float)


def _park_lines(path):
    """Park Systems TIFF: the header in tag 50435 (nx, ny after image_type, source_name 64 B,
    image_mode 16 B, lpf_strength d, auto_flatten, ac_track), the lines in tag 50434."""
    b = path.read_bytes()
    assert b[:2] == b"II"
    ifd = struct.unpack_from("<I", b, 4)[0]
    tags = {}
    for k in range(struct.unpack_from("<H", b, ifd)[0]):
        tag, _, cnt, val = struct.unpack_from("<HHII", b, ifd + 2 + 12 * k)
        tags[tag] = (cnt, val)
    hcnt, hoff = tags[50435]
    dcnt, doff = tags[50434]
    nx, ny = struct.unpack_from("<2I", b, hoff + 4 + 64 + 16 + 8 + 4 + 4)
    dt = {2: "<i2", 4: "<f4"}[dcnt // (nx * ny)]
    return np.frombuffer(b, dt, count=nx * ny, offset=doff).reshape(ny, nx).astype(float)


CASES = [  # file, its lines by hand, x reversed in the file (WSxM stores its map turned by 180°)
    ("mi-1.mi", _mi_lines, False),
    ("opd-1.opd", _opd_lines, False),
    ("frt-1.frt.xz", _frt_lines, False),
    ("top-1.top.xz", _wsxm_lines, True),
    ("example_ps.tiff.xz", _park_lines, False),
]


@pytest.mark.parametrize("name,lines,x_reversed", CASES, ids=[c[0] for c in CASES])
def test_the_first_stored_line_lies_at_y_zero(tmp_path, name, lines, x_reversed):
    path = _file(tmp_path, name)
    z = _gridded(path)
    raw = lines(path)
    if x_reversed:
        raw = raw[:, ::-1]
    assert raw.shape == z.shape
    # Park's data gain is negative: the sign of the correlation is the file's, its size the match
    as_stored, mirrored = abs(_corr(raw, z)), abs(_corr(raw[::-1], z))
    assert as_stored > 0.999999, (as_stored, mirrored)
    assert mirrored < 0.995, (as_stored, mirrored)


def test_a_zygo_maps_first_stored_row_is_the_top_of_its_picture():
    """MetroPro: "(0,0) is in the upper left corner of the video monitor" (MetroPro Reference Guide);
    prysm turns .dat and .datx so that y increases upward. The first stored row lies at y max."""
    b = (DATA / "metropro-1.dat").read_bytes()
    header = struct.unpack_from(">I", b, 6)[0]
    ac_w, ac_h, ac_n = struct.unpack_from(">3H", b, 52)
    w, h = struct.unpack_from(">2H", b, 68)
    raw = np.frombuffer(b, ">i4", count=w * h, offset=header + 2 * ac_n * ac_w * ac_h).reshape(h, w)
    raw = np.where(raw >= 2147483640, np.nan, raw.astype(float))
    z = _gridded(DATA / "metropro-1.dat")
    # a map that is mostly tilt correlates 0.995 either way up: the form (a plane removed) decides
    yy, xx = np.mgrid[0:h, 0:w]

    def less_plane(a):
        m = np.isfinite(a)
        design = np.column_stack([np.ones(m.sum()), xx[m], yy[m]])
        out = np.full(a.shape, np.nan)
        out[m] = a[m] - design @ np.linalg.lstsq(design, a[m], rcond=None)[0]
        return out

    top_first = abs(_corr(less_plane(raw[::-1]), less_plane(z)))
    as_stored = abs(_corr(less_plane(raw), less_plane(z)))
    assert top_first > 0.999999 and as_stored < 0.99, (top_first, as_stored)


def test_a_park_file_with_swapped_axes_is_refused_by_name(tmp_path):
    """swap_xy ≠ 0 (the fast axis along y): SurfaceTopography 1.27 reads its lines as x lines and
    Gwyddion turns them by 90°; not read rather than read turned."""
    src = _file(tmp_path, "example_ps.tiff.xz")
    b = bytearray(src.read_bytes())
    ifd = struct.unpack_from("<I", b, 4)[0]
    tags = {}
    for k in range(struct.unpack_from("<H", b, ifd)[0]):
        tag, _, cnt, val = struct.unpack_from("<HHII", b, ifd + 2 + 12 * k)
        tags[tag] = (cnt, val)
    hoff = tags[50435][1]
    # … nx I, ny I, angle d, sine_scan I, overscan_rate d, forward I, scan_up I, swap_xy I
    at = hoff + 4 + 64 + 16 + 8 + 4 + 4 + 8 + 8 + 4 + 8 + 4 + 4
    assert struct.unpack_from("<I", b, at)[0] == 0
    struct.pack_into("<I", b, at, 1)
    p = tmp_path / "swapped.tiff"
    p.write_bytes(bytes(b))
    with pytest.raises(InputError, match="swap_xy = 1") as e:
        read_cloud(p)
    assert str(p) in str(e.value)
