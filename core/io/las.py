"""LAS / LAZ point clouds (ASPRS LAS 1.0–1.4; LAZ compressed) through laspy with the lazrs backend —
the optional extra ``pip install 'pointspro[scanners]'``.

Coordinates: laspy's *scaled* x, y, z (the stored integer counts × scale + offset), float64. LAS
states no unit of its own; the unit is the coordinate reference system's:

- the GeoTIFF keys ``ProjLinearUnitsGeoKey`` (x, y) and ``VerticalUnitsGeoKey`` (z) — metre, foot,
  US survey foot — or the WKT's ``UNIT``/``LENGTHUNIT`` (its own factor to metres), in a VLR or an
  EVLR: x, y the horizontal CRS's own unit, z the vertical CRS's (``VERT_CS``, ESRI ``VERTCS``, WKT2
  ``VERTCRS``/``VERTICALCRS``, wherever it stands); a factor of exactly 1 beside a unit named
  otherwise (``UNIT["US survey foot",1.0]``) is read as the named unit, and the report says so;
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
_GEOKEY_UNITS = {9001: ("m", 1.0, ""), 9002: ("ft", 0.3048, ""), 9003: ("US survey ft", 1200 / 3937, ""),
                 9030: ("nautical mile", 1852.0, ""), 9036: ("km", 1000.0, "")}
_ANGULAR = re.compile(r"degree|radian|grad|arc|minute|second", re.I)


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
    try:
        (hname, hm, hnote), (vname, vm, vnote), stated = _units(las.header)
    except InputError as e:  # a geographic CRS (_wkt_units)
        raise InputError(f"{path}: {e}") from None
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
    notes = [f"{axes}: {note}" for axes, note in (("x, y", hnote), ("z", vnote)) if note]
    if hnote and hnote == vnote:
        notes = [hnote]
    unit += f" ({'; '.join(notes)})" if notes else ""
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


#: GeoTIFF keys (GeoTIFF 1.0 §6.3; LAS 1.0–1.4's GeoKeyDirectoryTag VLR)
_GT_MODEL, _GEOGRAPHIC_TYPE, _PROJECTED_CS, _PROJ_LINEAR_UNITS, _VERTICAL_UNITS = 1024, 2048, 3072, 3076, 4099
_USER_DEFINED = 32767


def _metre_crs(code: int) -> bool:
    """Projected CRSs known to be in metres by their EPSG code, for a file that names one without
    its ProjLinearUnitsGeoKey: WGS 84 / UTM (326xx, 327xx), NAD83 / UTM (269xx), ETRS89 / UTM and
    ETRS89-extended (258xx), Web Mercator (3857), CH1903+ (2056), British National Grid (27700),
    DHDN / Gauss-Krüger (31466–31469), SWEREF99 TM (3006), Amersfoort / RD New (28992), ETRS89 / LAEA
    and LCC Europe (3035, 3034), GDA94 / GDA2020 MGA (283xx, 78xx), NAD83(2011) / UTM (6328–6348),
    RGF93 / Lambert-93 (2154), NZTM2000 (2193), ETRS-TM35FIN (3067), CS92 (2180), S-JTSK Krovak East
    North (5514), CH1903 LV03 (21781), MGI / Austria GK (31254–31259), Slovenia 1996 (3794), HTRS96
    (3765), ETRS89 / Austria Lambert (3416). Others (the US State Planes: metres or US feet by zone and
    realisation) are not guessed."""
    return (32601 <= code <= 32660 or 32701 <= code <= 32760 or 26901 <= code <= 26923
            or 6328 <= code <= 6348  # NAD83(2011) / UTM (USGS 3DEP's lidar)
            or 25828 <= code <= 25838 or code in (3857, 2056, 21781, 27700, 3006, 28992, 3035, 3034, 2154,
                                                  2193, 3067, 2180, 5514, 3794, 3765, 3416)
            or 31466 <= code <= 31469 or 31254 <= code <= 31259 or 28348 <= code <= 28358
            or 7846 <= code <= 7859)


def _units(header) -> tuple[tuple[str, float, str], tuple[str, float, str], bool]:
    """((horizontal unit, metres, note), (vertical unit, metres, note), whether the file states
    them); a note says how a unit was read when that is not plain.

    GeoKeys: GTModelTypeGeoKey 2 (geographic), or a GeographicTypeGeoKey without a projected CRS,
    is refused like a geographic WKT (a review: longitude 8.5° read as 8500 mm, "m" as if stated);
    a ProjectedCSTypeGeoKey without ProjLinearUnitsGeoKey takes the EPSG code's unit where it is
    known to be metres (``_metre_crs``) and is refused otherwise (EPSG:2263, in US survey feet, read
    as metres: 3.28× off); the vertical unit never stands in for x, y when a horizontal CRS is named."""
    horizontal = vertical = None
    keys_seen: dict[int, int] = {}
    for vlr in [*getattr(header, "vlrs", []), *(getattr(header, "evlrs", None) or [])]:
        keys = getattr(vlr, "geo_keys", None)
        if keys is not None:
            for k in keys:
                if k.tiff_tag_location != 0:
                    continue
                keys_seen.setdefault(int(k.id), int(k.value_offset))
                if k.value_offset in _GEOKEY_UNITS:
                    if k.id == _PROJ_LINEAR_UNITS:
                        horizontal = _GEOKEY_UNITS[k.value_offset]
                    elif k.id == _VERTICAL_UNITS:
                        vertical = _GEOKEY_UNITS[k.value_offset]
        wkt = getattr(vlr, "string", None)
        if isinstance(wkt, bytes):
            wkt = wkt.decode("utf-8", "replace")
        if isinstance(wkt, str) and wkt.strip() and horizontal is None:
            h, v = _wkt_units(wkt)
            horizontal = h
            vertical = vertical or v
    if horizontal is None and keys_seen:
        horizontal = _geokey_horizontal(keys_seen)
    if horizontal is None and vertical is None:
        return ("m", 1.0, ""), ("m", 1.0, ""), False
    horizontal = horizontal or vertical
    return horizontal, vertical or horizontal, True


def _geokey_horizontal(keys: dict[int, int]) -> tuple[str, float, str] | None:
    """x, y's unit from the GeoKeys that name a CRS but not its linear unit (None: they name none)."""
    model, projected = keys.get(_GT_MODEL), keys.get(_PROJECTED_CS)
    if model == 2 or (_GEOGRAPHIC_TYPE in keys and projected is None and model != 1):
        crs = keys.get(_GEOGRAPHIC_TYPE)
        named = f"EPSG:{crs}" if crs not in (None, _USER_DEFINED) else "GTModelTypeGeoKey 2"
        raise InputError(f"x, y are geographic coordinates (longitude, latitude in degrees; GeoKeys: {named}): "
                         "PointsPro measures in lengths — reproject the cloud to a projected or local CRS "
                         "in metres or feet")
    if projected is None or projected == _USER_DEFINED:
        return None
    if _metre_crs(projected):
        return "m", 1.0, f"EPSG:{projected}'s unit"
    raise InputError(f"the file names the projected CRS EPSG:{projected} but not its linear unit "
                     "(ProjLinearUnitsGeoKey), and PointsPro does not look units up in the EPSG "
                     "database — metres or feet would be a guess: add the key (e.g. PDAL's "
                     "writers.las a_srs, or las2las) or reproject to a local frame in metres")


