"""Interferometer/profiler files in: each written here by another library (or byte by byte from the
format's specification), read through core.io.read_cloud, compared pixel by pixel."""
from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

NY, NX = 24, 32
DX, DY = 2.0e-3, 3.0e-3  # pixel pitch (mm)
BAD = (5, 7)             # (row, col) of an invalid pixel


def heights_um():
    """A tilted, curved test surface in µm on the (row = y, col = x) grid."""
    j, i = np.mgrid[0:NY, 0:NX]
    return 0.05 * i - 0.08 * j + 0.002 * (i - 10.0) ** 2 + 0.3


def _check(cloud, z_um, atol_um, x0=0.0, y0=0.0):
    valid = np.ones((NY, NX), bool)
    valid[BAD] = False
    assert cloud.n == valid.sum()
    r, c = cloud["row"], cloud["col"]
    assert not np.any((r == BAD[0]) & (c == BAD[1]))
    assert np.allclose(cloud.x, x0 + c * DX, atol=1e-12)
    assert np.allclose(cloud.y, y0 + r * DY, atol=1e-12)
    assert np.allclose(cloud.z * 1e3, z_um[r, c], atol=atol_um)


def test_x3p_from_x3pio(tmp_path):
    import x3pio

    z = heights_um() * 1e-6  # metres
    z[BAD] = np.nan
    x3pio.write(str(tmp_path / "m.x3p"), z, x_scale=DX * 1e-3, y_scale=DY * 1e-3,
                placement=x3pio.Placement.translation(0.010, -0.020, 0.0),
                coordinate_system=x3pio.CoordinateSystem.VIEW)
    c = read_cloud(tmp_path / "m.x3p")
    _check(c, heights_um(), 1e-12, x0=10.0, y0=-20.0)


@pytest.mark.parametrize("suffix", [".sur", ".sdf"])
def test_digital_surf_and_sdf_from_surfalize(tmp_path, suffix):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from surfalize import Surface

        z = heights_um().copy()
        z[BAD] = np.nan
        # a .sur's first stored row is the top of MountainsMap's picture (docs/formats.md): written
        # upside down, it reads back with row r at y = r·Δy; ISO 25178-71's .sdf keeps its order
        stored = z[::-1] if suffix == ".sur" else z
        Surface(stored, DX * 1e3, DY * 1e3).save(tmp_path / f"m{suffix}")  # µm heights, µm steps
    c = read_cloud(tmp_path / f"m{suffix}")
    # .sur stores 32-bit integers over the range (~1e-9 µm steps), .sdf decimals
    _check(c, heights_um(), 1e-6)


def write_datx(path, z_nm, px_m, py_m, no_data=np.nan):
    """A Zygo Mx .datx (HDF5): /MetaData (source, link, destination) triples and the surface
    dataset with Unit, X/Y/Z converters and No Data attributes, written with h5py."""
    import h5py

    meta = np.array([(b"Root", b"Measurement", b"{m}"), (b"{m}", b"Surface", b"{s}"),
                     (b"{s}", b"Path", b"/Measurement/Surface")],
                    dtype=[("Source", "S32"), ("Link", "S32"), ("Destination", "S32")])
    conv = np.dtype([("Category", "S16"), ("BaseUnit", "S16"), ("HeightUnit", "S16"),
                     ("Parameters", "<f8", (4,))])
    with h5py.File(path, "w") as h5:
        h5["MetaData"] = meta
        d = h5.create_dataset("Measurement/Surface", data=z_nm)
        d.attrs["Unit"] = np.array([b"NanoMeters"])
        d.attrs["No Data"] = np.array([no_data])
        d.attrs["X Converter"] = np.array([(b"LateralCat", b"Pixels", b"Meters", [0, px_m, 0, 0])], conv)
        d.attrs["Y Converter"] = np.array([(b"LateralCat", b"Pixels", b"Meters", [0, py_m, 0, 0])], conv)
        d.attrs["Z Converter"] = np.array([(b"HeightCat", b"NanoMeters", b"NanoMeters", [0, 1, 0, 0])],
                                          conv)


