"""LAS / LAZ (laspy + lazrs) and E57 (pye57) point clouds: the optional `scanners` extra
(core/io/las.py, core/io/e57.py). Each file is written here with the library itself and read back;
coordinates in metres become mm."""
from __future__ import annotations

import sys
from pathlib import Path

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


# --- the coordinate reference system's WKT: horizontal and vertical units ---------------------------
REAL = Path(__file__).parent / "data" / "realdata"
US_FT = 1200 / 3937  # the US survey foot in metres (EPSG 9003), exactly
_ESRI_PROJCS = ('PROJCS["NAD_1983_StatePlane_New_Mexico_Central_FIPS_3002_Feet",GEOGCS["GCS_North_'
                'American_1983",DATUM["D_North_American_1983",SPHEROID["GRS_1980",6378137.0,'
                '298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],'
                'PROJECTION["Transverse_Mercator"],PARAMETER["False_Easting",1640416.666666667],'
                'UNIT["Foot_US",0.3048006096012192]]')
_WKT2_PROJCRS = ('PROJCRS["NAD83(2011) / New Mexico Central (ftUS)",BASEGEOGCRS["NAD83(2011)",DATUM['
                 '"NAD83 (National Spatial Reference System 2011)",ELLIPSOID["GRS 1980",6378137,'
                 '298.257222101,LENGTHUNIT["metre",1]]],PRIMEM["Greenwich",0,ANGLEUNIT["degree",'
                 '0.0174532925199433]]],CONVERSION["SPCS83 New Mexico Central zone (US survey foot)",'
                 'METHOD["Transverse Mercator"],PARAMETER["False easting",1640416.667,LENGTHUNIT['
                 '"US survey foot",0.304800609601219]]],CS[Cartesian,2],AXIS["easting (X)",east,'
                 'LENGTHUNIT["US survey foot",0.304800609601219]],AXIS["northing (Y)",north,'
                 'LENGTHUNIT["US survey foot",0.304800609601219]]]')
WKTS = {  # (WKT, x/y metres per unit, z metres per unit, instrument_unit)
    # ESRI: the vertical CRS follows the PROJCS at the top level, spelt VERTCS
    "esri": (_ESRI_PROJCS + ',VERTCS["NAVD_1988",VDATUM["North_American_Vertical_Datum_1988"],'
             'PARAMETER["Vertical_Shift",0.0],PARAMETER["Direction",1.0],UNIT["Meter",1.0]]',
             0.3048006096012192, 1.0, "US survey ft (x, y), m (z)"),
    "ogc": ('COMPD_CS["NM Central (ftUS) + NAVD88 height (ftUS)",' + _ESRI_PROJCS
            + ',VERT_CS["NAVD88 height (ftUS)",VERT_DATUM["North American Vertical Datum 1988",2005],'
            'UNIT["US survey foot",0.304800609601219],AXIS["Up",UP]]]',
            0.3048006096012192, 0.304800609601219, "US survey ft"),
    "wkt2": ('COMPOUNDCRS["NM Central (ftUS) + NAVD88 height",' + _WKT2_PROJCRS
             + ',VERTCRS["NAVD88 height",VDATUM["North American Vertical Datum 1988"],CS[vertical,1],'
             'AXIS["gravity-related height (H)",up,LENGTHUNIT["metre",1]]]]',
             0.304800609601219, 1.0, "US survey ft (x, y), m (z)"),
    "wkt2_vertical_first": ('COMPOUNDCRS["c",VERTICALCRS["v",VDATUM["d"],CS[vertical,1],AXIS["H",up],'
                            'LENGTHUNIT["foot",0.3048]],' + _WKT2_PROJCRS + "]",
                            0.304800609601219, 0.3048, "US survey ft (x, y), ft (z)"),
}


def _las_wkt(path, wkt, evlr=False):
    xyz, _ = _points(50)
    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales = np.array([1e-3, 1e-3, 1e-3])
    vlr = laspy.vlrs.known.WktCoordinateSystemVlr(wkt)
    if evlr:
        h.evlrs = laspy.vlrs.vlrlist.VLRList([vlr])
    else:
        h.vlrs.append(vlr)
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz[:, 0] + 1.7e6, xyz[:, 1] + 1.8e6, xyz[:, 2] + 5600.0
    las.write(str(path))
    return laspy.read(str(path))


@pytest.mark.parametrize("kind", list(WKTS))
def test_las_wkt_gives_x_y_the_horizontal_unit_and_z_the_vertical_one(tmp_path, kind):
    wkt, hm, vm, unit = WKTS[kind]
    src = _las_wkt(tmp_path / "w.las", wkt)
    c = read_cloud(tmp_path / "w.las")
    assert np.allclose(c.x, np.asarray(src.x) * hm * 1e3, rtol=1e-15, atol=0)
    assert np.allclose(c.y, np.asarray(src.y) * hm * 1e3, rtol=1e-15, atol=0)
    assert np.allclose(c.z, np.asarray(src.z) * vm * 1e3, rtol=1e-15, atol=0)
    assert c.meta["instrument_unit"] == unit


def test_las_wkt_in_an_extended_vlr(tmp_path):
    """LAS 1.4 may keep its WKT in an EVLR after the points: read as from a VLR."""
    src = _las_wkt(tmp_path / "e.las", WKTS["esri"][0], evlr=True)
    c = read_cloud(tmp_path / "e.las")
    assert np.allclose(c.x, np.asarray(src.x) * 0.3048006096012192e3, rtol=1e-15, atol=0)
    assert np.array_equal(c.z, np.asarray(src.z) * 1e3)
    assert c.meta["instrument_unit"] == "US survey ft (x, y), m (z)"