# --- WKT -------------------------------------------------------------------------------------------
#: a vertical CRS: WKT1 OGC (VERT_CS), WKT1 ESRI (VERTCS), WKT2 (VERTCRS, VERTICALCRS)
_VERTICAL = {"VERT_CS", "VERTCS", "VERTCRS", "VERTICALCRS"}
#: a CRS whose axes x, y (and z when no vertical CRS is given) are lengths or angles
_HORIZONTAL = {"PROJCS", "PROJCRS", "PROJECTEDCRS", "GEOCCS", "GEODCRS", "GEODETICCRS", "LOCAL_CS",
               "ENGCRS", "ENGINEERINGCRS", "GEOGCS", "GEOGCRS", "GEOGRAPHICCRS"}
_UNIT_KEYS = {"UNIT", "LENGTHUNIT"}
#: a geographic CRS: its horizontal axes are angles
_GEOGRAPHIC = {"GEOGCS", "GEOGCRS", "GEOGRAPHICCRS"}
_WKT_TOKEN = re.compile(r'\s*(?:"((?:[^"]|"")*)"|([A-Za-z_][A-Za-z0-9_]*)\s*[\[(]|([\])])|(,)|'
                        r'([^\s,\[\]()"]+))')
#: linear units by name (lower case, "_" as " ") → metres: a factor of exactly 1 written beside a
#: name that is not metres is a writer's placeholder (libLAS-era VERTCS[…UNIT["US survey foot",1.0]]),
#: not a statement that the unit is a metre
_FT, _US_FT = 0.3048, 1200 / 3937
_NAMED = {"foot": _FT, "international foot": _FT, "foot international": _FT, "us survey foot": _US_FT,
          "foot us": _US_FT, "us foot": _US_FT, "survey foot": _US_FT, "millimetre": 1e-3,
          "millimeter": 1e-3, "centimetre": 1e-2, "centimeter": 1e-2, "kilometre": 1e3, "kilometer": 1e3}
_SHORT = {_FT: "ft", _US_FT: "US survey ft", 1e-3: "mm", 1e-2: "cm", 1e3: "km"}