def test_zygo_datx_written_with_h5py(tmp_path):
    """Zygo stores rows in the picture's order, the first at the top (docs/formats.md): written
    turned upside down, the map reads back with row r at y = r·Δy."""
    z = heights_um()[::-1] * 1e3  # nm, the first stored row the top of the picture
    z[NY - 1 - BAD[0], BAD[1]] = 1.7e308
    write_datx(tmp_path / "m.datx", z, DX * 1e-3, DY * 1e-3, no_data=1.7e308)
    c = read_cloud(tmp_path / "m.datx")
    _check(c, heights_um(), 1e-9)


def write_metropro(path, z_m, lateral_res_m, wavelength_m=632.8e-9):
    """A MetroPro .dat, header format 1 (834 bytes, big endian), phase data only, byte by byte from
    the MetroPro Reference Guide (Zygo OMP-0347): height = counts · S · O · λ / 4096."""
    ny, nx = z_m.shape
    S, O, R = 0.5, 1.0, 4096.0
    counts = np.round(z_m / (S * O * wavelength_m / R))
    counts = np.where(np.isfinite(z_m), counts, 2147483640).astype(">i4")
    h = bytearray(834)

    def put(off, fmt, *v):
        struct.pack_into(fmt, h, off, *v)

    put(0, ">I", 0x881B036F)          # magic, header format 1
    put(4, ">H", 1)
    put(6, ">I", 834)                 # header size
    put(64, ">hhHH", 0, 0, nx, ny)    # connected-phase origin and size
    put(72, ">I", nx * ny * 4)        # phase bytes
    put(164, ">fff", S, wavelength_m, 0.0)  # intf_scale_factor, wavelength_in, num_aperture
    put(176, ">fff", O, 1.0, lateral_res_m)  # obliquity, magnification, lateral_res
    put(218, ">h", 0)                 # phase_res 0 → R = 4096
    path.write_bytes(bytes(h) + counts.tobytes())
    return counts.astype(np.float64) * S * O * wavelength_m / R


def test_metropro_dat_written_from_the_specification(tmp_path):
    z = heights_um() * 1e-6
    z[BAD] = np.nan
    # MetroPro pixels are square: use DX for both axes
    quant = write_metropro(tmp_path / "m.dat", z, DX * 1e-3)
    c = read_cloud(tmp_path / "m.dat")
    r, col = c["row"], c["col"]
    assert c.n == NX * NY - 1
    assert np.allclose(c.x, col * DX, atol=1e-12) and np.allclose(c.y, r * DX, atol=1e-12)
    # the first stored row is the top of MetroPro's picture: at y max, `row` counting from the bottom
    assert np.allclose(c.z, quant[NY - 1 - r, col] * 1e3, atol=1e-12)
    assert np.allclose(c.z[c.y == c.y.max()], quant[0][np.isfinite(z[0])] * 1e3, atol=1e-12)


def test_text_dat_still_reads_as_text(tmp_path):
    p = tmp_path / "pts.dat"
    p.write_text("x y z\n0 0 1\n1 0 2\n0 1 3\n", encoding="utf-8")
    assert read_cloud(p).n == 3


def test_bad_instrument_files(tmp_path):
    p = tmp_path / "broken.datx"
    p.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    with pytest.raises(InputError, match=r"broken.datx: not a Zygo DATX file.*damaged or truncated"):
        read_cloud(p)
    p = tmp_path / "broken.x3p"
    p.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(InputError, match=r"broken.x3p: not a readable X3P file"):
        read_cloud(p)
    import x3pio

    z = np.full((4, 5), np.nan)
    x3pio.write(str(tmp_path / "empty.x3p"), z, x_scale=1e-6, y_scale=1e-6)
    with pytest.raises(InputError, match="no valid pixel"):
        read_cloud(tmp_path / "empty.x3p")


