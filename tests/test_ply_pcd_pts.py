"""PLY, PCD and PTS: read by our own numpy readers (core.io.ply, core.io.pcd) that check every count,
size and number, and the PLY writer's integer types.

Each damaged file must give one InputError naming the file (and the line or element) — never points
silently dropped, zeros, or uninitialised memory (what open3d returned for these files) — and each
valid file exactly its numbers.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.cloud import PointCloud
from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud, write_cloud
from pointspro.core.io.pcd import lzf_decompress

RNG = np.random.default_rng(11)
XYZ = RNG.uniform(-5, 5, (100, 3)).round(9)
FACES = [[0, 1, 2], [2, 3, 4], [5, 6, 7]]
D3 = [("double", "x"), ("double", "y"), ("double", "z")]
NP = {"double": "f8", "float": "f4", "uchar": "u1", "int": "i4", "uint": "u4", "short": "i2"}


# --- PLY -----------------------------------------------------------------------------------------
def ply_header(fmt, n, props=D3, faces=None, face_first=False, extra=()):
    ve = [f"element vertex {n}"] + [f"property {t} {p}" for t, p in props] + list(extra)
    fe = ([f"element face {faces}", "property list uchar int vertex_indices"]
          if faces is not None else [])
    lines = ["ply", f"format {fmt} 1.0", *(fe + ve if face_first else ve + fe), "end_header"]
    return ("\n".join(lines) + "\n").encode("ascii")


def ply_body(data, props=D3, order="<"):
    a = np.empty(len(data), np.dtype([(p, order + NP[t]) for t, p in props]))
    for j, (_, p) in enumerate(props):
        a[p] = data[:, j]
    return a.tobytes()


def face_bytes(faces, order="<"):
    return b"".join(struct.pack(order + "B" + "i" * len(f), len(f), *f) for f in faces)


def ascii_rows(data):
    return ("\n".join(" ".join(repr(float(v)) for v in r) for r in data) + "\n").encode()


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_ply_header_declaring_fewer_vertices_than_the_file_holds(tmp_path, fmt):
    body = ply_body(XYZ) if fmt != "ascii" else ascii_rows(XYZ)
    p = tmp_path / "fewer.ply"
    p.write_bytes(ply_header(fmt, 90) + body)
    with pytest.raises(InputError, match=r"fewer\.ply: the PLY header declares 90 vertices but the "
                                         r"file holds more data \("):
        read_cloud(p)
    # exactly right: read; ascii may end with blank lines
    p.write_bytes(ply_header(fmt, 100) + body + (b"\n\n  \n" if fmt == "ascii" else b""))
    assert np.array_equal(read_cloud(p).xyz, XYZ)


def test_ply_counts_checked_against_the_elements_after_the_vertices(tmp_path):
    p = tmp_path / "f.ply"
    # binary float vertices then triangles: exact
    f3 = [("float", "x"), ("float", "y"), ("float", "z")]
    good = ply_header("binary_little_endian", 100, f3, 3) + ply_body(XYZ, f3) + face_bytes(FACES)
    p.write_bytes(good)
    assert np.array_equal(read_cloud(p).xyz, XYZ.astype(np.float32).astype(np.float64))
    # mixed triangles and a quad (lists of varying length): walked item by item
    p.write_bytes(ply_header("binary_little_endian", 100, f3, 4) + ply_body(XYZ, f3)
                  + face_bytes(FACES + [[1, 2, 3, 4]]))
    assert read_cloud(p).n == 100
    # bytes after the last face
    p.write_bytes(good + b"\0" * 7)
    with pytest.raises(InputError, match=r"declares 100 vertices but the file holds more data \(7 "
                                         r"bytes after the last declared element, 'face'\)"):
        read_cloud(p)
    # one vertex too many in the header: the faces, shifted, no longer add up
    p.write_bytes(ply_header("binary_little_endian", 101, f3, 3) + ply_body(XYZ, f3)
                  + face_bytes(FACES))
    with pytest.raises(InputError, match=r"f\.ply: PLY face 0 lists 0 vertex indices.*does not "
                                         "match its header"):
        read_cloud(p)
    # too few faces in the file
    p.write_bytes(ply_header("binary_little_endian", 100, f3, 5) + ply_body(XYZ, f3)
                  + face_bytes(FACES))
    with pytest.raises(InputError, match=r"f\.ply: PLY file is truncated or its header is wrong: "
                                         r"element 'face' 3 of 5"):
        read_cloud(p)
    # ascii: the face lines counted
    faces_txt = "".join("3 " + " ".join(map(str, f)) + "\n" for f in FACES).encode()
    p.write_bytes(ply_header("ascii", 100, D3, 3) + ascii_rows(XYZ) + faces_txt)
    assert np.array_equal(read_cloud(p).xyz, XYZ)
    p.write_bytes(ply_header("ascii", 97, D3, 3) + ascii_rows(XYZ) + faces_txt)
    with pytest.raises(InputError, match=r"declares 97 vertices but the file holds more data "
                                         r"\(line 110: '3 0 1 2' after the 3 lines of 'face'\)"):
        read_cloud(p)
    p.write_bytes(ply_header("ascii", 100, D3, 4) + ascii_rows(XYZ) + faces_txt)
    with pytest.raises(InputError, match=r"truncated: element 'face' has 3 of the 4 lines"):
        read_cloud(p)


def test_ply_face_element_first_keeps_exactly_the_declared_properties(tmp_path):
    props = [("float", "x"), ("float", "y"), ("float", "z"), ("uchar", "red"),
             ("double", "quality"), ("uint", "id")]
    red = RNG.integers(0, 256, 100)
    quality = RNG.uniform(0, 1, 100)
    ids = np.arange(100) + 3_000_000_000
    data = np.column_stack([XYZ, red, quality, ids])
    p = tmp_path / "ff.ply"
    p.write_bytes(ply_header("binary_little_endian", 100, props, 3, face_first=True)
                  + face_bytes(FACES) + ply_body(data, props))
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ.astype(np.float32).astype(np.float64))
    assert set(c.channels) == {"index", "red", "quality", "id"}  # no invented green/blue
    assert c["red"].dtype == np.int64 and np.array_equal(c["red"], red)
    assert np.array_equal(c["quality"], quality) and np.array_equal(c["id"], ids)
    # truncated inside the vertices, which come last
    raw = p.read_bytes()
    p.write_bytes(raw[:-200])
    with pytest.raises(InputError, match=r"ff\.ply: PLY file is truncated or its header is wrong: "
                                         r"element 'vertex' \d+ of 100 runs past the end"):
        read_cloud(p)


def test_ply_vertex_list_property(tmp_path):
    head = ply_header("binary_little_endian", 100, extra=["property list uchar int nbrs",
                                                          "property float w"])
    w = RNG.uniform(0, 1, 100).astype(np.float32)
    # one list length for all (a strided view), then varying lengths (item by item)
    for lengths in ([1] * 100, [i % 4 for i in range(100)]):
        body = b"".join(struct.pack("<3dB", *r, k) + struct.pack(f"<{k}i", *range(k))
                        + struct.pack("<f", wi) for r, k, wi in zip(XYZ, lengths, w))
        p = tmp_path / "vl.ply"
        p.write_bytes(head + body)
        c = read_cloud(p)
        assert np.array_equal(c.xyz, XYZ) and np.array_equal(c["w"], w.astype(np.float64))
        assert "nbrs" not in c.channels
        p.write_bytes(head + body[:-300])
        with pytest.raises(InputError, match=r"vl\.ply: PLY file is truncated or its header is "
                                             r"wrong: element 'vertex' \d+ of 100"):
            read_cloud(p)
    # ascii
    rows = "".join(f"{a!r} {b!r} {c!r} 2 7 8 0.5\n" for a, b, c in XYZ.tolist())
    p.write_bytes(ply_header("ascii", 100, extra=["property list uchar int nbrs",
                                                  "property float w"]) + rows.encode())
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ) and np.all(c["w"] == 0.5)


def test_ply_ascii_damage_is_named_by_line(tmp_path):
    p = tmp_path / "a.ply"
    raw = ply_header("ascii", 100) + ascii_rows(XYZ)
    p.write_bytes(raw[:raw.index(b" ", len(raw) // 2)])
    with pytest.raises(InputError, match=r"a\.ply, line \d+: the file is truncated: vertex \d+ "
                                         r"holds \d of its 3 values"):
        read_cloud(p)
    lines = raw.decode().splitlines()
    lines[20] = "1.0 abc 2.0"  # line 21 of the file
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"a\.ply, line 21: 'abc' is not a number \(vertex 13\)"):
        read_cloud(p)
    p.write_bytes(ply_header("ascii", 2, [("double", "x"), ("double", "y"), ("double", "z"),
                                          ("uchar", "red")]) + b"1 2 3 255\n4 5 6 300\n")
    with pytest.raises(InputError, match=r"vertex 1: property 'red' is declared uchar but holds 300"):
        read_cloud(p)


def test_ply_big_endian_and_integers(tmp_path):
    props = [("double", "x"), ("double", "y"), ("double", "z"), ("short", "s"), ("uint", "u")]
    data = np.column_stack([XYZ, np.arange(100) - 50, np.arange(100) + 4_000_000_000])
    p = tmp_path / "be.ply"
    p.write_bytes(ply_header("binary_big_endian", 100, props) + ply_body(data, props, ">"))
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ)
    assert c["s"].tolist() == list(range(-50, 50))
    assert c["u"].tolist() == list(range(4_000_000_000, 4_000_000_100))


# --- PLY writer ----------------------------------------------------------------------------------
def _wide_cloud(n=50):
    xyz = RNG.normal(size=(n, 3))
    return PointCloud(xyz, {"id": np.arange(n) + 3_000_000_000, "line": np.full(n, 5_000_000_000),
                            "neg": -3_000_000_000 - np.arange(n), "small": np.arange(n) - 7,
                            "near53": np.arange(n) + (2**53 - n), "residual": RNG.normal(size=n)})


def test_ply_writer_keeps_large_integer_channels(tmp_path):
    c = _wide_cloud()
    p = tmp_path / "w.ply"
    write_cloud(c, p)
    header = p.read_bytes().split(b"end_header")[0].decode()
    assert "property uint id" in header and "property int small" in header
    assert "property double line" in header and "comment pointspro int64 line neg near53" in header
    back = read_cloud(p)
    assert back.equals(c)
    for name in c.channels:
        assert back[name].dtype == c[name].dtype, name
    assert back["id"][0] == 3_000_000_000 and back["line"][0] == 5_000_000_000
    assert back["near53"][-1] == 2**53 - 1


def test_ply_writer_refuses_integers_beyond_2_53(tmp_path):
    c = PointCloud(np.zeros((2, 3)), {"big": np.array([0, 2**53 + 1])})
    with pytest.raises(InputError, match=r"x\.ply: channel 'big' holds whole numbers up to "
                                         r"9007199254740993, beyond ±2\^53"):
        write_cloud(c, tmp_path / "x.ply")
    assert not list(tmp_path.iterdir())  # nothing left behind


def test_batch_cloud_format_ply_round_trip_of_large_integers(run_cli, tmp_path):
    n = 400
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-10, 10, n), rng.uniform(-10, 10, n)
    z = 1e-3 * (x**2 + y**2) / 100
    rows = [f"{a!r},{b!r},{c!r},{3_000_000_000 + 2 * i},{5_000_000_000 + i}"
            for i, (a, b, c) in enumerate(zip(x.tolist(), y.tolist(), z.tolist()))]
    src = tmp_path / "big.csv"
    src.write_text("x,y,z,index,line\n" + "\n".join(rows) + "\n", encoding="utf-8")
    recipe = tmp_path / "r.yaml"
    recipe.write_text("pointspro: 1\nsteps:\n  - aperture: {diameter: 15}\n", encoding="utf-8")
    code, _, err = run_cli("--batch", recipe, src, "--out", tmp_path / "o", "--quiet",
                           "--cloud-format", "ply", "--figures", "none")
    assert code == 0, err
    back = read_cloud(tmp_path / "o" / "big" / "cloud.ply")
    ref = read_cloud(src)
    assert 0 < back.n < n
    rows_of = {int(v): i for i, v in enumerate(ref["index"])}
    sel = np.array([rows_of[int(v)] for v in back["index"]])
    assert back["index"].dtype == np.int64 and back["line"].dtype == np.int64
    assert np.array_equal(back["line"], ref["line"][sel])
    assert np.array_equal(back.xyz, ref.xyz[sel])
    assert back["index"].min() >= 3_000_000_000 and back["line"].min() >= 5_000_000_000


# --- PCD -----------------------------------------------------------------------------------------
def pcd_header(fields, sizes, types, counts, n, data, width=None):
    return (f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {' '.join(fields)}\n"
            f"SIZE {' '.join(map(str, sizes))}\nTYPE {' '.join(types)}\n"
            f"COUNT {' '.join(map(str, counts))}\nWIDTH {width or n}\nHEIGHT 1\n"
            f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n").encode("ascii")


def xyz_pcd(n, data, dtype="F", size=8):
    return pcd_header("xyz", [size] * 3, [dtype] * 3, [1] * 3, n, data)


def test_pcd_binary_doubles_read_exactly(tmp_path):
    p = tmp_path / "d.pcd"
    p.write_bytes(xyz_pcd(100, "binary") + XYZ.astype("<f8").tobytes())
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ) and c.meta["format"] == "pcd"
    assert set(c.channels) == {"index"}
    p.write_bytes(xyz_pcd(100, "binary") + XYZ.astype("<f8").tobytes()[:-300])
    with pytest.raises(InputError, match=r"d\.pcd: PCD file is truncated \(2100 of the 2400 bytes"):
        read_cloud(p)
    p.write_bytes(xyz_pcd(90, "binary") + XYZ.astype("<f8").tobytes())
    with pytest.raises(InputError, match=r"d\.pcd: the PCD header declares 90 points but the file "
                                         r"holds more data \(240 bytes after them"):
        read_cloud(p)


def test_pcd_binary_mixed_fields(tmp_path):
    n = 100
    names = ["x", "y", "z", "_", "normal_x", "normal_y", "normal_z", "rgb", "intensity", "label",
             "ring", "hist"]
    sizes = [4, 4, 4, 4, 4, 4, 4, 4, 8, 4, 2, 4]
    types = ["F", "F", "F", "U", "F", "F", "F", "F", "F", "U", "I", "F"]
    counts = [1] * 11 + [3]
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("pad", "<u4"), ("nx", "<f4"),
                   ("ny", "<f4"), ("nz", "<f4"), ("rgb", "<u4"), ("intensity", "<f8"),
                   ("label", "<u4"), ("ring", "<i2"), ("hist", "<f4", (3,))])
    a = np.zeros(n, dt)
    for j, k in enumerate("xyz"):
        a[k] = XYZ[:, j]
    a["nz"] = 1.0
    r, g, b = RNG.integers(0, 256, (3, n))
    a["rgb"] = (r << 16) | (g << 8) | b
    a["intensity"] = RNG.uniform(0, 1, n)
    a["label"] = np.arange(n) + 4_000_000_000
    a["ring"] = np.arange(n) - 50
    rgb_as_float = a.copy()  # PCL's rgb: the packed integer's bits in a float field
    p = tmp_path / "m.pcd"
    p.write_bytes(pcd_header(names, sizes, types, counts, n, "binary") + rgb_as_float.tobytes())
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ.astype(np.float32).astype(np.float64))
    assert set(c.channels) == {"index", "nx", "ny", "nz", "red", "green", "blue", "intensity",
                               "label", "ring"}
    assert np.array_equal(c["red"], r) and np.array_equal(c["green"], g)
    assert np.array_equal(c["blue"], b) and np.array_equal(c["nz"], np.ones(n))
    assert np.array_equal(c["intensity"], a["intensity"])
    assert c["label"].tolist() == list(range(4_000_000_000, 4_000_000_100))
    assert c["ring"].tolist() == list(range(-50, 50))


@pytest.mark.parametrize("size", [4, 8])
def test_pcd_ascii(tmp_path, size):
    p = tmp_path / "a.pcd"
    text = ascii_rows(XYZ)
    p.write_bytes(xyz_pcd(100, "ascii", size=size) + text)
    assert np.array_equal(read_cloud(p).xyz, XYZ)
    p.write_bytes(xyz_pcd(100, "ascii") + text[:text.index(b" ", len(text) // 2)])
    with pytest.raises(InputError, match=r"a\.pcd, line \d+: the file is truncated: point \d+ holds "
                                         r"\d of its 3 values \(the header declares 100 points\)"):
        read_cloud(p)
    p.write_bytes(xyz_pcd(100, "ascii") + text[:text.index(b"\n", len(text) // 2) + 1])
    with pytest.raises(InputError, match=r"a\.pcd: the file is truncated: the header declares 100 "
                                         r"points, the file holds \d+"):
        read_cloud(p)
    p.write_bytes(xyz_pcd(90, "ascii") + text)
    with pytest.raises(InputError, match=r"a\.pcd: the PCD header declares 90 points but the file "
                                         r"holds more data \(line 102: "):
        read_cloud(p)
    lines = text.decode().splitlines()
    lines[5] = "1.0 abc 2.0"
    p.write_bytes(xyz_pcd(100, "ascii") + ("\n".join(lines) + "\n").encode())
    with pytest.raises(InputError, match=r"a\.pcd, line 17: 'abc' is not a number \(point 5\)"):
        read_cloud(p)
    # PCL writes a packed colour as an integer even in a TYPE F field
    head = pcd_header(["x", "y", "z", "rgb"], [4, 4, 4, 4], ["F", "F", "F", "F"], [1] * 4, 2, "ascii")
    p.write_bytes(head + b"1 2 3 16744448\n4 5 6 255\n")
    c = read_cloud(p)
    assert c["red"].tolist() == [255, 0] and c["green"].tolist() == [128, 0]
    assert c["blue"].tolist() == [0, 255]


def lzf_literals(raw: bytes) -> bytes:
    """An LZF stream of literal runs only (valid, if not compressed)."""
    return b"".join(bytes([len(raw[i:i + 32]) - 1]) + raw[i:i + 32] for i in range(0, len(raw), 32))


def test_lzf_decompress_back_references():
    assert lzf_decompress(b"\x01ab\x80\x01", 8) == b"abababab"  # overlapping copy
    # a long reference (length 7 + 3 + 2 = 12) to 4 bytes back
    assert lzf_decompress(b"\x03abcd\xe0\x03\x03", 16) == b"abcd" * 4
    assert lzf_decompress(b"\x01ab\x80\x05", 8) is None  # refers before the start
    assert lzf_decompress(b"\x05ab", 6) is None  # literal run past the end
    assert lzf_decompress(b"\x01ab", 3) is None  # short of the stated size


def test_pcd_binary_compressed(tmp_path):
    n = 100
    cols = np.concatenate([XYZ[:, 0], XYZ[:, 1], XYZ[:, 2]]).astype("<f8").tobytes()
    comp = lzf_literals(cols)
    p = tmp_path / "c.pcd"
    head = xyz_pcd(n, "binary_compressed")
    p.write_bytes(head + struct.pack("<II", len(comp), len(cols)) + comp)
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ) and c.meta["pcd_data"] == "binary_compressed"
    p.write_bytes(head + struct.pack("<II", len(comp), len(cols)) + comp[:-10])
    with pytest.raises(InputError, match=r"c\.pcd: PCD file is truncated"):
        read_cloud(p)
    p.write_bytes(head + struct.pack("<II", len(comp), len(cols) - 24) + comp)
    with pytest.raises(InputError, match=r"c\.pcd: PCD compressed data unpack to 2376 bytes"):
        read_cloud(p)
    bad = bytearray(comp)
    bad[0] = 0x9F  # a back reference before the start
    p.write_bytes(head + struct.pack("<II", len(comp), len(cols)) + bytes(bad))
    with pytest.raises(InputError, match=r"c\.pcd: the PCD's compressed point data are damaged"):
        read_cloud(p)


def test_pcd_binary_compressed_zero_padding_after_the_points(tmp_path):
    """PCL's writer leaves zero bytes after the compressed block: accepted; other bytes there are
    more data than the header declares, and refused."""
    cols = np.concatenate([XYZ[:, 0], XYZ[:, 1], XYZ[:, 2]]).astype("<f8").tobytes()
    comp = lzf_literals(cols)
    body = xyz_pcd(100, "binary_compressed") + struct.pack("<II", len(comp), len(cols)) + comp
    p = tmp_path / "c.pcd"
    p.write_bytes(body + bytes(3913))
    assert np.array_equal(read_cloud(p).xyz, XYZ)
    p.write_bytes(body + bytes(3000) + b"\x01" + bytes(912))
    with pytest.raises(InputError, match=r"c\.pcd: the PCD header declares 100 points but the file "
                                         r"holds more data \(3913 bytes after the compressed points, "
                                         r"not all zero\)"):
        read_cloud(p)


def test_pcd_real_pcl_file_binary_compressed_reads_as_open3d_reads_it(tmp_path):
    """PCL's test/car6.pcd (BSD-3, LICENSE-PCL.txt beside it): binary_compressed x y z, 10031
    points, 3913 zero bytes after the compressed block (PCL's writer pads the file)."""
    o3d = pytest.importorskip("open3d")
    real = Path(__file__).parent / "data" / "realdata"
    path = real / "pcl_car6.pcd"
    data = path.read_bytes()
    start = data.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    csize, _ = struct.unpack("<II", data[start:start + 8])
    assert len(data) - start - 8 - csize == 3913 and not any(data[start + 8 + csize:])
    c = read_cloud(path)
    ref = np.asarray(o3d.io.read_point_cloud(str(path)).points)
    assert c.n == len(ref) == 10031 and c.meta["pcd_data"] == "binary_compressed"
    assert np.array_equal(c.xyz, ref)
    assert (real / "LICENSE-PCL.txt").read_text(encoding="utf-8").startswith(
        "Software License Agreement (BSD License)")
    (tmp_path / "tail.pcd").write_bytes(data[:-1] + b"\x07")
    with pytest.raises(InputError, match=r"tail\.pcd: .*3913 bytes after the compressed points, not all"):
        read_cloud(tmp_path / "tail.pcd")


def test_pcd_written_by_open3d_reads_as_open3d_reads_it(tmp_path):
    o3d = pytest.importorskip("open3d")
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(XYZ))
    normals = RNG.normal(size=(100, 3))
    pc.normals = o3d.utility.Vector3dVector(normals / np.linalg.norm(normals, axis=1)[:, None])
    pc.colors = o3d.utility.Vector3dVector(RNG.integers(0, 256, (100, 3)) / 255.0)
    for i, kw in enumerate([{}, {"write_ascii": True}, {"compressed": True}]):
        p = tmp_path / f"o{i}.pcd"
        assert o3d.io.write_point_cloud(str(p), pc, **kw)
        ref = o3d.io.read_point_cloud(str(p))
        c = read_cloud(p)
        assert np.array_equal(c.xyz, np.asarray(ref.points))
        assert np.array_equal(np.column_stack([c["nx"], c["ny"], c["nz"]]), np.asarray(ref.normals))
        assert np.array_equal(np.column_stack([c["red"], c["green"], c["blue"]]),
                              np.rint(np.asarray(ref.colors) * 255))