def test_las_real_file_with_vertcs_inside_its_projcs():
    """laspy's tests/data/test1_4.las (BSD, LICENSE-laspy.txt): a WKT PROJCS "NAD83(HARN) / New
    Mexico Central (ftUS)" (EPSG 2903) whose UNIT["US survey foot",0.3048006096012192] is x and y's,
    with a VERTCS (NAVD88, EPSG 5703) nested at its end, UNIT["US survey foot",1.0].

    The truth, read here from the WKT text with plain string search (no pyproj in the venv): x, y
    in US survey feet by the PROJCS's own factor. z: the VERTCS's unit *names* the US survey foot but
    writes 1.0 as its factor (a placeholder; a metre is written "metre"); the heights, 5592–5599,
    are US survey feet: 1704–1707 m lies in New Mexico's range (859–4013 m), 5599 m lies above
    any point of it. So z is converted as US survey feet too, and the report says how it was read."""
    las = laspy.read(str(REAL / "laspy_test1_4.las"))
    (wkt,) = [v.string for v in las.header.vlrs if getattr(v, "string", None)]
    h_part, v_part = wkt.split("VERTCS[", 1)
    assert 'UNIT["US survey foot",0.3048006096012192,AUTHORITY["EPSG","9003"]],AXIS["X",EAST]' in h_part
    assert 'UNIT["US survey foot",1.0]' in v_part and "UNIT" not in v_part.replace(
        'UNIT["US survey foot",1.0]', "")
    z_m = np.asarray(las.z) * US_FT
    assert 859 < z_m.min() and z_m.max() < 4013 < np.asarray(las.z).min()
    c = read_cloud(REAL / "laspy_test1_4.las")
    assert c.n == 1000
    assert np.allclose(c.x, np.asarray(las.x) * 0.3048006096012192e3, rtol=1e-15, atol=0)
    assert np.allclose(c.y, np.asarray(las.y) * 0.3048006096012192e3, rtol=1e-15, atol=0)
    assert np.allclose(c.z, np.asarray(las.z) * US_FT * 1e3, rtol=1e-15, atol=0)
    assert 5.16e8 < c.x.min() and c.x.max() < 5.17e8  # ≈ 1694038 ft, not 1.694e9 mm (read as m)
    assert c.meta["instrument_unit"] == (
        'US survey ft (z: WKT UNIT["US survey foot",1.0] read as the unit it names)')
    assert (REAL / "LICENSE-laspy.txt").read_text(encoding="utf-8").startswith("laspy License")


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


def test_las_in_longitude_and_latitude_is_refused(tmp_path):
    """A geographic CRS (degrees): x, y were taken in the vertical unit or metres (0.0001° read as
    0.1 mm). No length unit holds: refused, naming the CRS and what to do."""
    wkt = ('GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],'
           'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]]')
    _las_wkt(tmp_path / "g.las", wkt)
    with pytest.raises(InputError, match=r"g\.las: x, y are geographic coordinates .*'WGS 84'.*reproject"):
        read_cloud(tmp_path / "g.las")


@pytest.mark.parametrize("keys", [[(1024, 2), (2048, 4326), (4099, 9001)], [(1024, 2), (2048, 4326)],
                                  [(2048, 4269)]])
def test_las_geokeys_of_a_geographic_crs_are_refused(tmp_path, keys):
    """GeoKeys are LAS 1.0–1.3's usual way to state a CRS (a review: GTModelTypeGeoKey 2 with EPSG:4326
    read longitude 8.5° as 8500 mm, and the vertical key's "m" stood in for x, y as if stated)."""
    _las(tmp_path / "g.las", geokeys=keys)
    with pytest.raises(InputError, match=r"g\.las: x, y are geographic coordinates .*EPSG:\d+.*reproject"):
        read_cloud(tmp_path / "g.las")


def test_las_projected_crs_code_without_its_unit(tmp_path):
    """ProjectedCSTypeGeoKey without ProjLinearUnitsGeoKey: a UTM zone is in metres; EPSG:2263 (New York
    Long Island, US survey feet) was read as metres, 3.28× off — refused, naming the code."""
    src = _las(tmp_path / "utm.las", geokeys=[(1024, 1), (3072, 32632)])
    c = read_cloud(tmp_path / "utm.las")
    assert np.array_equal(c.x, np.asarray(src.x) * 1e3)
    assert c.meta["instrument_unit"].startswith("m (") and "EPSG:32632" in c.meta["instrument_unit"]
    assert "assumed" not in c.meta["instrument_unit"]
    _las(tmp_path / "ny.las", geokeys=[(1024, 1), (3072, 2263)])
    with pytest.raises(InputError, match=r"ny\.las: .*EPSG:2263 but not its linear unit"):
        read_cloud(tmp_path / "ny.las")
    src = _las(tmp_path / "ny_ft.las", geokeys=[(1024, 1), (3072, 2263), (3076, 9003)])  # the unit given
    assert np.allclose(read_cloud(tmp_path / "ny_ft.las").x, np.asarray(src.x) * 1200 / 3937 * 1e3, rtol=1e-15)


@pytest.mark.parametrize("code", [2154, 6340])
def test_las_common_metric_crs_codes_without_a_unit_key_read_in_metres(tmp_path, code):
    """A review of the EPSG rule: Lambert-93 and NAD83(2011) / UTM (USGS 3DEP) files without
    ProjLinearUnitsGeoKey, read as metres before, were refused."""
    src = _las(tmp_path / "m.las", geokeys=[(1024, 1), (3072, code)])
    assert np.array_equal(read_cloud(tmp_path / "m.las").x, np.asarray(src.x) * 1e3)