# --- X3P without namespace (Sensofar), .datx in pixels and fringes, reader options -------------------
def _plain_x3p(src, dst, edit=lambda xml: xml):
    """x3pio's X3P with main.xml's root renamed to a namespace-less <ISO5436> (as Sensofar writes)."""
    import re
    import zipfile

    with zipfile.ZipFile(src) as zi, zipfile.ZipFile(dst, "w") as zo:
        for name in zi.namelist():
            data = zi.read(name)
            if name == "main.xml":
                xml = data.decode()
                xml = re.sub(r"<p:ISO5436_2[^>]*>", "<ISO5436>", xml).replace("</p:ISO5436_2>",
                                                                              "</ISO5436>")
                data = edit(xml).encode()
            zo.writestr(name, data)


def test_x3p_with_namespace_less_root_is_read(tmp_path):
    import x3pio

    z = heights_um() * 1e-6
    z[BAD] = np.nan
    x3pio.write(str(tmp_path / "m.x3p"), z, x_scale=DX * 1e-3, y_scale=DY * 1e-3)
    _plain_x3p(tmp_path / "m.x3p", tmp_path / "s.x3p")
    with pytest.raises(x3pio.X3pError):  # what made the file unreadable before
        x3pio.read(str(tmp_path / "s.x3p"))
    c = read_cloud(tmp_path / "s.x3p")
    _check(c, heights_um(), 1e-12)
    assert c.meta["invalid_dropped"] == 1 and "own reader" in c.meta["instrument_format"]
    _plain_x3p(tmp_path / "m.x3p", tmp_path / "p.x3p",
               lambda xml: xml.replace("<FeatureType>SUR</FeatureType>",
                                       "<FeatureType>PRF</FeatureType>"))
    with pytest.raises(InputError, match=r"p.x3p: X3P with a namespace-less <ISO5436> root "
                                         r"\(Sensofar\): feature type PRF is not supported"):
        read_cloud(tmp_path / "p.x3p")


def write_datx_units(path, z, height_unit=b"Fringes", lateral=(b"Pixels", b"Pixels", 1.0)):
    """A .datx whose heights and lateral converter are not lengths (an uncalibrated export)."""
    import h5py

    meta = np.array([(b"Root", b"Measurement", b"{m}"), (b"{m}", b"Surface", b"{s}"),
                     (b"{s}", b"Path", b"/Measurement/Surface")],
                    dtype=[("Source", "S32"), ("Link", "S32"), ("Destination", "S32")])
    conv = np.dtype([("Category", "S16"), ("BaseUnit", "S16"), ("HeightUnit", "S16"),
                     ("Parameters", "<f8", (4,))])
    with h5py.File(path, "w") as h5:
        h5["MetaData"] = meta
        d = h5.create_dataset("Measurement/Surface", data=z)
        d.attrs["Unit"] = np.array([height_unit])
        d.attrs["No Data"] = np.array([np.nan])
        for a in ("X Converter", "Y Converter"):
            d.attrs[a] = np.array([(b"LateralCat", lateral[0], lateral[1], [0, lateral[2], 0, 0])], conv)
        d.attrs["Z Converter"] = np.array([(b"HeightCat", height_unit, height_unit, [0, 1, 0, 0])], conv)


def test_datx_in_pixels_and_fringes_needs_named_options(tmp_path):
    """Read by the own h5py path; its first stored row is the top of the picture, as through
    SurfaceTopography's (written upside down, row r reads back at y = r·Δy)."""
    fr = heights_um() / 0.3164  # fringes of λ = 632.8 nm (λ/2 of height each)
    fr[BAD] = np.nan
    fr = fr[::-1]
    p = tmp_path / "fr.datx"
    write_datx_units(p, fr)
    with pytest.raises(InputError, match=r"fr.datx: Zygo DATX heights in Fringes; give the reader "
                                         r"option wavelength_nm"):
        read_cloud(p)
    with pytest.raises(InputError, match=r"fr.datx: Zygo DATX lateral converter in pixels without a "
                                         r"size; give the reader option pixel_size_um"):
        read_cloud(p, wavelength_nm=632.8)
    c = read_cloud(p, wavelength_nm=632.8, pixel_size_um=[DX * 1e3, DY * 1e3])
    _check(c, heights_um(), 1e-9)
    # heights in nm but pixels without a size: SurfaceTopography would take them for metres
    q = tmp_path / "nm.datx"
    write_datx_units(q, heights_um()[::-1] * 1e3, b"NanoMeters")
    with pytest.raises(InputError, match=r"nm.datx: .*give the reader option pixel_size_um"):
        read_cloud(q)
    c = read_cloud(q, pixel_size_um=[DX * 1e3, DY * 1e3])
    assert np.allclose(c.z * 1e3, heights_um()[c["row"], c["col"]], atol=1e-9)
    assert np.allclose(c.x, c["col"] * DX, atol=1e-12)
    # the same picture in metres and nm (SurfaceTopography's path) reads the same way up
    write_datx(tmp_path / "m.datx", heights_um()[::-1] * 1e3, DX * 1e-3, DY * 1e-3)
    a = read_cloud(tmp_path / "m.datx")
    assert a.meta["instrument_reader"] != c.meta["instrument_reader"]
    assert np.array_equal(a["row"], c["row"]) and np.allclose(a.z, c.z, atol=1e-12)


