"""Damaged headers of real instrument files (tests/data/realdata, SurfaceTopography's published
examples, MIT): a scale of 0 (or NaN) collapses a map into a "perfect part", a lateral size without
unit is lent one, a declared validity mask is missing … Each is one InputError naming the file and the
header field, never a silently wrong cloud; the undamaged file reads exactly as before.

Each damaged file is built here, in tmp_path, from the real one by a struct edit (as a user's copy
could be damaged by a transfer or a converter)."""
from __future__ import annotations

import hashlib
import json
import re
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud
from pointspro.core.io.instruments import check_map_geometry

DATA = Path(__file__).parent / "data" / "realdata"

# the undamaged files' figures (as tests/test_realdata.py: numpy on the file's numbers)
FIGURES = {  # name: (points, invalid dropped, mean height µm)
    "metropro-1.dat": (307200, 0, 50.740406),
    "sur-2.sur": (272375, 117, 10.157376),
    "opd-1.opd": (307084, 116, -0.2722895),
    "mi-1.mi": (65536, 0, -0.5588049),
    "sdf-1.sdf": (28, 0, 0.9835632),
}


def _undamaged_reads_as_before(name):
    c = read_cloud(DATA / name)
    n, invalid, mean_um = FIGURES[name]
    assert c.n == n and c.meta["invalid_dropped"] == invalid
    assert np.isclose(c.z.mean() * 1e3, mean_um, rtol=1e-6)
    assert np.ptp(c.x) > 0 and np.ptp(c.y) > 0 and np.ptp(c.z) > 0
    return c


def _damaged(tmp_path, name, edits, out=None):
    """A copy of the real file with (offset, struct format, value) edits."""
    b = bytearray((DATA / name).read_bytes())
    for off, fmt, val in edits:
        struct.pack_into(fmt, b, off, val)
    p = tmp_path / (out or name)
    p.write_bytes(bytes(b))
    return p


def _one_line(e, p):
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg and "internal error" not in msg
    assert "Traceback" not in msg and len(msg) < 400


# --- 1. a zero or non-finite scale in an instrument header --------------------------------------------
@pytest.mark.parametrize("name,edits,pattern", [
    ("metropro-1.dat", [(168, ">f", 0.0)], r"metropro-1.dat: the header's wavelength is 0 — heights "
                                           r"cannot be scaled"),
    ("metropro-1.dat", [(168, ">f", float("nan"))], r"metropro-1.dat: the header's wavelength is not "
                                                    r"a number — heights cannot be scaled"),
    ("metropro-1.dat", [(164, ">f", 0.0)], r"the header's intf_scale_factor is 0"),
    ("metropro-1.dat", [(176, ">f", 0.0)], r"the header's obliquity_factor is 0"),
    ("sur-2.sur", [(128, "<f", 0.0)], r"sur-2.sur: the header's height scale \(offset 128\) is 0 — "
                                      r"heights cannot be scaled"),
    ("sur-2.sur", [(128, "<f", float("nan"))], r"sur-2.sur: the header's height scale \(offset "
                                               r"128\) is not a number"),
    ("sur-2.sur", [(120, "<f", float("nan"))], r"sur-2.sur: the header's x spacing \(offset 120\) "
                                               r"is not a number — x positions cannot be scaled"),
    ("opd-1.opd", [(24016, "<f", 0.0)], r"opd-1.opd: the header's Pixel_size is 0 — x and y "
                                        r"positions cannot be scaled"),
    ("opd-1.opd", [(24016, "<f", -1e-4)], r"opd-1.opd: the header's Pixel_size is negative"),
    ("opd-1.opd", [(24008, "<f", 0.0)], r"opd-1.opd: the header's Wavelength is 0 — heights cannot "
                                        r"be scaled"),
    ("opd-1.opd", [(24012, "<f", 0.0)], r"opd-1.opd: the header's Aspect is 0 — y positions cannot "
                                        r"be scaled"),
])
def test_zero_scale_in_a_binary_header(tmp_path, name, edits, pattern):
    p = _damaged(tmp_path, name, edits)
    with pytest.raises(InputError, match=pattern) as e:
        read_cloud(p)
    _one_line(e, p)
    _undamaged_reads_as_before(name)


