"""LAS / LAZ (laspy + lazrs) and E57 (pye57) point clouds: the optional `scanners` extra
(core/io/las.py, core/io/e57.py). Each file is written here with the library itself and read back;
coordinates in metres become mm."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

laspy = pytest.importorskip("laspy")
pye57 = pytest.importorskip("pye57")


def _points(n=200, seed=11):
    rng = np.random.default_rng(seed)
    return rng.uniform([-2.0, -1.5, -0.1], [2.0, 1.5, 0.1], size=(n, 3)), rng


def _las(path, n=200, seed=11, geokeys=None):
    xyz, rng = _points(n, seed)
    h = laspy.LasHeader(point_format=3, version="1.2")
    h.scales = np.array([1e-4, 1e-4, 1e-5])
    h.offsets = np.array([100.0, -20.0, 0.5])
    if geokeys is not None:
        vlr = laspy.vlrs.known.GeoKeyDirectoryVlr()
        vlr.geo_keys_header.key_directory_version = 1
        vlr.geo_keys_header.number_of_keys = len(geokeys)
        vlr.geo_keys = []
        for key, value in geokeys:
            e = laspy.vlrs.known.GeoKeyEntryStruct()
            e.id, e.tiff_tag_location, e.count, e.value_offset = key, 0, 1, value
            vlr.geo_keys.append(e)
        h.vlrs.append(vlr)
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz[:, 0] + 100.0, xyz[:, 1] - 20.0, xyz[:, 2] + 0.5
    las.intensity = rng.integers(0, 65535, n).astype(np.uint16)
    las.classification = np.where(np.arange(n) % 3 == 0, 2, 6).astype(np.uint8)
    las.red = rng.integers(0, 65535, n).astype(np.uint16)
    las.green = rng.integers(0, 65535, n).astype(np.uint16)
    las.blue = rng.integers(0, 65535, n).astype(np.uint16)
    las.gps_time = np.linspace(1000.0, 1001.0, n)
    las.return_number = np.ones(n, np.uint8)
    las.number_of_returns = np.ones(n, np.uint8)
    las.write(str(path))
    return laspy.read(str(path))  # the stored (quantised) values, as any reader sees them


@pytest.mark.parametrize("name", ["scan.las", "scan.laz", "scan_laz_named.bin"])
def test_las_and_laz_read_in_mm_with_channels(tmp_path, name):
    if name.endswith(".bin"):  # a LAZ named otherwise: chosen by content (b"LASF")
        src = _las(tmp_path / "x.laz")
        (tmp_path / name).write_bytes((tmp_path / "x.laz").read_bytes())
    else:
        src = _las(tmp_path / name)
    c = read_cloud(tmp_path / name)
    assert c.xyz.dtype == np.float64
    assert np.array_equal(c.x, np.asarray(src.x) * 1e3) and np.array_equal(c.z, np.asarray(src.z) * 1e3)
    assert np.array_equal(c.y, np.asarray(src.y) * 1e3)
    assert np.allclose(c.x / 1e3 - 100.0, _points()[0][:, 0], atol=1e-4)  # metres → mm, scale+offset
    assert np.array_equal(c["intensity"], np.asarray(src.intensity))
    assert np.array_equal(c["classification"], np.asarray(src.classification))
    assert np.array_equal(c["red"], np.asarray(src.red)) and np.array_equal(c["gps_time"], src.gps_time)
    assert {"return_number", "number_of_returns"} <= set(c.channels)
    assert "user_data" not in c.channels  # zero everywhere: left out
    assert np.array_equal(c.index, np.arange(200))
    assert c.meta["format"] == ("laz" if "laz" in name else "las")
    assert c.meta["instrument_unit"] == "m (assumed: the file states no unit)"


def test_las_in_us_survey_feet(tmp_path):
    src = _las(tmp_path / "ft.las", geokeys=[(3076, 9003), (4099, 9001)])
    c = read_cloud(tmp_path / "ft.las")
    assert np.allclose(c.x, np.asarray(src.x) * 1200 / 3937 * 1e3, rtol=1e-15)
    assert np.array_equal(c.z, np.asarray(src.z) * 1e3)
    assert c.meta["instrument_unit"] == "US survey ft (x, y), m (z)"


def test_las_truncated_is_named(tmp_path):
    _las(tmp_path / "a.las")
    data = (tmp_path / "a.las").read_bytes()
    (tmp_path / "cut.las").write_bytes(data[:150])
    with pytest.raises(InputError, match=r"cut.las: a damaged or truncated LAS/LAZ file"):
        read_cloud(tmp_path / "cut.las")


def _e57(path, scans):
    with pye57.E57(str(path), mode="w") as e:
        for data, kw in scans:
            e.write_scan_raw(data, **kw)


def test_e57_two_scans_in_mm_with_pose_and_invalid_points(tmp_path):
    xyz, rng = _points(120, seed=5)
    n = len(xyz)
    inv = np.zeros(n, np.int8)
    inv[[3, 50]] = 1
    a = {"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1], "cartesianZ": xyz[:, 2],
         "intensity": rng.random(n), "colorRed": rng.integers(0, 255, n).astype(np.uint8),
         "colorGreen": rng.integers(0, 255, n).astype(np.uint8),
         "colorBlue": rng.integers(0, 255, n).astype(np.uint8), "cartesianInvalidState": inv}
    b = {k: v[:40].copy() for k, v in a.items()}
    b["cartesianInvalidState"] = np.zeros(40, np.int8)
    _e57(tmp_path / "s.e57", [(a, {}), (b, {"translation": np.array([10.0, 0.0, 0.0]),
                                            "rotation": np.array([1.0, 0.0, 0.0, 0.0])})])
    c = read_cloud(tmp_path / "s.e57")
    keep = inv == 0
    assert c.n == keep.sum() + 40 and c.meta["invalid_dropped"] == 2
    with pye57.E57(str(tmp_path / "s.e57")) as e:  # the stored values (pye57 writes float32)
        raw = [e.read_scan_raw(i) for i in (0, 1)]
    stored = [np.column_stack([r["cartesianX"], r["cartesianY"], r["cartesianZ"]]) for r in raw]
    assert np.allclose(stored[0], xyz, rtol=1e-6)
    assert np.allclose(c.xyz[:keep.sum()], stored[0][keep] * 1e3, rtol=1e-15, atol=0)
    assert np.allclose(c.xyz[keep.sum():], (stored[1] + [10.0, 0, 0]) * 1e3, rtol=1e-15, atol=0)
    assert np.array_equal(c["scan"], np.r_[np.zeros(keep.sum()), np.ones(40)])
    assert np.allclose(c["intensity"][:keep.sum()], a["intensity"][keep])
    assert np.array_equal(c["red"][:keep.sum()], a["colorRed"][keep])
    assert c.meta["format"] == "e57" and c.meta["instrument_unit"] == "m"


def test_e57_damaged_is_named(tmp_path):
    (tmp_path / "bad.e57").write_bytes(b"ASTM-E57" + bytes(200))
    with pytest.raises(InputError, match=r"bad.e57: a damaged or truncated E57 file"):
        read_cloud(tmp_path / "bad.e57")


@pytest.mark.parametrize("module,magic,name", [("laspy", b"LASF", "a.las"), ("pye57", b"ASTM-E57", "a.e57")])
def test_missing_library_says_what_to_install(tmp_path, monkeypatch, module, magic, name):
    (tmp_path / name).write_bytes(magic + bytes(400))
    monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
    with pytest.raises(InputError) as e:
        read_cloud(tmp_path / name)
    assert str(e.value).startswith(str(tmp_path / name))
    assert "pip install 'pointspro[scanners]'" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("name,text,what", [
    ("m.obj", "# Blender\no part\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n", "an OBJ mesh"),
    ("m.txt", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "an OFF mesh"),
    ("m.csv", "solid part\nfacet normal 0 0 1\nendfacet\nendsolid part\n", "an ASCII STL mesh"),
])
def test_a_mesh_given_as_measurement_is_named(tmp_path, name, text, what):
    (tmp_path / name).write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=rf"{name}: {what} \(a nominal for `register` or "
                                         r"`surface: \{type: mesh\}`\), not a measurement file"):
        read_cloud(tmp_path / name)