def test_pcd_invalid_points_and_header_errors(tmp_path):
    p = tmp_path / "h.pcd"
    xyz = XYZ.copy()
    xyz[[3, 7], 2] = np.nan  # an organised cloud's missing pixels
    p.write_bytes(xyz_pcd(100, "binary") + xyz.astype("<f8").tobytes())
    c = read_cloud(p)
    assert c.n == 98 and c.meta["invalid_dropped"] == 2
    assert np.array_equal(c["index"], np.delete(np.arange(100), [3, 7]))
    with pytest.raises(InputError, match=r"h\.pcd: point 3 has a NaN/inf coordinate"):
        read_cloud(p, invalid="error")
    cases = [
        (xyz_pcd(100, "binary").replace(b"WIDTH 100", b"WIDTH 90"), r"POINTS 100 is not WIDTH × HEIGHT"),
        (xyz_pcd(100, "binary", size=3), r"field 'x' of TYPE F cannot have SIZE 3"),
        (xyz_pcd(100, "binary").replace(b"FIELDS x y z", b"FIELDS x y w"), r"no 'z' field"),
        (xyz_pcd(100, "zip"), r"DATA is one of ascii, binary, binary_compressed"),
        (xyz_pcd(100, "binary").replace(b"SIZE 8 8 8", b"SIZE 8 8"), r"SIZE needs 3 whole numbers"),
    ]
    for head, msg in cases:
        p.write_bytes(head + XYZ.astype("<f8").tobytes())
        with pytest.raises(InputError, match=r"h\.pcd: .*" + msg):
            read_cloud(p)
    p.write_bytes(b"1 2 3\n4 5 6\n")
    with pytest.raises(InputError, match=r"h\.pcd: no points read — not a PCD file"):
        read_cloud(p)


