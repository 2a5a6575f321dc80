"""LAS / LAZ point clouds (ASPRS LAS 1.0–1.4; LAZ compressed) through laspy with the lazrs backend —
the optional extra ``pip install 'pointspro[scanners]'``.

Coordinates: laspy's *scaled* x, y, z (the stored integer counts × scale + offset), float64. LAS
states no unit of its own; the unit is the coordinate reference system's:

- the GeoTIFF keys ``ProjLinearUnitsGeoKey`` (x, y) and ``VerticalUnitsGeoKey`` (z) — metre, foot,
  US survey foot — or the WKT's ``UNIT``/``LENGTHUNIT`` (its own factor to metres; a ``VERT_CS`` /
  ``VERTCRS`` part gives z its own);
- none stated (a scanner's local frame, the common case): **metres** — the convention of LAS and of
  scanner software; ``meta["instrument_unit"]`` (in the report's ``input_file``) then says
  "m (assumed: the file states no unit)".

Then to mm in one multiplication per axis (× 1000 for metres, × 304.8 for feet). Every other point
dimension becomes a channel: intensity, classification, return_number, number_of_returns, gps_time,
red/green/blue/nir, point_source_id, scan_angle, extra bytes …; flags and fields that are zero at
every point (user_data, synthetic, withheld … when unused) are left out, intensity and classification
always kept. ``index`` is the point's number in the file.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import InputError

INSTALL = "pip install 'pointspro[scanners]'"
MAGIC = b"LASF"
_ALWAYS = ("intensity", "classification")
_RENAME = {"scan_angle_rank": "scan_angle"}
#: EPSG unit codes of the GeoTIFF keys → metres
_GEOKEY_UNITS = {9001: ("m", 1.0), 9002: ("ft", 0.3048), 9003: ("US survey ft", 1200 / 3937),
                 9030: ("nautical mile", 1852.0), 9036: ("km", 1000.0)}
_ANGULAR = re.compile(r"degree|radian|grad|arc|minute|second", re.I)
_WKT_UNIT = re.compile(r'(?:LENGTHUNIT|UNIT)\[\s*"([^"]+)"\s*,\s*([0-9.eE+-]+)')


def _laspy():
    try:
        import laspy
    except ImportError:
        return None
    return laspy


def read_las(path: Path):
    """(xyz (N,3) float64 mm, channels, meta) of a LAS or LAZ file."""
    laspy = _laspy()
    if laspy is None:
        raise InputError(f"{path}: a LAS/LAZ point cloud; reading it needs laspy: {INSTALL}")
    try:
        las = laspy.read(str(path))
    except Exception as e:  # noqa: BLE001 - laspy/lazrs errors: one line naming the file
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if "LazBackend" in msg or "lazrs" in msg.lower() or "laszip" in msg.lower():
            raise InputError(f"{path}: a compressed LAZ point cloud; reading it needs the lazrs "
                             f"backend: {INSTALL}") from None
        raise InputError(f"{path}: a damaged or truncated LAS/LAZ file ({msg})") from None
    n = len(las.points)
    if n == 0:
        raise InputError(f"{path}: a LAS/LAZ file with no points")
    (hname, hm), (vname, vm), stated = _units(las.header)
    xyz = np.column_stack([np.asarray(las.x, dtype=np.float64) * (hm * 1e3),
                           np.asarray(las.y, dtype=np.float64) * (hm * 1e3),
                           np.asarray(las.z, dtype=np.float64) * (vm * 1e3)])
    if not np.isfinite(xyz).all():
        raise InputError(f"{path}: point {int(np.argwhere(~np.isfinite(xyz))[0, 0])} has a NaN/inf "
                         "coordinate")
    cols = {}
    for dim in las.point_format.dimension_names:
        if dim in ("X", "Y", "Z"):
            continue
        a = np.asarray(las[dim])
        if a.ndim != 1:  # an extra-bytes array of several values: one channel each
            for k in range(a.shape[1]):
                _add(cols, f"{dim}_{k}", a[:, k])
            continue
        if dim not in _ALWAYS and not np.any(a):
            continue
        _add(cols, _RENAME.get(dim, dim), a)
    unit = hname if hname == vname else f"{hname} (x, y), {vname} (z)"
    meta = {"format": "laz" if las.header.are_points_compressed else "las",
            "las_version": str(las.header.version), "las_point_format": int(las.point_format.id),
            "instrument_unit": unit if stated else f"{unit} (assumed: the file states no unit)",
            "invalid_dropped": 0}
    return xyz, cols, meta


def _add(cols: dict, name: str, a: np.ndarray) -> None:
    name = re.sub(r"[^0-9A-Za-z_]+", "_", name).strip("_").lower() or "dim"
    if name[0].isdigit():
        name = "c_" + name
    if name in ("index", "x", "y", "z") or name in cols:
        name = "las_" + name
    cols[name] = a.astype(np.float64) if a.dtype.kind in "fb" else a.astype(np.int64)


def _units(header) -> tuple[tuple[str, float], tuple[str, float], bool]:
    """((horizontal unit, metres), (vertical unit, metres), whether the file states them)."""
    horizontal = vertical = None
    for vlr in getattr(header, "vlrs", []):
        keys = getattr(vlr, "geo_keys", None)
        if keys is not None:
            for k in keys:
                if k.tiff_tag_location == 0 and k.value_offset in _GEOKEY_UNITS:
                    if k.id == 3076:
                        horizontal = _GEOKEY_UNITS[k.value_offset]
                    elif k.id == 4099:
                        vertical = _GEOKEY_UNITS[k.value_offset]
        wkt = getattr(vlr, "string", None)
        if isinstance(wkt, bytes):
            wkt = wkt.decode("utf-8", "replace")
        if isinstance(wkt, str) and wkt.strip() and horizontal is None:
            m = re.search(r"VERT_CS|VERTCRS|VERTICALCRS", wkt)
            h_part, v_part = (wkt[:m.start()], wkt[m.start():]) if m else (wkt, "")
            horizontal = _wkt_unit(h_part)
            vertical = vertical or _wkt_unit(v_part)
    if horizontal is None and vertical is None:
        return ("m", 1.0), ("m", 1.0), False
    horizontal = horizontal or vertical
    return horizontal, vertical or horizontal, True


def _wkt_unit(wkt: str) -> tuple[str, float] | None:
    """The last linear unit a WKT part names, with its factor to metres."""
    found = [(name, float(f)) for name, f in _WKT_UNIT.findall(wkt) if not _ANGULAR.search(name)]
    if not found:
        return None
    name, f = found[-1]
    short = {"metre": "m", "meter": "m", "foot": "ft", "us survey foot": "US survey ft"}
    return short.get(name.lower(), name), f