def test_metropro_zero_wavelength_with_reader_options(tmp_path):
    """Reader options send the file to SurfaceTopography's reader: the wavelength is checked first."""
    p = _damaged(tmp_path, "metropro-1.dat", [(168, ">f", 0.0)])
    with pytest.raises(InputError, match=r"metropro-1.dat: the header's wavelength is 0"):
        read_cloud(p, pixel_size_um=1.0)


@pytest.mark.parametrize("name,old,new,pattern", [
    ("sdf-1.sdf", b"Xscale = 1.0E-6", b"Xscale = 0", r"sdf-1.sdf: the header's Xscale is 0 — x "
                                                     r"positions cannot be scaled"),
    ("sdf-1.sdf", b"Zscale = 1.0E-6", b"Zscale = 0", r"sdf-1.sdf: the header's Zscale is 0 — "
                                                     r"heights cannot be scaled"),
    ("sdf-1.sdf", b"Xscale = 1.0E-6", b"Xscale = -1.0E-6", r"sdf-1.sdf: the header's Xscale is "
                                                           r"negative"),
    ("mi-1.mi", b"xLength       2.0000000000000002e-005", b"xLength       0.0000000000000000e+000",
     r"mi-1.mi: the header's xLength is 0 — x positions cannot be scaled"),
])
def test_zero_scale_in_a_text_header(tmp_path, name, old, new, pattern):
    raw = (DATA / name).read_bytes()
    assert raw.count(old) == 1
    p = tmp_path / name
    p.write_bytes(raw.replace(old, new))
    with pytest.raises(InputError, match=pattern) as e:
        read_cloud(p)
    _one_line(e, p)
    _undamaged_reads_as_before(name)


def test_gwyddion_width_zero(tmp_path):
    text = (DATA / "gwyddion-export-english.txt").read_text(encoding="utf-8")
    p = tmp_path / "g.txt"
    p.write_text(text.replace("# Width: 12.34 µm", "# Width: 0 µm"), encoding="utf-8")
    with pytest.raises(InputError, match=r"g.txt, line 2: the header's # Width is 0 — x positions "
                                         r"cannot be scaled") as e:
        read_cloud(p)
    _one_line(e, p)
    p.write_text(text.replace("# Width: 12.34 µm", "# Width: -12.34 µm"), encoding="utf-8")
    with pytest.raises(InputError, match=r"g.txt, line 2: the header's # Width is negative"):
        read_cloud(p)
    c = read_cloud(DATA / "gwyddion-export-english.txt")
    assert np.allclose(c.x, c["col"] * 12.34e-3 / 3, rtol=1e-12)
    assert np.allclose(c.y, c["row"] * 5678.9e-6 / 4, rtol=1e-12)


# --- the generic safety net -------------------------------------------------------------------------
def _grid(nx=20, ny=10, dx=1e-3, dy=1e-3, z=None):
    j, i = np.mgrid[0:ny, 0:nx]
    zz = (1e-4 * i + 2e-4 * j) if z is None else np.full((ny, nx), z)
    xyz = np.column_stack([(i * dx).ravel(), (j * dy).ravel(), zz.ravel()])
    return xyz, {"row": j.ravel(), "col": i.ravel()}