def test_pcd_is_told_by_content(tmp_path):
    p = tmp_path / "renamed.txt"
    p.write_bytes(xyz_pcd(100, "ascii") + ascii_rows(XYZ))
    c = read_cloud(p)
    assert c.meta["format"] == "pcd" and np.array_equal(c.xyz, XYZ)


# --- PTS -----------------------------------------------------------------------------------------
def pts_text(count, data, fmt=repr):
    return f"{count}\n" + "".join(" ".join(fmt(v) for v in r) + "\n" for r in data)


def test_pts_columns(tmp_path):
    p = tmp_path / "s.pts"
    p.write_text(pts_text(100, XYZ.tolist()))
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ) and c.meta["format"] == "pts" and set(c.channels) == {"index"}
    inten = RNG.integers(-2048, 2048, 100)
    rgb = RNG.integers(0, 256, (100, 3))
    p.write_text(pts_text(100, np.column_stack([XYZ, inten, rgb]).tolist(),
                          fmt=lambda v: repr(v) if v != int(v) else str(int(v))))
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ) and np.array_equal(c["intensity"], inten)
    assert c["red"].dtype == np.int64 and np.array_equal(c["blue"], rgb[:, 2])
    p.write_text(pts_text(100, np.column_stack([XYZ, rgb]).tolist()))
    assert np.array_equal(read_cloud(p)["green"], rgb[:, 1])
    # two scans, each with its count
    p.write_text(pts_text(60, XYZ[:60].tolist()) + pts_text(40, XYZ[60:].tolist()))
    c = read_cloud(p)
    assert np.array_equal(c.xyz, XYZ) and c["scan"].tolist() == [0] * 60 + [1] * 40