def _wkt_tree(wkt: str) -> list:
    """The WKT as nested [keyword, arg, …] lists (strings, numbers as text, nodes); forgiving: an
    unclosed bracket closes at the end, stray text is skipped."""
    top: list = []
    stack = [top]
    pos = 0
    while pos < len(wkt):
        m = _WKT_TOKEN.match(wkt, pos)
        if not m or m.end() == pos:
            pos += 1
            continue
        pos = m.end()
        quoted, key, close, _comma, bare = m.groups()
        if key is not None:
            node = [key.upper()]
            stack[-1].append(node)
            stack.append(node)
        elif close is not None:
            if len(stack) > 1:
                stack.pop()
        elif quoted is not None:
            stack[-1].append(quoted.replace('""', '"'))
        elif bare is not None:
            stack[-1].append(bare)
    return top


def _find(nodes: list, keys: set, skip: set = frozenset()) -> list | None:
    """The first node (depth first) whose keyword is in ``keys``, not looking inside ``skip``
    (iterative: a WKT of thousands of nested brackets is no recursion error)."""
    stack = [iter(nodes)]
    while stack:
        node = next(stack[-1], None)
        if node is None:
            stack.pop()
        elif isinstance(node, list):
            if node[0] in keys:
                return node
            if node[0] not in skip:
                stack.append(iter(node[1:]))
    return None


def _crs_unit(crs: list) -> tuple[str, float, str] | None:
    """A CRS node's linear unit: its own UNIT/LENGTHUNIT (WKT1; WKT2 for all axes), else its first
    axis's (WKT2) — never one of a base CRS, datum, ellipsoid or parameter inside it."""
    units = [n for n in crs[1:] if isinstance(n, list) and n[0] in _UNIT_KEYS]
    axes = [n for n in crs[1:] if isinstance(n, list) and n[0] == "AXIS"]
    for node in units + [u for a in axes for u in a[1:] if isinstance(u, list) and u[0] in _UNIT_KEYS]:
        unit = _linear(node)
        if unit is not None:
            return unit
    return None


def _linear(node: list) -> tuple[str, float, str] | None:
    """(short name, metres, note) of a UNIT/LENGTHUNIT node; None for an angular or unreadable one."""
    if len(node) < 3 or not isinstance(node[1], str) or not isinstance(node[2], str) \
            or _ANGULAR.search(node[1]):
        return None
    try:
        f = float(node[2])
    except ValueError:
        return None
    if not (np.isfinite(f) and f > 0):
        return None
    name = node[1]
    named = _NAMED.get(re.sub(r"[_\s]+", " ", name).strip().lower())
    if f == 1.0 and named is not None:
        return _short(name), named, f'WKT UNIT["{name}",{node[2]}] read as the unit it names'
    return _short(name), f, ""


def _short(name: str) -> str:
    key = re.sub(r"[_\s]+", " ", name).strip().lower()
    return "m" if key in ("metre", "meter") else _SHORT.get(_NAMED.get(key), name)


def _wkt_units(wkt: str) -> tuple[tuple[str, float, str] | None, tuple[str, float, str] | None]:
    """(horizontal unit, vertical unit) of a WKT coordinate system — OGC or ESRI WKT1, WKT2. The
    vertical CRS is found wherever it stands (in a COMPD_CS/COMPOUNDCRS, after the PROJCS as ESRI
    writes it, or even inside the PROJCS); x, y take the horizontal CRS's own unit."""
    tree = _wkt_tree(wkt)
    vert = _find(tree, _VERTICAL)
    vertical = _crs_unit(vert) if vert is not None else None
    horiz = _find(tree, _HORIZONTAL, skip=_VERTICAL)
    if horiz is not None and horiz[0] in _GEOGRAPHIC:
        # longitude and latitude in degrees: no length unit x, y could be read in (they were taken
        # as the vertical unit's or metres: 0.0001° read as 0.1 mm)
        raise InputError(f"x, y are geographic coordinates (longitude, latitude in degrees; CRS "
                         f"{horiz[1] if len(horiz) > 1 and isinstance(horiz[1], str) else horiz[0]!r}): "
                         "PointsPro measures in lengths — reproject the cloud to a projected or local "
                         "CRS in metres or feet")
    if horiz is not None:
        return _crs_unit(horiz), vertical
    # no CRS keyword known here: the last linear unit outside the vertical CRS, as before
    found, stack = None, [iter(tree)]
    while stack:
        node = next(stack[-1], None)
        if node is None:
            stack.pop()
        elif isinstance(node, list) and node[0] not in _VERTICAL:
            if node[0] in _UNIT_KEYS:
                found = _linear(node) or found
            stack.append(iter(node[1:]))
    return found, vertical