def test_safety_net_for_scales_the_metadata_does_not_show():
    check_map_geometry("m.map", *_grid())  # a usable map passes
    with pytest.raises(InputError, match=r"m.map: every point has the same x \(0 mm\) on a map of 20 "
                                         r"columns — the x spacing is 0; is a scale or pixel size in "
                                         r"the header zero\?"):
        check_map_geometry("m.map", *_grid(dx=0.0))
    with pytest.raises(InputError, match=r"m.map: every point has the same y .* 10 rows — the y "
                                         r"spacing is 0"):
        check_map_geometry("m.map", *_grid(dy=0.0))
    with pytest.raises(InputError, match=r"m.map: the map's x positions are not finite numbers"):
        check_map_geometry("m.map", *_grid(dx=np.nan))
    with pytest.raises(InputError, match=r"m.map: all 200 valid heights are exactly 0 mm — is a "
                                         r"height scale or wavelength in the header zero\?"):
        check_map_geometry("m.map", *_grid(z=0.0))
    check_map_geometry("m.map", *_grid(nx=9, ny=11, z=0.0))  # 99 pixels: too few to tell
    check_map_geometry("m.map", *_grid(z=0.0), heights=False)  # heights written as they are
    xyz, ch = _grid(nx=1)  # one column: every x equal is right
    check_map_geometry("m.map", xyz, ch)


def test_a_flat_xyz_text_file_is_legitimate(tmp_path):
    """x y z text is never held to the all-equal-heights rule (a synthetic flat)."""
    xyz, _ = _grid(z=0.0)
    p = tmp_path / "flat.csv"
    np.savetxt(p, xyz, delimiter=",", header="x,y,z", comments="")
    c = read_cloud(p)
    assert c.n == 200 and np.all(c.z == 0)


# --- 2. a text matrix whose lateral size has no unit ------------------------------------------------
GWY = "# Channel: x\n# Width: 12.34\n# Height: 5678.9\n# Value units: m\n1 1.5 3\n-2 -3 -6\n0 0 0\n9 9 9\n"
SPIP = ("# File Format = ASCII\n# x-pixels = 3\n# y-pixels = 4\n# x-length = 12.34\n"
        "# y-length = 5.6789\n# z-unit = nm\n# Start of Data:\n1 1.5 3\n-2 -3 -6\n0 0 0\n9 9 9\n")


def test_matrix_size_without_unit_is_refused_naming_the_key(tmp_path):
    p = tmp_path / "g.txt"
    p.write_text(GWY, encoding="utf-8")
    with pytest.raises(InputError, match=r"g.txt, line 2: # Width has no unit \('# Width: 12.34'\); "
                                         r"write e.g. '# Width: 12.34 µm' or give the reader option "
                                         r"pixel_size_um") as e:
        read_cloud(p)
    _one_line(e, p)
    p.write_text(GWY.replace("# Width: 12.34", "# Width: 12.34 µm"), encoding="utf-8")
    with pytest.raises(InputError, match=r"g.txt, line 3: # Height has no unit"):
        read_cloud(p)  # SurfaceTopography would lend it the width's µm
    s = tmp_path / "s.txt"
    s.write_text(SPIP, encoding="utf-8")
    with pytest.raises(InputError, match=r"s.txt, line 4: # x-length has no unit \('# x-length = "
                                         r"12.34'\); add a line '# x-unit = µm'.* pixel_size_um"):
        read_cloud(s)
    # x-unit alone: SurfaceTopography takes a SPIP y-length without y-unit as nm
    s.write_text(SPIP.replace("# z-unit", "# x-unit = µm\n# z-unit"), encoding="utf-8")
    with pytest.raises(InputError, match=r"s.txt, line 5: # y-length has no unit .* add a line "
                                         r"'# y-unit = µm'"):
        read_cloud(s)
    s.write_text(SPIP.replace("# z-unit", "# x-unit = µm\n# y-unit = µm\n# z-unit"),
                 encoding="utf-8")
    c = read_cloud(s)
    assert np.isclose(c.meta["pixel_mm"][0], 12.34e-3 / 3) and np.isclose(c.meta["pixel_mm"][1],
                                                                         5.6789e-3 / 4)
    assert np.isclose(c.z.max(), 9e-6)


