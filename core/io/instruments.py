"""Areal files of interferometers and profilers → point clouds (x, y, z in mm, invalid pixels dropped).

Readers (maintained, not ours):
  .x3p  ISO 25178-72 — x3pio (reads the 2000 and the Amd 1:2020 revisions; SurfaceTopography's reader
        accepts only 'ISO5436 - 2000' files)
  .datx Zygo Mx (HDF5), .dat Zygo MetroPro, .sur Digital Surf, .sdf ISO 25178-71 / BCR — SurfaceTopography
        (pastewka/SurfaceTopography), with each file's lateral calibration and height unit.
Pixel (i, j) lies at x = x0 + i·Δx, y = y0 + j·Δy; the channels ``row`` (j) and ``col`` (i) keep the
pixel so a map can go back to the instrument's grid. Units are converted to mm from what the file
says; a file without lateral calibration is an error (never a silent "pixel = 1 mm").
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

AREAL_SUFFIXES = (".datx", ".sur", ".sdf", ".x3p")
METROPRO_MAGICS = (b"\x88\x1b\x03\x6f", b"\x88\x1b\x03\x70", b"\x88\x1b\x03\x71")


def is_metropro(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(4) in METROPRO_MAGICS


def _to_cloud(X_mm, Y_mm, Z_mm, valid, path):
    rows, cols = np.nonzero(valid)
    if rows.size == 0:
        raise InputError(f"{path}: no valid pixel (every height is marked invalid)")
    xyz = np.column_stack([X_mm[valid], Y_mm[valid], Z_mm[valid]]).astype(np.float64)
    return xyz, {"row": rows.astype(np.int64), "col": cols.astype(np.int64)}


def read_x3p(path: Path):
    import x3pio

    try:
        f = x3pio.read(str(path))
    except (x3pio.X3pError, OSError, ValueError) as e:
        raise InputError(f"{path}: not a readable X3P file ({e})") from None
    if isinstance(f, x3pio.PointCloud):
        p = np.asarray(f.layers[0].points, dtype=np.float64) * 1e3
        ok = np.all(np.isfinite(p), axis=1)
        return p[ok], {}, {"instrument_format": "x3p point cloud"}
    z = np.asarray(f.layers[0].z, dtype=np.float64)
    if z.ndim == 1:
        z = z[None, :]
    hx = f.header.x.increment * 1e3
    hy = (f.header.y.increment if f.header.y is not None else f.header.x.increment) * 1e3
    off = getattr(f, "placement", None)
    ox, oy, oz = (0.0, 0.0, 0.0) if off is None else tuple(np.asarray(off.offset) * 1e3)
    ny, nx = z.shape
    X, Y = np.meshgrid(ox + hx * np.arange(nx), oy + hy * np.arange(ny))
    xyz, ch = _to_cloud(X, Y, z * 1e3 + oz, np.isfinite(z), path)
    return xyz, ch, {"instrument_format": "x3p", "pixel_mm": [hx, hy]}


def read_surface_topography(path: Path):
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from SurfaceTopography.IO import open_topography
            from SurfaceTopography.Support.UnitConversion import get_unit_conversion_factor

            reader = open_topography(str(path))
            t = reader.topography()
    except Exception as e:  # the library raises its own classes (FileFormatMismatch, CorruptFile…)
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(f"{path}: cannot read this instrument file ({msg})") from None
    if t.dim != 2:
        raise InputError(f"{path}: a line profile, not an areal map")
    unit = t.unit
    if unit is None:
        raise InputError(f"{path}: the file gives no length unit, so its lateral calibration is unknown")
    unit = unit.replace("Âµ", "µ")  # a Latin-1 µ read as UTF-8 (Digital Surf files)
    to_mm = get_unit_conversion_factor(unit, "mm")
    h = np.ma.getdata(t.heights()).astype(np.float64)
    mask = np.ma.getmaskarray(t.heights())
    X, Y = t.positions()
    info = reader.channels[0].info.get("raw_metadata", {}) or {}
    if type(reader).__name__ == "SURReader" and "data_offset" in info:
        # SurfaceTopography 1.27 drops the Digital Surf header's z offset (heights = stored·scale +
        # offset in the file's data unit); tested against surfalize, which writes it
        h = h + float(info["data_offset"]) * float(info.get("data_unit_ratio", 1.0) or 1.0)
    # float files mark invalid pixels with NaN or with the type's extreme (surfalize writes −DBL_MAX
    # into .sdf, which SurfaceTopography 1.27 does not mask): no surface is 10³⁰ units high
    valid = ~mask & np.isfinite(h) & (np.abs(h) < 1e30)
    # SurfaceTopography's arrays are (x, y): index [i, j] is column i, row j
    xyz, ch = _to_cloud(X.T * to_mm, Y.T * to_mm, h.T * to_mm, valid.T, path)
    sx, sy = t.pixel_size
    return xyz, ch, {"instrument_format": reader.format(), "pixel_mm": [sx * to_mm, sy * to_mm],
                     "instrument_unit": unit}


def read_areal(path: Path):
    """(xyz mm, channels, meta) of an areal instrument file."""
    if path.suffix.lower() == ".x3p":
        return read_x3p(path)
    return read_surface_topography(path)