def test_options_on_a_calibrated_file_are_refused_by_name(tmp_path):
    z = heights_um() * 1e3
    write_datx(tmp_path / "m.datx", z, DX * 1e-3, DY * 1e-3)
    with pytest.raises(InputError, match=r"m.datx: the file gives its own lateral calibration; "
                                         r"remove the reader option pixel_size_um"):
        read_cloud(tmp_path / "m.datx", pixel_size_um=2.0)


def test_recipe_input_block(tmp_path):
    from pointspro.core.errors import RecipeError
    from pointspro.core.recipe import load_recipe

    def recipe(text):
        p = tmp_path / "r.yaml"
        p.write_text("pointspro: 1\n" + text + "steps: []\n", encoding="utf-8")
        return load_recipe(p)

    r = recipe("input:\n  pixel_size_um: [2.0, 3.0]\n  wavelength_nm: 632.8\n  invalid: error\n")
    assert r.input == {"pixel_size_um": [2.0, 3.0], "wavelength_nm": 632.8, "invalid": "error"}
    assert r.to_dict()["input"] == r.input
    assert recipe("").input == {}
    with pytest.raises(RecipeError, match=r"r.yaml, line 4: input: unknown reader option "
                                          r"'pixel_size' \(options: pixel_size_um"):
        recipe("input:\n  invalid: drop\n  pixel_size: 2\n")
    with pytest.raises(RecipeError, match=r"r.yaml, line 3: input: key 'invalid': drop or error"):
        recipe("input:\n  invalid: skip\n")
    with pytest.raises(RecipeError, match=r"r.yaml, line 2: input: must be a mapping"):
        recipe("input: 3\n")


def test_batch_passes_the_recipe_input_block_to_the_reader(tmp_path):
    from pointspro.core.batch import process_input
    from pointspro.core.recipe import parse_recipe

    fr = heights_um() / 0.3164
    write_datx_units(tmp_path / "fr.datx", fr)
    (tmp_path / "out").mkdir()
    r = parse_recipe({"pointspro": 1, "input": {"pixel_size_um": DX * 1e3, "wavelength_nm": 632.8},
                      "steps": []})
    out = process_input(tmp_path / "fr.datx", r, tmp_path / "out", "fr")
    assert out.ok, out.error
    bare = parse_recipe({"pointspro": 1, "steps": []})
    out = process_input(tmp_path / "fr.datx", bare, tmp_path / "out", "fr2")
    assert not out.ok and "wavelength_nm" in out.error


@pytest.mark.parametrize("name", ["metropro-1.dat", "sur-2.sur"])
def test_wavelength_on_a_map_in_a_length_unit_is_refused(name):
    """wavelength_nm is for heights in fringes or waves (Zygo .datx): a MetroPro or .sur map states
    its heights in a length unit, and the option was ignored silently (height_unit was refused)."""
    from pathlib import Path

    path = Path(__file__).parent / "data" / "realdata" / name
    with pytest.raises(InputError, match=r"wavelength_nm is for maps whose heights are in fringes"):
        read_cloud(path, wavelength_nm=1000.0)
    assert read_cloud(path).n > 0