def test_pixel_size_option_replaces_a_size_without_unit(tmp_path):
    p = tmp_path / "g.txt"
    p.write_text(GWY, encoding="utf-8")
    c = read_cloud(p, pixel_size_um=[2.0, 3.0])
    assert np.allclose(c.x, c["col"] * 2e-3) and np.allclose(c.y, c["row"] * 3e-3)
    assert np.array_equal(np.sort(c.z), np.sort(np.array([1, 1.5, 3, -2, -3, -6, 0, 0, 0, 9, 9, 9])
                                                * 1e3))
    # a file with its own calibration still refuses the option
    with pytest.raises(InputError, match=r"gives its own lateral calibration; remove the reader "
                                         r"option pixel_size_um"):
        read_cloud(DATA / "gwyddion-export-english.txt", pixel_size_um=2.0)


def test_height_unit_does_not_replace_the_sizes_own_units(tmp_path):
    """Sizes with their units, values without: the sizes stay in their own units (SurfaceTopography
    took 12.34 µm as 12.34 of the height unit)."""
    p = tmp_path / "nz.txt"
    p.write_text("# Width: 12.34 µm\n# Height: 5678.9 nm\n1 1.5 3\n-2 -3 -6\n0 0 0\n9 9 9\n",
                 encoding="utf-8")
    with pytest.raises(InputError, match=r"nz.txt: the Plain text file gives no length unit for its "
                                         r"heights; give the reader option height_unit"):
        read_cloud(p)
    c = read_cloud(p, height_unit="nm")
    assert np.allclose(c.meta["pixel_mm"], [12.34e-3 / 3, 5678.9e-6 / 4], rtol=1e-12)
    assert np.isclose(c.z.max(), 9e-6)


def test_matrix_with_one_size_only(tmp_path):
    p = tmp_path / "w.txt"
    p.write_text("# Width: 12.34 µm\n# Value units: m\n1 1.5 3\n-2 -3 -6\n0 0 0\n9 9 9\n",
                 encoding="utf-8")
    with pytest.raises(InputError, match=r"w.txt, line 1: the header gives the map's x size "
                                         r"\(# Width\) but not its y size"):
        read_cloud(p)
    assert read_cloud(p, pixel_size_um=2.0).n == 12


# --- 3. namespace-less (Sensofar) X3P: the validity mask; PRF through x3pio ------------------------
NX, NY = 40, 30


def _plain_x3p(path, incx="1e-6", ftype="SUR", valid="full", incz="1", dtype="D"):
    """A Sensofar-style X3P (root <ISO5436> without namespace) whose pixel (5, 7) is invalid and holds
    a placeholder of 12345 m; valid: "full", "short", "missing" (declared, not in the archive)."""
    z = (np.add.outer(np.arange(NY), np.arange(NX)) * 1e-7).astype("<f8")
    z[5, 7] = 12345.0
    if dtype == "I":  # counts × the CZ increment
        z = np.add.outer(np.arange(NY), np.arange(NX)).astype("<i2")
    ok = np.ones((NY, NX), bool)
    ok[5, 7] = False
    vb = np.packbits(ok.ravel(), bitorder="little").tobytes()
    xml = (f'<?xml version="1.0"?><ISO5436><Record1><Revision>ISO5436 - 2000</Revision>'
           f"<FeatureType>{ftype}</FeatureType><Axes>"
           f"<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>{incx}</Increment>"
           f"<Offset>0</Offset></CX>"
           f"<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>1e-6</Increment>"
           f"<Offset>0</Offset></CY>"
           f"<CZ><AxisType>A</AxisType><DataType>{dtype}</DataType><Increment>{incz}</Increment>"
           f"<Offset>0</Offset></CZ></Axes></Record1>"
           f"<Record3><MatrixDimension><SizeX>{NX}</SizeX><SizeY>{NY}</SizeY><SizeZ>1</SizeZ>"
           f"</MatrixDimension><DataLink><PointDataLink>bindata/data.bin</PointDataLink>"
           f"<ValidPointsLink>bindata/valid.bin</ValidPointsLink></DataLink></Record3></ISO5436>")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("main.xml", xml)
        zf.writestr("bindata/data.bin", z.tobytes())
        if valid == "full":
            zf.writestr("bindata/valid.bin", vb)
        elif valid == "short":
            zf.writestr("bindata/valid.bin", vb[:-10])
    return path


