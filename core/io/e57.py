"""ASTM E57 point clouds (terrestrial laser scanners) through pye57 — the optional extra
``pip install 'pointspro[scanners]'``.

Every scan of the file is read and placed in the file's common frame (each scan's pose applied, as
pye57's ``read_scan(transform=True)`` does; scans stored as spherical range/azimuth/elevation are
converted to x, y, z). E57 stores lengths in **metres** (ASTM E2807, the standard's unit); they
become mm in one multiplication by 1000. Points the scanner marks invalid
(``cartesianInvalidState``/``sphericalInvalidState``) are dropped and counted in
``meta["invalid_dropped"]``. Channels: ``intensity``, ``red``/``green``/``blue``, ``row``/``col``
(the scanner's grid) when the file has them, and ``scan`` (0, 1 … the scan a point comes from) when
it holds several. ``index`` numbers the points read, scan after scan.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

INSTALL = "pip install 'pointspro[scanners]'"
MAGIC = b"ASTM-E57"
_CHANNELS = {"intensity": "intensity", "colorRed": "red", "colorGreen": "green", "colorBlue": "blue",
             "rowIndex": "row", "columnIndex": "col"}


def read_e57(path: Path):
    """(xyz (N,3) float64 mm, channels, meta) of an E57 file."""
    try:
        import pye57
    except ImportError:
        raise InputError(f"{path}: an E57 point cloud; reading it needs pye57: {INSTALL}") from None
    try:
        e57 = pye57.E57(str(path))
    except Exception as e:  # noqa: BLE001 - libE57 errors: one line naming the file
        raise InputError(f"{path}: a damaged or truncated E57 file ({_first_line(e)})") from None
    try:
        count = e57.scan_count
        if count == 0:
            raise InputError(f"{path}: an E57 file with no scan")
        parts, dropped = [], 0
        for i in range(count):
            try:
                data = e57.read_scan(i, intensity=True, colors=True, row_column=True, transform=True,
                                     ignore_missing_fields=True)
                stored = int(e57.get_header(i).point_count)
            except Exception as e:  # noqa: BLE001
                raise InputError(f"{path}: scan {i}: a damaged or unreadable E57 scan "
                                 f"({_first_line(e)})") from None
            parts.append(data)
            dropped += stored - len(data["cartesianX"])
    finally:
        e57.close()
    xyz = np.concatenate([np.column_stack([d["cartesianX"], d["cartesianY"], d["cartesianZ"]])
                          .astype(np.float64) for d in parts]) * 1e3
    if len(xyz) == 0:
        raise InputError(f"{path}: no valid point in the E57 file ({dropped} marked invalid)")
    if not np.isfinite(xyz).all():
        raise InputError(f"{path}: point {int(np.argwhere(~np.isfinite(xyz))[0, 0])} has a NaN/inf "
                         "coordinate")
    cols = {}
    for field, name in _CHANNELS.items():
        if all(field in d for d in parts):
            a = np.concatenate([np.asarray(d[field]) for d in parts])
            cols[name] = a.astype(np.float64) if a.dtype.kind == "f" else a.astype(np.int64)
    if count > 1:
        cols["scan"] = np.concatenate([np.full(len(d["cartesianX"]), i, np.int64)
                                       for i, d in enumerate(parts)])
    meta = {"format": "e57", "e57_scans": count, "instrument_unit": "m", "invalid_dropped": int(dropped)}
    return xyz, cols, meta


def _first_line(e: BaseException) -> str:
    s = str(e).strip()
    return s.splitlines()[0][:200] if s else type(e).__name__
