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
        Surface(z, DX * 1e3, DY * 1e3).save(tmp_path / f"m{suffix}")  # µm heights, µm steps
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
    z = heights_um() * 1e3  # nm, rows along y
    z[BAD] = 1.7e308
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
    assert np.allclose(c.z, quant[r, col] * 1e3, atol=1e-12)


def test_text_dat_still_reads_as_text(tmp_path):
    p = tmp_path / "pts.dat"
    p.write_text("x y z\n0 0 1\n1 0 2\n0 1 3\n")
    assert read_cloud(p).n == 3


def test_bad_instrument_files(tmp_path):
    p = tmp_path / "broken.datx"
    p.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    with pytest.raises(InputError, match=r"broken.datx: cannot read this instrument file"):
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