def test_plain_x3p_validity_mask_missing_or_short(tmp_path):
    c = read_cloud(_plain_x3p(tmp_path / "ok.x3p"))
    assert c.n == NX * NY - 1 and c.meta["invalid_dropped"] == 1 and c.z.max() < 1
    p = _plain_x3p(tmp_path / "missing.x3p", valid="missing")
    with pytest.raises(InputError, match=r"missing.x3p: X3P with a namespace-less <ISO5436> root "
                                         r"\(Sensofar\): its validity mask bindata/valid.bin "
                                         r"\(ValidPointsLink\) is missing from the archive") as e:
        read_cloud(p)
    _one_line(e, p)
    p = _plain_x3p(tmp_path / "short.x3p", valid="short")
    with pytest.raises(InputError, match=r"short.x3p: .*its validity mask bindata/valid.bin holds "
                                         r"140 bytes where 40 × 30 pixels need 150"):
        read_cloud(p)


@pytest.mark.parametrize("inc,pattern", [
    ("0", r"the header's CX <Increment> is 0 — x positions cannot be scaled"),
    ("nan", r"the header's CX <Increment> is not a number"),
    ("inf", r"the header's CX <Increment> is inf"),
    ("-1e-6", r"the header's CX <Increment> is negative"),
])
def test_plain_x3p_increment(tmp_path, inc, pattern):
    p = _plain_x3p(tmp_path / "inc.x3p", incx=inc)
    with pytest.raises(InputError, match=r"inc.x3p: " + pattern) as e:
        read_cloud(p)
    _one_line(e, p)


def test_plain_x3p_integer_heights_with_zero_cz_increment(tmp_path):
    c = read_cloud(_plain_x3p(tmp_path / "i.x3p", dtype="I", incz="1e-7"))
    assert c.n == NX * NY - 1 and np.isclose(c.z.max(), (NX + NY - 2) * 1e-4)
    p = _plain_x3p(tmp_path / "i0.x3p", dtype="I", incz="0")
    with pytest.raises(InputError, match=r"i0.x3p: the header's CZ <Increment> is 0 — heights cannot "
                                         r"be scaled"):
        read_cloud(p)


def _with_main_xml(src, dst, edit):
    """A copy of an x3pio-written X3P with main.xml edited and its checksum file made to match."""
    with zipfile.ZipFile(src) as zi:
        files = {n: zi.read(n) for n in zi.namelist()}
    xml = edit(files["main.xml"].decode())
    files["main.xml"] = xml.encode()
    if "md5checksum.hex" in files:
        files["md5checksum.hex"] = f"{hashlib.md5(xml.encode()).hexdigest()} *main.xml\n".encode()
    with zipfile.ZipFile(dst, "w") as zo:
        for n, b in files.items():
            zo.writestr(n, b)
    return dst


def test_x3p_of_feature_type_prf_is_refused_by_name(tmp_path):
    import x3pio

    z = np.add.outer(np.arange(6), np.arange(8)) * 1e-7
    x3pio.write(str(tmp_path / "m.x3p"), z, x_scale=1e-6, y_scale=1e-6)
    assert read_cloud(tmp_path / "m.x3p").n == 48
    p = _with_main_xml(tmp_path / "m.x3p", tmp_path / "prf.x3p",
                       lambda x: re.sub(r"<FeatureType>SUR", "<FeatureType>PRF", x, count=1))
    x3pio.read(str(p))  # x3pio reads it (as a surface)
    with pytest.raises(InputError, match=r"prf.x3p: an X3P of feature type PRF \(a line profile\), "
                                         r"not an areal map") as e:
        read_cloud(p)
    _one_line(e, p)


