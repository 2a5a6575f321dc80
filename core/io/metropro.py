"""Zygo MetroPro .dat maps read directly with numpy (issue 17): the same numbers as SurfaceTopography's
reader without importing that library (1.5–3 s of a 300k-pixel map's 8 s on the project's machine).

The layout (big-endian; Zygo's MetroPro Reference Guide, section 12, "Data format"; as read by
SurfaceTopography.IO.MetroPro and Gwyddion's metropro.c):

    offset  field                 type
         0  magic                 881B036F, 881B0370 or 881B0371 (header formats 1, 2, 3)
         6  header_size           uint32: 834 (formats 1, 2) or 4096 (format 3)
        52  ac_org_width/height   uint16 ×2: the intensity frames' size (skipped)
        56  ac_n_buckets          uint16: intensity frames, 2 bytes a pixel
        68  cn_org_width/height   uint16 ×2: the phase map's columns, rows
       164  intf_scale_factor     float32
       168  wavelength_in         float32, m
       176  obliquity_factor      float32
       184  lateral_res           float32, m per pixel (0: not calibrated)
       218  phase_res             int16: 0, 1, 2 → 4096, 32768, 131072 counts a wave
       232  sign                  int16: non-zero flips the heights
    header_size + 2·ac_n_buckets·ac_width·ac_height: the phase map, int32 row by row; ≥ 2147483640
    marks an invalid pixel.

    height (m) = (−1 if sign else 1) · intf_scale_factor · obliquity_factor · wavelength / counts · value

A wavelength, intf_scale_factor or obliquity_factor of 0 or NaN is refused naming the field (every
height would be 0: a perfect part). ``read_metropro`` returns None for anything outside that common
case (a header of another size, no lateral calibration, reader options given, a short file): the
caller then reads the file with SurfaceTopography, whose messages name what is wrong. tests/test_speed_metropro.py compares both
readers bit for bit.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

MAGICS = {b"\x88\x1b\x03\x6f": 834, b"\x88\x1b\x03\x70": 834, b"\x88\x1b\x03\x71": 4096}
_COUNTS = {0: 4096, 1: 32768, 2: 131072}
_INVALID = 2147483640
_M_TO_MM = 1000.0


#: the header's height scales: (offset, name, must be positive)
_HEIGHT_SCALES = ((164, "intf_scale_factor", False), (168, "wavelength", True),
                  (176, "obliquity_factor", False))


def check_height_scales(path: Path, head: bytes) -> None:
    """InputError naming the first height scale of a MetroPro header (≥ 180 bytes) that is 0, NaN
    or inf (every height would be 0 or invalid: a "perfect" part), or a negative wavelength."""
    from .instruments import bad_header_scale

    for off, name, positive in _HEIGHT_SCALES:
        (v,) = struct.unpack_from(">f", head, off)
        err = bad_header_scale(path, name, v, "heights", positive)
        if err is not None:
            raise err


def read_metropro(path: Path, opts=None):
    """(xyz mm, channels, meta) as core.io.instruments.read_surface_topography gives them, or None
    when this file needs SurfaceTopography's reader (module doc). A height scale that would make
    every height 0 (or NaN) — wavelength, intf_scale_factor or obliquity_factor 0 or not a number,
    a negative wavelength — is refused naming the field, whoever reads the rest."""
    with open(path, "rb") as f:
        head = f.read(834)
        if len(head) < 834 or head[:4] not in MAGICS:
            return None
        check_height_scales(path, head)
        if opts is not None and (getattr(opts, "pixel_size_um", None) is not None
                                 or getattr(opts, "height_unit", None) is not None):
            return None  # the options' checks and messages are the general reader's
        (header_size,) = struct.unpack_from(">I", head, 6)
        ac_w, ac_h, ac_n = struct.unpack_from(">3H", head, 52)
        cn_w, cn_h = struct.unpack_from(">2H", head, 68)
        (intf,) = struct.unpack_from(">f", head, 164)
        (wavelength,) = struct.unpack_from(">f", head, 168)
        (obliquity,) = struct.unpack_from(">f", head, 176)
        (lateral,) = struct.unpack_from(">f", head, 184)
        (phase_res,) = struct.unpack_from(">h", head, 218)
        (sign,) = struct.unpack_from(">h", head, 232)
        if (header_size != MAGICS[head[:4]] or phase_res not in _COUNTS or not lateral > 0
                or cn_w == 0 or cn_h == 0):
            return None
        start = header_size + 2 * ac_n * ac_h * ac_w
        f.seek(start)
        raw = f.read(4 * cn_w * cn_h)
    if len(raw) != 4 * cn_w * cn_h:
        return None
    data = np.frombuffer(raw, dtype=">i4").reshape(cn_h, cn_w)
    # the same operations, in the same order, as SurfaceTopography's reader and our conversion
    scale = (-1.0 if sign != 0 else 1.0) * intf * obliquity * wavelength / _COUNTS[phase_res]
    h = scale * data.astype(np.float64)
    z = h * _M_TO_MM
    valid = (data < _INVALID) & np.isfinite(z) & (np.abs(h) < 1e30)
    sx = (lateral * cn_w) / cn_w  # physical size / points, as SurfaceTopography's pixel_size
    sy = (lateral * cn_h) / cn_h
    # y up MetroPro's picture: its first stored row is the top of the video monitor ("(0,0) is in
    # the upper left corner"), so stored row r lies at y = (rows − 1 − r)·Δy and `row` counts from
    # the bottom (docs/formats.md, Pixel convention; core/io/instruments.py _FIRST_LINE_AT_TOP)
    z, valid = z[::-1], valid[::-1]
    rows, cols = np.nonzero(valid)
    if rows.size == 0:
        from ..errors import InputError

        raise InputError(f"{path}: no valid pixel (every height is marked invalid)")
    xyz = np.empty((rows.size, 3))
    np.multiply(cols * sx, _M_TO_MM, out=xyz[:, 0])
    np.multiply(rows * sy, _M_TO_MM, out=xyz[:, 1])
    xyz[:, 2] = z[valid]
    meta = {"instrument_format": "metropro", "instrument_reader": "Zygo MetroPro DAT",
            "instrument_unit": "m", "pixel_mm": [np.float64(sx * _M_TO_MM), np.float64(sy * _M_TO_MM)],
            "grid": [int(cn_w), int(cn_h)], "invalid_dropped": int(valid.size - valid.sum())}
    return xyz, {"row": rows.astype(np.int64), "col": cols.astype(np.int64)}, meta