def test_pts_damage(tmp_path):
    p = tmp_path / "d.pts"
    p.write_text(pts_text(150, XYZ.tolist()))
    with pytest.raises(InputError, match=r"d\.pts: the file is truncated: line 1 declares 150 "
                                         r"points, the file holds 100"):
        read_cloud(p)
    p.write_text(pts_text(50, XYZ.tolist()))
    with pytest.raises(InputError, match=r"d\.pts: line 1 declares 50 points but the file holds more "
                                         r"rows \(line 52: "):
        read_cloud(p)
    rows = pts_text(100, XYZ.tolist()).splitlines()
    rows[41] = "1.0 abc 2.0"
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match=r"d\.pts, line 42: 'abc' is not a number \(point 40\)"):
        read_cloud(p)
    rows[41] = "1.0 2.0"
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match=r"d\.pts, line 42: point 40 holds 2 values where 3 are "
                                         r"expected \(x y z\)"):
        read_cloud(p)
    p.write_text("".join(f"{a} {b} {c}\n" for a, b, c in XYZ))
    with pytest.raises(InputError, match=r"d\.pts, line 1: a PTS file starts with its number of "
                                         "points"):
        read_cloud(p)
    p.write_text("2\n1 2 3 4 5\n1 2 3 4 5\n")
    with pytest.raises(InputError, match=r"d\.pts, line 2: a PTS row is x y z, .* this one has 5"):
        read_cloud(p)
    p.write_text("2\n1 2 3 0 0 1.5\n1 2 3 0 0 1\n")
    with pytest.raises(InputError, match=r"d\.pts: point 0: the colour blue is 1.5, not a whole"):
        read_cloud(p)