# --- 4. NPZ -----------------------------------------------------------------------------------------
def _npz(path, edit=lambda arrays, meta: None):
    from pointspro.core.cloud import PointCloud
    from pointspro.core.io.npz import META_KEY, write_npz_cloud

    g = np.linspace(0.0, 1.0, 50)
    write_npz_cloud(PointCloud.from_xyz(g, 2 * g, g ** 2, residual=g - 0.5), path)
    with np.load(path, allow_pickle=False) as z:
        arrays = {n: np.array(z[n]) for n in z.files}
    meta = json.loads(str(arrays.pop(META_KEY)))
    edit(arrays, meta)
    arrays[META_KEY] = np.array(json.dumps(meta))
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


def test_npz_columns_of_different_length(tmp_path):
    p = _npz(tmp_path / "a.npz", lambda a, m: a.update(y=a["y"][:-5]))
    with pytest.raises(InputError, match=r"a.npz: array 'y' has 45 values where 'x' has 50 — the "
                                         r"columns differ in length") as e:
        read_cloud(p)
    _one_line(e, p)
    p = _npz(tmp_path / "b.npz", lambda a, m: a.update(residual=a["residual"][:-5]))
    with pytest.raises(InputError, match=r"b.npz: array 'residual' has 45 values"):
        read_cloud(p)


def test_npz_columns_without_x(tmp_path):
    p = _npz(tmp_path / "c.npz", lambda a, m: m["columns"].remove("x"))
    with pytest.raises(InputError, match=r"c.npz: pointspro_meta's 'columns' has no 'x'") as e:
        read_cloud(p)
    _one_line(e, p)


@pytest.mark.parametrize("edit,pattern", [
    (lambda a, m: a.update(x=a["x"].reshape(25, 2)), r"array 'x' has shape \(25, 2\); a column is 1-D"),
    (lambda a, m: a.update(x=a["x"].astype(complex)), r"array 'x' holds complex128 values"),
    (lambda a, m: m["columns"].append("ghost"), r"column 'ghost' is listed in pointspro_meta but"),
])
def test_npz_bad_arrays(tmp_path, edit, pattern):
    p = _npz(tmp_path / "d.npz", edit)
    with pytest.raises(InputError, match=pattern):
        read_cloud(p)


def test_npz_reads_back_in_the_frame_it_states(tmp_path):
    """A batch's cloud.npz after `misalignment` is in the part frame and says so; it read back as
    "measuring" (as every other file) until 2026-11-27. A frame that is neither is refused, named."""
    assert read_cloud(_npz(tmp_path / "m.npz")).frame == "measuring"
    assert read_cloud(_npz(tmp_path / "n.npz", lambda a, m: m.update(frame=None))).frame == "measuring"
    assert read_cloud(_npz(tmp_path / "p.npz", lambda a, m: m.update(frame="part"))).frame == "part"
    p = _npz(tmp_path / "w.npz", lambda a, m: m.update(frame="world"))
    with pytest.raises(InputError, match=r"w.npz: pointspro_meta's frame 'world' is not one of "
                                         r"measuring, part") as e:
        read_cloud(p)
    _one_line(e, p)


def test_npz_nan_rows_are_dropped_and_counted(tmp_path):
    from pointspro.core.io.npz import read_npz

    def nan(a, m):
        a["x"][3] = np.nan
        a["z"][7] = np.inf

    p = _npz(tmp_path / "n.npz", nan)
    c = read_cloud(p)
    assert c.n == 48 and c.meta["invalid_dropped"] == 2
    assert np.isfinite(c.xyz).all() and 3 not in c.index and 7 not in c.index
    assert np.array_equal(c["residual"], np.linspace(0, 1, 50)[c.index] - 0.5)
    with pytest.raises(InputError, match=r"n.npz, row 3, column 'x': nan is not a finite number"):
        read_npz(p, invalid="error")
    p = _npz(tmp_path / "all.npz", lambda a, m: a["y"].fill(np.nan))
    with pytest.raises(InputError, match=r"all.npz: every row holds a NaN/inf x, y or z"):
        read_cloud(p)
    # the undamaged cloud reads back as written
    c = read_cloud(_npz(tmp_path / "ok.npz"))
    assert c.n == 50 and c.meta["invalid_dropped"] == 0
    assert np.array_equal(c.x, np.linspace(0, 1, 50))


# --- 5. the library's reason is kept; the file is named --------------------------------------------
def test_surfacetopography_reason_is_appended(tmp_path):
    p = _damaged(tmp_path, "sur-2.sur", [(108, "<i", 562)], out="nx.sur")
    with pytest.raises(InputError, match=r"nx.sur: a damaged or truncated Digital Surf SUR file — its "
                                         r"header is recognised but it cannot be read \(Structure "
                                         r"entry `nb_points` has invalid value '272492' at file "
                                         r"offset 116") as e:
        read_cloud(p)
    _one_line(e, p)
    _undamaged_reads_as_before("sur-2.sur")


def test_spip_pixels_that_disagree_name_the_file(tmp_path):
    p = tmp_path / "sp.txt"
    p.write_text(SPIP.replace("# x-pixels = 3", "# x-pixels = 5").replace(
        "# z-unit", "# x-unit = µm\n# y-unit = µm\n# z-unit"), encoding="utf-8")
    with pytest.raises(InputError, match=r"sp.txt, line 2: the header's x-pixels = 5 but the matrix "
                                         r"has 3 values a row") as e:
        read_cloud(p)
    _one_line(e, p)
    assert "_io." not in str(e.value)
    p.write_text(SPIP.replace("# y-pixels = 4", "# y-pixels = 7").replace(
        "# z-unit", "# x-unit = µm\n# y-unit = µm\n# z-unit"), encoding="utf-8")
    with pytest.raises(InputError, match=r"sp.txt, line 3: the header's y-pixels = 7 but the matrix "
                                         r"has 4 rows"):
        read_cloud(p)


def test_headerless_bytes_are_not_an_srtm_elevation_map(tmp_path):
    """SRTM has no header, and SurfaceTopography's detection took any 2·n² bytes for one: 5,000 random
    bytes named .dat read as "the NASA SRTM file" — and, with height_unit and pixel_size_um in a
    recipe, as a 50 × 50 map processed with exit 0. Only a .hgt file is SRTM."""
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud

    p = tmp_path / "rnd.dat"
    p.write_bytes(np.random.default_rng(0).bytes(5000))
    for opts in ({}, {"height_unit": "nm", "pixel_size_um": 1.0}):
        with pytest.raises(InputError, match="nor any format PointsPro or SurfaceTopography recognises") as e:
            read_cloud(p, **opts)
        assert "SRTM" not in str(e.value)


def test_height_unit_is_refused_where_the_file_has_its_own(tmp_path):
    """`input: {height_unit: um}` was ignored silently on an x y z CSV (z read as mm) and on a
    MetroPro map (heights in the file's m), while pixel_size_um was refused there."""
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud

    from .conftest import EXAMPLE, ROOT

    with pytest.raises(InputError, match=r"reader option height_unit is for instrument maps .*`x \[mm\],y \[mm\],z \[um\]`"):
        read_cloud(EXAMPLE / "asphere_cmm.csv", height_unit="um")
    with pytest.raises(InputError, match=r"metropro-1.dat: the file gives its own height unit \(m\); remove"):
        read_cloud(ROOT / "tests/data/realdata/metropro-1.dat", height_unit="um")
    assert read_cloud(EXAMPLE / "asphere_cmm.csv").n == 4680  # without it, as before


def test_a_cut_pointspro_npz_is_named_damaged(tmp_path):
    """A .npz PointsPro wrote, cut short (a full disk, a stopped copy), read as "unknown file type
    '.npz' — no reader recognises its content"."""
    from pointspro.core import PointCloud
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud
    from pointspro.core.io.npz import write_npz_cloud

    p = tmp_path / "c.npz"
    write_npz_cloud(PointCloud.from_xyz(np.arange(5000.0), np.zeros(5000), np.ones(5000)), p)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    with pytest.raises(InputError, match=r"cut.npz: a damaged or truncated \.npz"):
        read_cloud(cut)


def test_recipe_messages_name_the_line_and_the_surface_type(tmp_path):
    """A non-UTF-8 byte was a byte offset ("position 46"); a surface without `type` pydantic's
    "Unable to extract tag using discriminator 'type'"."""
    from pointspro.core.errors import RecipeError
    from pointspro.core.recipe import load_recipe

    p = tmp_path / "r.yaml"
    p.write_bytes(b"pointspro: 1\nsteps:\n  - zernike: {terms: 4}\n# \xb5m\n")
    with pytest.raises(RecipeError, match=r"r.yaml, line 4: not UTF-8 text \(byte 0xb5\)"):
        load_recipe(p)
    p.write_text("pointspro: 1\nsurface: {c: 0.001}\nsteps:\n  - zernike: {terms: 4}\n", encoding="utf-8")
    with pytest.raises(RecipeError, match=r"line 2: surface: key 'type' is missing"):
        load_recipe(p)
    p.write_text("pointspro: 1\nsurface: {type: torus}\nsteps:\n  - zernike: {terms: 4}\n", encoding="utf-8")
    with pytest.raises(RecipeError, match=r"surface: unknown type 'torus'; one of .*'even_asphere'"):
        load_recipe(p)


def test_digits_python_reads_but_the_readers_do_not_name_their_line(tmp_path):
    """`1_000` and full-width digits: Python's float() takes them, the fast readers do not, so the
    message was "could not parse the numeric data" with no line."""
    from pointspro.core.errors import InputError
    from pointspro.core.io import read_cloud

    for tok in ("1_000", "\uff11"):
        p = tmp_path / "u.csv"
        p.write_text(f"x,y,z\n0,0,0\n1,0,1\n0,{tok},2\n", encoding="utf-8")
        with pytest.raises(InputError, match=r"u.csv, line 4, column 2: '.*' is not a number"):
            read_cloud(p)


def test_a_matrix_cut_after_its_first_row_is_refused_a_profile_is_not(tmp_path):
    """A review: matrix-3.txt cut in its second line read as a one-row map, its cut last value
    '1.9473e-0' taken as 1.9473 m; the format stores no counts, but the header's Height does."""
    lines = (DATA / "matrix-3.txt").read_text(encoding="utf-8").splitlines()
    first = next(i for i, ln in enumerate(lines) if ln and not ln.startswith("#"))
    cut = tmp_path / "cut.txt"
    cut.write_text("\n".join(lines[:first + 1]) + "\n" + lines[first + 1][:40] + "\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"cut\.txt"):
        read_cloud(cut)
    one = tmp_path / "one.txt"
    one.write_text("\n".join(lines[:first + 1]) + "\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"one\.txt: one row of heights, but the header's Height spans "
                                         r"about 256 of its pixels — the file looks cut after its first line"):
        read_cloud(one)
    # a profile — the header's Height one pixel of the width's — stays a profile (a review)
    prof = tmp_path / "prof.txt"
    prof.write_text("# Channel: Height\n# Width: 4.00 mm\n# Height: 0.01 mm\n# Value units: m\n"
                    + "\t".join(f"{1e-9 * k:.5e}" for k in range(400)) + "\n", encoding="utf-8")
    assert read_cloud(prof).n == 400
