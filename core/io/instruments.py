"""Areal files of interferometers, profilers and AFMs → point clouds (x, y, z in mm, invalid pixels
dropped and counted in ``meta["invalid_dropped"]``).

Readers (maintained, not ours), each chosen by the file's content, never by its extension alone:
  .x3p  ISO 25178-72 — x3pio (the 2000 and the Amd 1:2020 revisions). Files whose main.xml root is
        a namespace-less ``<ISO5436>`` (Sensofar) are refused by x3pio and SurfaceTopography; we read
        those ourselves (:func:`read_x3p_plain`: the same Record1/Record3 layout, binary point data).
        main.xml may lie in the one folder the file was zipped with (:func:`_x3p_folder`); absolute
        x/y axes give the stored coordinates (:func:`_x3p_absolute_axes`).
  everything else — SurfaceTopography (ContactEngineering/SurfaceTopography): Zygo .datx / MetroPro
        .dat, Digital Surf .sur, ISO 25178-71 .sdf, Wyko/Bruker .opd, Bruker .di, Sensofar .plu/.plux,
        Keyence .vk3/.vk4/.zon, Gwyddion .gwy, FRT .frt, Alicona .al3d, Igor .ibw, Agilent .mi, NMM,
        Dektak .opdx … with each file's lateral calibration and height unit. Its own detection tries
        the readers by content (magic bytes first); where no magic matches and one format alone uses
        the extension (.nms, .mat …), that reader is tried first (:func:`_open_by_extension`).
        Multi-channel files give their default height channel. Corrected here: NanoFocus .nms pixel
        in nm (:func:`_nms_lateral`), FRT's valid range (:func:`_frt_in_valid_range`), an Igor
        wave with Igor's default x/y scaling (1 per point, no unit) taken as uncalibrated, not as
        a pixel of one height unit (:func:`_ibw_uncalibrated`).
  Zygo .datx whose heights are in fringes or waves (SurfaceTopography refuses the unit): read here
        with h5py, heights × λ/2 (fringe) or × λ (wave) with the reader option ``wavelength_nm``.

Pixel convention (SurfaceTopography's ``positions()``): pixel (i, j) — column i, row j — lies at
x = x0 + i·Δx, y = y0 + j·Δy, so the first pixel is at the origin (x0 = y0 = 0 unless the file
gives an offset, as X3P does) and the points span (n − 1)·Δ while the map's size is n·Δ.
The channels ``row`` (j) and ``col`` (i) keep the pixel so a map can go back to the instrument's grid.
Units are converted to mm from what the file says. A file without lateral calibration is an error
naming the reader option ``pixel_size_um`` (never a silent "pixel = 1 mm"); heights without a
length unit need ``height_unit`` (or ``wavelength_nm`` for fringes/waves).

A header scale that would collapse the map — a wavelength, height scale, pixel size or increment of
0, NaN or inf (every height 0: a "perfect part"; every x equal), or a negative pixel size — is refused
naming the field (``bad_header_scale``: MetroPro, Digital Surf, Wyko OPD, SDF, MI, namespace-less
X3P). Where the reader's metadata does not show the field, ``check_map_geometry`` refuses the map
afterwards: x (y) all equal on several columns (rows), or every valid height equal on 100 pixels or
more (not for formats that store plain numbers without a scale, nor for x y z text).
"""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from ..errors import InputError

#: extensions of the areal formats (a reminder for file dialogs: the reader is chosen by content)
AREAL_SUFFIXES = (".datx", ".dat", ".sur", ".sdf", ".x3p", ".opd", ".opdx", ".mi", ".di", ".spm",
                  ".ibw", ".plu", ".plux", ".apx", ".zon", ".vk3", ".vk4", ".vk6", ".vk7",
                  ".gwy", ".frt", ".al3d", ".os3d", ".lext", ".oir", ".poir", ".mdt", ".ezd", ".nid",
                  ".tmd", ".zmg", ".mnt", ".jpk", ".qep", ".nc", ".h5", ".npy", ".npz", ".bcr",
                  ".bcrf", ".tif", ".tiff", ".xlsx", ".nms", ".hgt", ".mat")
METROPRO_MAGICS = (b"\x88\x1b\x03\x6f", b"\x88\x1b\x03\x70", b"\x88\x1b\x03\x71")
_LENGTH_TO_MM = {"nm": 1e-6, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "mm": 1.0, "m": 1e3}
_MAX_MSG = 160


def is_metropro(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(4) in METROPRO_MAGICS


def _short(e: BaseException, limit: int = _MAX_MSG) -> str:
    """The first line of a library's message, printable and bounded (some quote whole buffers)."""
    s = str(e).strip()
    s = s.splitlines()[0].strip() if s else type(e).__name__
    s = "".join(ch if ch.isprintable() else "?" for ch in s)
    return s if len(s) <= limit else s[:limit - 1] + "…"


# --- scales that collapse a map ------------------------------------------------------------------------
def bad_header_scale(path, field: str, value, what: str, positive: bool = False) -> InputError | None:
    """The error for a header scale that would collapse the map (0, NaN, inf: every height or every x
    the same) or, with ``positive``, mirror it (a negative pixel size or wavelength); None when the
    value is usable. ``what``: what the scale gives ("heights", "x positions")."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return InputError(f"{path}: the header's {field} is {str(value)[:40]!r}, not a number — "
                          f"{what} cannot be scaled")
    if not np.isfinite(v):
        return InputError(f"{path}: the header's {field} is {'not a number' if np.isnan(v) else v} "
                          f"— {what} cannot be scaled")
    if v == 0:
        return InputError(f"{path}: the header's {field} is 0 — {what} cannot be scaled")
    if positive and v < 0:
        return InputError(f"{path}: the header's {field} is negative ({v:g}) — {what} would be "
                          f"{'mirrored' if 'position' in what else 'upside down'}")
    return None


def _raise_bad(path, fields) -> None:
    """Raise the first bad_header_scale of (field, value, what, positive) tuples."""
    for field, value, what, positive in fields:
        err = bad_header_scale(path, field, value, what, positive)
        if err is not None:
            raise err


#: minimum valid pixels for "every height equal" to mean a zero scale (a real map is never that flat)
FLAT_MAP_PIXELS = 100


def check_map_geometry(path, xyz, channels, heights: bool = True) -> None:
    """Safety net after reading an instrument map, for scales its reader's metadata does not show:
    x (y) all equal on a map of several columns (rows), non-finite positions, or — with ``heights``,
    for maps whose heights come through a header's scale — every valid height exactly equal on
    ``FLAT_MAP_PIXELS`` pixels or more. Never for x y z text (a synthetic flat is legitimate there)."""
    n = len(xyz)
    if n == 0:
        return
    for k, axis, chan, along in ((0, "x", "col", "columns"), (1, "y", "row", "rows")):
        idx = channels.get(chan)
        v = xyz[:, k]
        if not np.isfinite(v).all():
            raise InputError(f"{path}: the map's {axis} positions are not finite numbers — a pixel "
                             f"size or {axis} scale in the header that is not a number?")
        if idx is None or n < 2:
            continue
        lo, hi = int(np.min(idx)), int(np.max(idx))
        if lo != hi and float(np.min(v)) == float(np.max(v)):
            raise InputError(f"{path}: every point has the same {axis} ({float(v[0]):g} mm) on a map "
                             f"of {hi - lo + 1} {along} — the {axis} spacing is 0; is a scale or pixel "
                             f"size in the header zero?")
    if heights and n >= FLAT_MAP_PIXELS:
        z = xyz[:, 2]
        if float(np.min(z)) == float(np.max(z)):
            raise InputError(f"{path}: all {n} valid heights are exactly {float(z[0]):g} mm — is a "
                             "height scale or wavelength in the header zero?")


#: header fields (SurfaceTopography's raw metadata) that scale a map: format → (key, name, what,
#: must be positive)
_HEADER_SCALES = {
    "metropro": (("intf_scale_factor", "intf_scale_factor", "heights", False),
                 ("wavelength_in", "wavelength", "heights", True),
                 ("obliquity_factor", "obliquity_factor", "heights", False)),
    "sur": (("grid_spacing_x", "x spacing", "x positions", True),
            ("grid_spacing_y", "y spacing", "y positions", True),
            ("height_scale_factor", "height scale", "heights", False)),
    "opd": (("Wavelength", "Wavelength", "heights", True),
            ("Pixel_size", "Pixel_size", "x and y positions", True),
            ("Aspect", "Aspect", "y positions", True)),
    "sdf": (("Xscale", "Xscale", "x positions", True), ("Yscale", "Yscale", "y positions", True),
            ("Zscale", "Zscale", "heights", False)),
    "mi": (("xLength", "xLength", "x positions", True), ("yLength", "yLength", "y positions", True)),
}
#: Digital Surf's binary header (little-endian float32 at these offsets) — checked before
#: SurfaceTopography reads it, whose messages for a NaN there are a bare TypeError
_SUR_SCALES = ((120, "x spacing (offset 120)", "x positions", True),
               (124, "y spacing (offset 124)", "y positions", True),
               (128, "height scale (offset 128)", "heights", False))


def _check_raw_scales(path, fmt: str, info: dict) -> None:
    fields = _HEADER_SCALES.get(fmt, ())
    _raise_bad(path, ((name, info[key], what, pos) for key, name, what, pos in fields if key in info))


def _check_sur_header(path, head: bytes) -> None:
    import struct

    if head[:12] not in (b"DIGITAL SURF", b"DSCOMPRESSED") or len(head) < 132:
        return
    _raise_bad(path, ((name, struct.unpack_from("<f", head, off)[0], what, pos)
                      for off, name, what, pos in _SUR_SCALES))


def _to_cloud(X_mm, Y_mm, Z_mm, valid, path):
    rows, cols = np.nonzero(valid)
    if rows.size == 0:
        raise InputError(f"{path}: no valid pixel (every height is marked invalid)")
    xyz = np.column_stack([X_mm[valid], Y_mm[valid], Z_mm[valid]]).astype(np.float64)
    return xyz, {"row": rows.astype(np.int64), "col": cols.astype(np.int64)}


def _grid_cloud(z_mm, dx_mm, dy_mm, path, x0=0.0, y0=0.0, valid=None):
    """A (rows = y, cols = x) height grid in mm → (xyz, channels, meta part)."""
    ny, nx = z_mm.shape
    X, Y = np.meshgrid(x0 + dx_mm * np.arange(nx), y0 + dy_mm * np.arange(ny))
    ok = np.isfinite(z_mm) if valid is None else valid & np.isfinite(z_mm)
    xyz, ch = _to_cloud(X, Y, z_mm, ok, path)
    return xyz, ch, {"pixel_mm": [float(dx_mm), float(dy_mm)], "grid": [int(nx), int(ny)],
                     "invalid_dropped": int(ok.size - ok.sum())}


# --- X3P ---------------------------------------------------------------------------------------------
def read_x3p(path: Path):
    import x3pio

    folder = _x3p_folder(path)  # "" (main.xml at the root, as ISO 25178-72 has it) or "name/"
    try:
        f = x3pio.read(str(path))  # x3pio 2.0 itself finds main.xml in a single folder
    except (x3pio.X3pError, OSError, ValueError, KeyError, EOFError) as e:
        plain = _plain_iso5436_root(path, folder)
        if plain:
            return read_x3p_plain(path, folder)
        raise InputError(f"{path}: not a readable X3P file ({_short(e)})") from None
    ftype = _x3p_feature_type(path, folder)
    if ftype == "PRF" or type(f).__name__ == "Profile":
        raise InputError(f"{path}: an X3P of feature type PRF (a line profile), not an areal map; "
                         "profiles are not yet supported as input")
    where = _x3p_folder_note(folder)
    layer = f.layers[0]
    if isinstance(f, x3pio.PointCloud):
        # x3pio 2.0: ``points`` is a method (the placement applied); 1.x had an attribute
        pts = layer.points() if callable(layer.points) else layer.points
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 3) * 1e3
        ok = np.all(np.isfinite(p), axis=1)
        return p[ok], {}, {"instrument_format": "x3p point cloud", **where,
                           "invalid_dropped": int((~ok).sum())}
    z = np.asarray(layer.z, dtype=np.float64)
    if z.ndim == 1:
        z = z[None, :]
    if f.header.y is not None and not (f.header.x.is_incremental and f.header.y.is_incremental):
        return _x3p_absolute_axes(path, layer, z.shape, where)
    hx = f.header.x.increment * 1e3
    hy = (f.header.y.increment if f.header.y is not None else f.header.x.increment) * 1e3
    off = getattr(f, "placement", None)
    ox, oy, oz = (0.0, 0.0, 0.0) if off is None else tuple(np.asarray(off.offset) * 1e3)
    xyz, ch, m = _grid_cloud(z * 1e3 + oz, hx, hy, path, ox, oy)
    check_map_geometry(path, xyz, ch, heights=False)  # x3pio refuses a zero or NaN increment itself
    return xyz, ch, {"instrument_format": "x3p", **where, **m}


def _x3p_absolute_axes(path: Path, layer, shape, where: dict):
    """A surface whose x or y axis is absolute (AxisType A): each point's stored coordinate, never
    its index × increment. ISO 25178-72 (Amd 1:2020, which x3pio follows for both revisions): an
    absolute axis's coordinate is the stored value × its Increment + its Offset, so CY with
    Increment 2, Offset 1 and stored 1, 2, 3, 4 is y = 3, 5, 7, 9 m (an incremental axis would give
    Offset + index × Increment = 1, 3, 5, 7: what PointsPro read before). x3pio's ``points()``
    applies this and the placement; a point whose coordinate or height is missing is dropped."""
    p = np.asarray(layer.points(), dtype=np.float64).reshape(-1, 3) * 1e3  # row-major: x fastest
    ny, nx = shape
    rows, cols = np.divmod(np.arange(ny * nx, dtype=np.int64), nx)
    ok = np.all(np.isfinite(p), axis=1)
    if not ok.any():
        raise InputError(f"{path}: no valid pixel (every height is marked invalid)")
    xyz, ch = p[ok], {"row": rows[ok], "col": cols[ok]}
    check_map_geometry(path, xyz, ch, heights=False)
    # no pixel_mm: along an absolute axis the points need not be evenly spaced
    return xyz, ch, {"instrument_format": "x3p (absolute x/y axis: stored coordinates)", **where,
                     "grid": [int(nx), int(ny)], "invalid_dropped": int((~ok).sum())}


#: what operating systems add to a folder they zip (x3pio 2.0 drops the same)
_ZIP_JUNK_NAMES = (".ds_store", "thumbs.db", "desktop.ini")


def _zip_junk(name: str) -> bool:
    *dirs, base = name.lower().split("/")
    return "__macosx" in dirs or base in _ZIP_JUNK_NAMES or base.startswith("._")


def x3p_main_xml_names(names) -> list[str]:
    """The members of a zip named main.xml (at any depth), leaving out what an operating system
    adds (``__MACOSX/``, ``._`` files)."""
    return [n for n in names if not _zip_junk(n) and (n == "main.xml" or n.endswith("/main.xml"))]


def _x3p_folder(path: Path) -> str:
    """Where the X3P's main.xml lies: '' at the archive's root (ISO 25178-72), 'name/' when the whole
    content was zipped with its folder (x3ptools' examples: ``csafe-logo/main.xml``,
    ``csafe-logo/bindata/data.bin``), which x3pio 2.0 reads and so do we, the links in main.xml then
    being relative to that folder. Several such folders, or one deeper down, are refused saying
    where main.xml is. '' too when the archive cannot be listed (x3pio's message says why)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as zf:
            mains = x3p_main_xml_names(n.replace("\\", "/") for n in zf.namelist())
    except Exception:  # noqa: BLE001 - not a zip, damaged: x3pio names it
        return ""
    if "main.xml" in mains or not mains:
        return ""
    folders = [m[:-len("main.xml")] for m in mains]
    if len(folders) > 1:
        raise InputError(f"{path}: not a readable X3P file — the archive holds main.xml in "
                         f"{len(folders)} folders ({', '.join(folders[:3])}), where ISO 25178-72 "
                         "puts one main.xml at the archive's root")
    if folders[0].count("/") > 1:
        raise InputError(f"{path}: not a readable X3P file — main.xml is in folder {folders[0]} of "
                         "the archive, where ISO 25178-72 puts it at the root (a file zipped with "
                         "its one folder is read; not one nested deeper)")
    return folders[0]


def _x3p_folder_note(folder: str) -> dict:
    return {"instrument_reader": f"main.xml in folder {folder}, not at the archive's root"} \
        if folder else {}


def _x3p_feature_type(path: Path, folder: str = "") -> str:
    """Record1/FeatureType of an X3P's main.xml ("SUR", "PRF", "PCL"), '' when unreadable (x3pio
    infers a surface from the data's shape whatever the header says)."""
    import xml.etree.ElementTree as ET
    import zipfile

    try:  # parsed up to the element only: main.xml may hold the data inline (DataList)
        with zipfile.ZipFile(path) as zf, zf.open(folder + "main.xml") as f:
            for _, node in ET.iterparse(f, events=("end",)):
                if isinstance(node.tag, str) and node.tag.rsplit("}", 1)[-1] == "FeatureType":
                    return (node.text or "").strip().upper()
    except Exception:  # noqa: BLE001 - x3pio has read it; nothing more to learn here
        return ""
    return ""


def _plain_iso5436_root(path: Path, folder: str = "") -> bool:
    """Whether main.xml's root is ``<ISO5436>`` without the ISO 5436-2 namespace (Sensofar)."""
    import xml.etree.ElementTree as ET
    import zipfile

    try:
        with zipfile.ZipFile(path) as zf:
            root = ET.fromstring(zf.read(folder + "main.xml"))
    except Exception:  # noqa: BLE001 - not a zip, no main.xml, bad XML: x3pio's message stands
        return False
    return root.tag in ("ISO5436", "ISO5436_2")


_X3P_TYPES = {"D": "<f8", "F": "<f4", "L": "<i4", "I": "<i2"}


def read_x3p_plain(path: Path, folder: str = ""):
    """An X3P whose main.xml has no namespace: Record1 axes (CX, CY incremental), Record3 matrix
    size and a binary PointDataLink (optional ValidPointsLink bit mask), heights × CZ increment.
    ``folder``: where main.xml lies in the archive ('' at the root, see :func:`_x3p_folder`); the
    links are relative to it."""
    import xml.etree.ElementTree as ET
    import zipfile

    def fail(what):
        raise InputError(f"{path}: X3P with a namespace-less <ISO5436> root (Sensofar): {what}")

    try:
        with zipfile.ZipFile(path) as zf:
            root = ET.fromstring(zf.read(folder + "main.xml"))
            names = {n[len(folder):] for n in zf.namelist() if n.startswith(folder)}
            r1, r3 = root.find("Record1"), root.find("Record3")
            if r1 is None or r3 is None:
                fail("main.xml has no Record1/Record3")
            ftype = (r1.findtext("FeatureType") or "").strip()
            if ftype != "SUR":
                fail(f"feature type {ftype or '?'} is not supported (only SUR, an areal map)")
            axes = {}
            for a in ("CX", "CY", "CZ"):
                node = r1.find(f"Axes/{a}")
                if node is None:
                    fail(f"axis {a} missing in Record1")
                axes[a] = node
            for a in ("CX", "CY"):
                if (axes[a].findtext("AxisType") or "").strip() != "I":
                    fail(f"axis {a} is not incremental (AxisType I); absolute x/y are not supported")
            inc = {a: float(axes[a].findtext("Increment") or 1.0) for a in axes}
            off = {a: float(axes[a].findtext("Offset") or 0.0) for a in axes}
            dtype = (axes["CZ"].findtext("DataType") or "D").strip()
            if dtype not in _X3P_TYPES:
                fail(f"CZ data type {dtype!r} is not supported (D, F, L, I)")
            _raise_bad(path, (("CX <Increment>", inc["CX"], "x positions", True),
                              ("CY <Increment>", inc["CY"], "y positions", True)))
            if _X3P_TYPES[dtype][1] == "i":  # integer heights are scaled by CZ's increment
                _raise_bad(path, (("CZ <Increment>", inc["CZ"], "heights", False),))
            bad_off = next((a for a in axes if not np.isfinite(off[a])), None)
            if bad_off:
                fail(f"axis {bad_off} <Offset> is {off[bad_off]}, not a finite number")
            size = r3.find("MatrixDimension")
            if size is None:
                fail("Record3 has no MatrixDimension")
            nx, ny, nz = (int(size.findtext(k) or 1) for k in ("SizeX", "SizeY", "SizeZ"))
            if nx < 1 or ny < 1:
                fail(f"matrix size {nx} × {ny} is not positive")
            if nz != 1:
                fail(f"SizeZ = {nz} layers are not supported (one layer)")
            link = (r3.findtext("DataLink/PointDataLink") or "").strip()
            if not link:
                fail("point data inline in main.xml (DataList) is not supported, only a "
                     "binary PointDataLink")
            if link not in names:
                fail(f"its point data {link} is missing from the archive")
            raw = zf.read(folder + link)
            valid_link = (r3.findtext("DataLink/ValidPointsLink") or "").strip()
            if valid_link and valid_link not in names:
                fail(f"its validity mask {valid_link} (ValidPointsLink) is missing from the archive")
            valid_raw = zf.read(folder + valid_link) if valid_link else None
    except zipfile.BadZipFile as e:
        raise InputError(f"{path}: not a readable X3P file ({_short(e)})") from None
    except ET.ParseError as e:
        raise InputError(f"{path}: X3P main.xml is not valid XML ({_short(e)})") from None
    except ValueError as e:
        raise InputError(f"{path}: X3P main.xml has a non-numeric size or increment ({_short(e)})") \
            from None
    dt = np.dtype(_X3P_TYPES[dtype])
    if len(raw) != nx * ny * dt.itemsize:
        raise InputError(f"{path}: X3P point data holds {len(raw)} bytes where {nx} × {ny} values of "
                         f"type {dtype} need {nx * ny * dt.itemsize} (truncated or damaged)")
    z = np.frombuffer(raw, dt).astype(np.float64).reshape(ny, nx)  # x runs fastest
    z = z * (inc["CZ"] if dt.kind == "i" else 1.0) + off["CZ"]
    valid = np.ones_like(z, bool)
    if valid_raw is not None:
        need = (nx * ny + 7) // 8
        if len(valid_raw) < need:
            fail(f"its validity mask {valid_link} holds {len(valid_raw)} bytes where {nx} × {ny} "
                 f"pixels need {need} (truncated or damaged)")
        bits = np.unpackbits(np.frombuffer(valid_raw, np.uint8), bitorder="little")
        valid = bits[:nx * ny].reshape(ny, nx).astype(bool)
    xyz, ch, m = _grid_cloud(z * 1e3, inc["CX"] * 1e3, inc["CY"] * 1e3, path, off["CX"] * 1e3,
                             off["CY"] * 1e3, valid)
    check_map_geometry(path, xyz, ch, heights=False)  # the increments are checked above
    return xyz, ch, {"instrument_format": "x3p (namespace-less ISO5436, own reader)",
                     **_x3p_folder_note(folder), **m}


# --- SurfaceTopography ----------------------------------------------------------------------------
def st_extension_names(suffix: str) -> str:
    """The SurfaceTopography format names that use this extension ("Wyko OPD"), or ''."""
    s = suffix.lower().lstrip(".")
    if not s:
        return ""
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from SurfaceTopography.IO import readers
    except Exception:  # noqa: BLE001 - a broken install: no hint
        return ""
    names = [r.name() for r in readers if s in (r._file_extensions or []) and r.format() not in
             ("asc", "xyz", "npz")]
    return " or ".join(dict.fromkeys(names))


#: heads that name a format whose SurfaceTopography reader answers only "maybe" to them: a Bruker
#: Nanoscope file begins with its "\*File list" header (a truncated .di read "unknown file type"
#: where its reader knew it was short: a review)
_OWN_MAGIC = {"di": b"\\*File list"}


def _magic_readers(head: bytes):
    """SurfaceTopography readers whose magic bytes match the file's head."""
    with quiet():
        from SurfaceTopography.IO import MagicMatch, readers

        return [r for r in readers if r.can_read(head[:512]) == MagicMatch.YES
                or head.startswith(_OWN_MAGIC.get(r.format(), b"\0never"))]


def st_magic_names(head: bytes) -> list[str]:
    """Names of the instrument formats whose magic bytes the head matches (imports the library)."""
    return [r.name() for r in _magic_readers(head)]


class quiet:
    """SurfaceTopography's warnings, stray prints (a reader prints whole buffers) and its readers'
    log records kept off the terminal: trying each format on a truncated .opd, igor2's reader logged
    an error quoting the whole file — one line of 6.5 MB on stderr (a review). Records of other
    loggers than PointsPro's, from the reading thread, are dropped by the root handlers (and
    logging's last resort) while a file is read; PointsPro's own and other threads' pass.

    sys.stdout, sys.stderr and the warnings' filters belong to the process, not to a thread: the
    first of overlapping blocks (the window reads in a worker thread while another reads a hint)
    silences them, the last one out restores them. Each block restoring what it found left
    sys.stdout a StringIO for good when two threads' blocks overlapped out of order (a review);
    hence the one lock and count, on the class, for the one process-wide resource."""

    _lock = threading.Lock()
    _depth = 0
    _shared = None  # the ExitStack holding the redirections while any block is open

    def __enter__(self):
        import contextlib
        import io
        import logging
        import warnings

        with quiet._lock:
            if quiet._depth == 0:
                shared = contextlib.ExitStack()
                shared.enter_context(warnings.catch_warnings())
                warnings.simplefilter("ignore")
                shared.enter_context(contextlib.redirect_stdout(io.StringIO()))
                shared.enter_context(contextlib.redirect_stderr(io.StringIO()))
                quiet._shared = shared
            quiet._depth += 1
        self._stack = contextlib.ExitStack()
        only = _OnlyPointsPro()  # its own: a nested quiet's exit must not remove the outer one's
        # (and only this thread's records: another thread's — the window reads in a worker — pass)
        for handler in [*logging.getLogger().handlers, logging.lastResort]:
            if handler is not None:
                handler.addFilter(only)
                self._stack.callback(handler.removeFilter, only)
        return self

    def __exit__(self, *exc):
        self._stack.close()
        with quiet._lock:
            quiet._depth -= 1
            if quiet._depth == 0:
                shared, quiet._shared = quiet._shared, None
                shared.close()
        return False


class _OnlyPointsPro:
    """Drops the records of other loggers than PointsPro's emitted by the thread that made it."""

    def __init__(self):
        import threading

        self.thread = threading.get_ident()

    def filter(self, record) -> bool:
        return (record.thread != self.thread or record.name == "pointspro"
                or record.name.startswith("pointspro."))


def read_surface_topography(path: Path, opts=None, head: bytes | None = None):
    """(xyz mm, channels, meta) of any file SurfaceTopography reads, found by content; a map whose
    header scales collapse it (a zero wavelength, pixel size, height scale) is refused naming the
    field, or — where the reader's metadata does not show it — by check_map_geometry."""
    if opts is None:
        from .formats import ReaderOptions

        opts = ReaderOptions()
    if head is None:
        with open(path, "rb") as f:
            head = f.read(4096)
    _check_sur_header(path, head)
    xyz, ch, meta = _read_surface_topography(path, opts, head)
    check_map_geometry(path, xyz, ch, heights=meta.get("instrument_format") not in _PLAIN_ARRAYS)
    return xyz, ch, meta


#: SurfaceTopography formats that store heights as plain numbers, no header scale (a synthetic flat
#: array is legitimate there)
_PLAIN_ARRAYS = ("npy", "npz", "mat", "h5", "nc", "xyz", "asc")


def _read_surface_topography(path: Path, opts, head: bytes):
    if head[:4] in METROPRO_MAGICS:  # the common MetroPro map without importing SurfaceTopography
        from .metropro import read_metropro

        got = read_metropro(path, opts)
        if got is not None:
            return got
    with quiet():  # the library warns about metadata and prints; never on the terminal
        try:
            from SurfaceTopography.IO import open_topography
        except Exception as e:  # noqa: BLE001
            raise InputError(f"{path}: SurfaceTopography cannot be imported ({_short(e)})") from None
        magic = _magic_readers(head)
        reader = _open_by_extension(path, magic)
        if reader is None:
            try:
                reader = open_topography(str(path))
            except Exception as e:  # noqa: BLE001 - the library raises many classes
                raise _not_readable(path, head, e) from None
        if magic and type(reader) not in magic:
            # a reader without magic (NASA SRTM, NumPy …) took a file whose magic names another
            # format: that format's reader failed on it — say so, with its own words
            reader.close()
            try:
                reader = open_topography(str(path), format=magic[0].format())
            except Exception as e:  # noqa: BLE001
                raise InputError(f"{path}: a damaged or truncated {magic[0].name()} file "
                                 f"({_short(e)})") from None
        if reader.format() == "hgt" and path.suffix.lower() != ".hgt":
            # SRTM has no header: its reader takes any file of 2·n² bytes (5,000 random bytes read
            # as a 50 × 50 elevation map); only a .hgt file is one (review 2026-11-26)
            reader.close()
            raise _not_readable(path, head, _no_format())
        try:
            if reader.format() in ("h5", "datx") and _is_datx(path) and (
                    reader.format() == "h5" or not _datx_lateral_in_length(path)):
                return _read_datx_own(path, opts)
            return _topography_to_cloud(path, reader, opts, head)
        finally:
            try:
                reader.close()
            except Exception:  # noqa: BLE001
                pass


#: readers never tried first for their extension: they take almost any text (a Wyko ASCII or SDF
#: file named .txt must still reach its own reader)
_NOT_BY_EXTENSION = ("asc", "xyz")


def _extension_format(suffix: str) -> str | None:
    """The one SurfaceTopography format that uses this extension ('nms' for .nms), None when none or
    several do (.dat: MetroPro and plain text)."""
    from SurfaceTopography.IO import readers

    s = suffix.lower().lstrip(".")
    fmts = {r.format() for r in readers if s and s in (r._file_extensions or [])}
    return fmts.pop() if len(fmts) == 1 and not fmts & set(_NOT_BY_EXTENSION) else None


def _open_by_extension(path: Path, magic):
    """The reader of the file's extension when the extension names one format and no reader's
    magic bytes claim the file, or None (then SurfaceTopography's detection decides).

    Formats without magic bytes (NanoFocus NMS, MATLAB, NumPy …) are told apart only by trying each
    reader in turn, and a reader that opens a file is not one that reads it: SurfaceTopography 1.27
    opens a .nms (st_nms-2.nms) with its MATLAB reader, which then fails ("list index out of range")
    while its NMS reader reads the file. The extension's own reader goes first; if it cannot open
    the file, the detection by content runs as before — magic bytes still outrank an extension (a
    .sur renamed .opd is read as a .sur)."""
    from SurfaceTopography.IO import open_topography

    fmt = None if magic else _extension_format(path.suffix)
    if fmt is None:
        return None
    try:
        return open_topography(str(path), format=fmt)
    except Exception:  # noqa: BLE001 - not that format after all: the content decides
        return None


def _no_format() -> Exception:
    from SurfaceTopography.Exceptions import CannotDetectFileFormat

    return CannotDetectFileFormat("no reader recognises the content")


def _not_readable(path: Path, head: bytes, e: BaseException) -> InputError:
    from SurfaceTopography.Exceptions import CannotDetectFileFormat

    from .formats import foreign_kind

    suffix = path.suffix.lower()
    claimed = st_extension_names(suffix)
    if not isinstance(e, CannotDetectFileFormat):  # a reader recognised the file and then failed
        return InputError(f"{path}: cannot read this instrument file ({_short(e)})")
    magic = _magic_readers(head)
    if magic:
        # the detection hides why the reader refused: ask that reader alone for its reason
        why = ""
        try:
            from SurfaceTopography.IO import open_topography

            open_topography(str(path), format=magic[0].format()).close()
        except Exception as e2:  # noqa: BLE001 - the library raises many classes
            why = f" ({_short(e2, 150)})"
        return InputError(f"{path}: a damaged or truncated {magic[0].name()} file — its header is "
                          f"recognised but it cannot be read{why}")
    what = foreign_kind(head)
    lie = f"; the extension '{suffix}' says {claimed}" if claimed else ""
    if what:
        return InputError(f"{path}: {what}, not a measurement file{lie}")
    if claimed:
        return InputError(f"{path}: not a {claimed} file, nor any format PointsPro or "
                          f"SurfaceTopography recognises by content (damaged or truncated?)")
    return InputError(f"{path}: unknown file type '{suffix}' — no reader recognises its content; "
                      f"PointsPro reads x y z text, PLY/PCD/PTS, X3P and the instrument formats of "
                      f"SurfaceTopography (see docs/formats.md)")


def _height_channel(reader):
    chans = reader.channels
    default = reader.default_channel
    if getattr(default, "is_height_channel", True) and default.dim == 2:
        return chans.index(default), default
    for i, c in enumerate(chans):
        if getattr(c, "is_height_channel", True) and c.dim == 2:
            return i, c
    return chans.index(default), default


def _unit_to_mm(unit):
    from SurfaceTopography.Support.UnitConversion import get_unit_conversion_factor

    return get_unit_conversion_factor(unit, "mm")


def _topography_to_cloud(path: Path, reader, opts, head: bytes):
    from SurfaceTopography.Support.UnitConversion import is_length_unit

    fmt = reader.format()
    try:
        idx, ch = _height_channel(reader)
    except Exception as e:  # noqa: BLE001
        raise InputError(f"{path}: cannot read this {reader.name()} file ({_short(e)})") from None
    if ch.dim != 2:
        raise InputError(f"{path}: a line profile ({reader.name()}), not an areal map; profiles are "
                         "not yet supported as input")
    _check_raw_scales(path, fmt, ch.info.get("raw_metadata", {}) or {})
    unit = ch.unit.replace("Âµ", "µ") if isinstance(ch.unit, str) else ch.unit  # Latin-1 µ as UTF-8
    # no lateral calibration: none in the reader's metadata, or an Igor wave whose x/y scaling is
    # Igor's default (SurfaceTopography reads it as a pixel of 1 height unit)
    no_lateral = "pixel size" if ch.physical_sizes is None else None
    if fmt == "ibw" and no_lateral is None:
        no_lateral = _ibw_uncalibrated(path)
    kwargs = {}
    if unit is None or not is_length_unit(unit):
        if opts.height_unit is None:
            if no_lateral is not None and opts.pixel_size_um is None:
                raise InputError(f"{path}: the {reader.name()} file gives no length unit for its "
                                 f"heights{f' ({unit})' if unit else ''} and no lateral calibration "
                                 f"({no_lateral}); give the reader options height_unit (nm, µm, mm or "
                                 "m) and pixel_size_um (µm), e.g. `input: {pixel_size_um: 1.1, "
                                 "height_unit: nm}` in the recipe")
            raise InputError(f"{path}: the {reader.name()} file gives no length unit for its heights"
                             f"{f' ({unit})' if unit else ''}; give the reader option height_unit "
                             "(nm, µm, mm or m)")
        unit = "µm" if opts.height_unit in ("um", "μm") else opts.height_unit
        kwargs["unit"] = unit
    elif opts.height_unit is not None:  # was ignored silently, while pixel_size_um was refused
        raise InputError(f"{path}: the file gives its own height unit ({unit}); remove the reader "
                         "option height_unit")
    if no_lateral is not None:
        if opts.pixel_size_um is None:
            raise InputError(f"{path}: the {reader.name()} file gives no lateral calibration "
                             f"({no_lateral}); give the reader option pixel_size_um (µm), e.g. "
                             "`input: {pixel_size_um: 1.1}` in the recipe")
        if ch.physical_sizes is None:
            to_unit = 1e-3 / _unit_to_mm(unit)  # µm → the file's unit
            nx, ny = ch.nb_grid_pts
            kwargs["physical_sizes"] = (nx * opts.pixel_size_um[0] * to_unit,
                                        ny * opts.pixel_size_um[1] * to_unit)
        # else (Igor): the reader refuses physical_sizes; the positions are set below
    elif opts.pixel_size_um is not None:
        raise InputError(f"{path}: the file gives its own lateral calibration; remove the reader "
                         "option pixel_size_um")
    try:
        t = reader.topography(channel_index=idx, **kwargs)
        h_ma = t.heights()
        if t.dim == 2:
            X, Y = t.positions()  # fails too on a damaged header (sizes of the wrong shape …)
            sx, sy = t.pixel_size
    except Exception as e:  # noqa: BLE001 - truncated data blocks, bad headers …
        magic = "damaged or truncated " if _magic_readers(head) else ""
        raise InputError(f"{path}: cannot read this {magic}{reader.name()} file ({_short(e)})") \
            from None
    if t.dim != 2:
        raise InputError(f"{path}: a line profile ({reader.name()}), not an areal map; profiles are "
                         "not yet supported as input")
    to_mm = _unit_to_mm(unit)
    h = np.ma.getdata(h_ma).astype(np.float64)
    mask = np.ma.getmaskarray(h_ma)
    info = ch.info.get("raw_metadata", {}) or {}
    if fmt == "sur" and "data_offset" in info:
        # SurfaceTopography 1.27 drops the Digital Surf header's z offset (heights = stored·scale +
        # offset in the file's data unit); tested against surfalize, which writes it
        h = h + float(info["data_offset"]) * float(info.get("data_unit_ratio", 1.0) or 1.0)
    # float files mark invalid pixels with NaN or with the type's extreme (surfalize writes −DBL_MAX
    # into .sdf, which SurfaceTopography 1.27 does not mask): no surface is 10³⁰ units high
    valid = ~mask & np.isfinite(h) & (np.abs(h) < 1e30)
    if fmt == "frt":
        valid &= _frt_in_valid_range(info, h)
    X_mm, Y_mm, pixel = X * to_mm, Y * to_mm, [sx * to_mm, sy * to_mm]
    if fmt == "nms":
        X_mm, Y_mm, pixel = _nms_lateral(path, t.nb_grid_pts)
    elif no_lateral is not None and ch.physical_sizes is not None:  # Igor: default x/y scaling
        X_mm, Y_mm, pixel = _pixel_grid(t.nb_grid_pts, opts.pixel_size_um[0] * 1e-3,
                                        opts.pixel_size_um[1] * 1e-3)
    if fmt == "ps" and int(info.get("swap_xy", 0) or 0):
        raise InputError(f"{path}: a Park Systems TIFF scanned with its axes swapped (header swap_xy "
                         f"= {info.get('swap_xy')}): SurfaceTopography 1.27 reads its lines as x "
                         "lines, Gwyddion turns them by 90°, and which is right is not established — "
                         "not read rather than read turned; export the map as X3P or a text matrix")
    if fmt in _FIRST_LINE_AT_Y0 or fmt in _FIRST_LINE_AT_TOP:  # y up the instrument's picture:
        # SurfaceTopography's rows are Gwyddion's (row 0 at the top), reversed (docs/formats.md)
        # Igor .ibw: an Igor wave states its own coordinates, x = sfB₀ + i·sfA₀, y = sfB₁ + j·sfA₁ (dimension 0 the
        # rows, 1 the columns); SurfaceTopography 1.27 gives dimension 1 reversed, which put the wave's
        # y = 0 line at the top of our y-up frame: a mirror (y-odd Zernike terms, a correction's side,
        # flipped). Gwyddion's igorfile.c flips the wave vertically for its y-down image rows — the
        # same picture as the wave's own y up (checked pixel by pixel on spot_1-1000nm.ibw)
        # —
        # Nanosurf .nid/.ezd: stored line q lies at the file's own y = Dim1Min + q·Dim1Range/Lines
        # (the slow axis, y up), whatever its "Scan direction": lines are stored by position, not
        # by time. On st_nid-1.nid ("Up", CurLine=255) the feedback's settling transient is in
        # lines 0–3, the first ones scanned; on Nanosurf's own "Down" examples (NSFopen,
        # CurLine=0) the scan ran from line 255 to 0 — SBS-PMMA.nid's one z step falls in line
        # 251's backward trace between a raised 252 and a normal 250. Nanosurf's readers
        # (NSFopen, nanosurf's nid_reader: reshape(Lines, Points), plotted origin="lower") and
        # Gwyddion's ezdfile.c (rows flipped for its y-down image) ignore the direction too.
        # SurfaceTopography 1.27 flips dimension 1 (np.fliplr), which put line 0 at y max: a
        # y mirror (checked pixel by pixel on st_nid-1.nid; no .ezd file was at hand, it shares the
        # reader and Gwyddion's flip); undone here. Dim0Min/Dim1Min are not applied: the first
        # pixel is at the origin, as for the other maps
        # —
        # Bruker/Veeco Nanoscope .di: the first stored line is the bottom of the scan (y = 0; Bruker:
        # "Frame Up" starts at the bottom), which Gwyddion's nanoscope.c turns upside down for its
        # y-down image rows, as for Igor and Nanosurf above. SurfaceTopography 1.27 flips dimension 1
        # (np.fliplr, to look like Gwyddion), which put line 0 at y max: a y mirror (an independent
        # review: the file's int16 lines parsed by hand correlate 1.000000 with our rows reversed,
        # 0.39 in order, on SurfaceTopography's di-1.di and di-3.di); undone here
        # —
        # Park Systems TIFF, WSxM, FRT MicroProf, Molecular Imaging .mi, Wyko OPD, NT-MDT: their first
        # stored line is the bottom of the image (the instrument's picture, y up): Gwyddion turns them
        # upside down for its y-down rows (psia.c, wsxmfile.c, microprof.c, mifile.c, opdfile.c,
        # nt-mdt.c), and SurfaceTopography 1.27 follows it — "the first stored row is the bottom line
        # of the image; flip it to match the orientation of Gwyddion" (IO/FRT.py; the same in PS.py,
        # MI.py, MDT.py, OPD.py; WSXM.py turns the map by 180°, x right again). Our y = j·Δy then put
        # the first line at y max: the instrument's picture mirrored, y-odd terms of a freeform and a
        # correction's side flipped. Checked against the raw lines decoded by hand (an independent
        # review, 2026-11-28; tests/test_map_orientation.py): mi-1, opd-1, frt-1, example_ps.tiff,
        # stp-1, top-1 correlate 1.000000 with our rows once undone. No NT-MDT file was at hand.
        h, valid = h[:, ::-1], valid[:, ::-1]
    # SurfaceTopography's arrays are (x, y): index [i, j] is column i, row j
    xyz, chans = _to_cloud(X_mm.T, Y_mm.T, h.T * to_mm, valid.T, path)
    return xyz, chans, {"instrument_format": fmt, "instrument_reader": reader.name(),
                        "instrument_unit": unit, "pixel_mm": pixel,
                        "grid": [int(t.nb_grid_pts[0]), int(t.nb_grid_pts[1])],
                        "invalid_dropped": int(valid.size - valid.sum())}


#: SurfaceTopography formats whose first stored line lies at y = 0 (the bottom of the instrument's
#: picture, y up) and which SurfaceTopography 1.27 reverses to look like Gwyddion's y-down image rows;
#: the reader undoes that (_topography_to_cloud).
_FIRST_LINE_AT_Y0 = ("ibw", "ezd", "di", "ps", "wsxm", "frt", "mi", "opd", "mdt")
#: formats whose first stored line is the TOP of the instrument's picture, established: Zygo's
#: (MetroPro .dat, here through SurfaceTopography only for files the own reader passes over, and
#: .datx) — "(0,0) is in the upper left corner of the video monitor" (MetroPro Reference Guide, as
#: quoted by SOLEIL's Superflat reader), and prysm (prysm/io.py) turns both so that y increases
#: upward; Gwyddion reads them in that order for its y-down rows. JPK, whichever way its lines are
#: stored: SurfaceTopography and Gwyddion's jpkscan.c put an unreflected file's first line at the
#: bottom and a reflected one's at the top (GridReflect), in Gwyddion's y-down rows (checked on
#: AFMReader's sample_0.jpk, an independent review, 2026-11-28). Digital Surf MountainsMap .mnt: the
#: file's own JPEG preview, drawn by MountainsMap, matches the stored rows only with row 0 at the
#: top (a scratch's rise, a low spot, a masked corner: SurfaceTopography's mnt-1, mnt-2); .sur,
#: the same vendor's older format with the same row order and an explicit upside-down flag (which
#: SurfaceTopography honours), by that evidence, indirect. TrueMap .tmd: the lettering of a dime
#: (TrueMap v6's own file, tmd-1) reads right only with row 0 at the top (an independent review,
#: 2026-11-28). SurfaceTopography hands these in Gwyddion's row order (row 0 the top of the picture):
#: reversed here, so that y is up the instrument's picture as for the formats above.
_FIRST_LINE_AT_TOP = ("metropro", "datx", "jpk", "mnt", "sur", "tmd")

#: NanoFocus .nms: the pixel size, two little-endian float64 (x, y) at this byte offset
_NMS_PIXEL_OFFSET = 1376


def _nms_lateral(path: Path, nb_grid_pts):
    """(X mm, Y mm as (nx, ny) arrays, [Δx, Δy] mm) of a NanoFocus .nms map.

    The header's pixel size (bytes 1376–1391, after nx, ny at 1368) is in **nanometres**.
    SurfaceTopography 1.27's NMS reader takes it for mm (its field ``dx_mm``, × 1000 into µm), so
    st_nms-1.nms's 312.4999 became a 312.5 mm pixel and a 160 m field. Decoded by hand: the only
    lateral numbers in the header are those two doubles (312.4999911618964 for x and y, 512 × 512
    pixels); surfalize reads them as nm (``step = dx * 1e-3`` µm: 0.3125 µm pixel, a 160 µm field);
    the heights (zmin 2.69, zmax 6.01 in µm, at byte 16) span 3.3 µm — a confocal field of view of
    160 µm fits them, 160 m does not. Read here from the file itself, so a later SurfaceTopography
    that fixes the unit cannot make us scale it twice."""
    import struct

    with open(path, "rb") as f:
        f.seek(_NMS_PIXEL_OFFSET)
        b = f.read(16)
    if len(b) < 16:
        raise InputError(f"{path}: a damaged or truncated NanoFocus NMS file (no pixel size in its "
                         "header)")
    dx_nm, dy_nm = struct.unpack("<2d", b)
    _raise_bad(path, (("pixel size x (offset 1376, nm)", dx_nm, "x positions", True),
                      ("pixel size y (offset 1384, nm)", dy_nm, "y positions", True)))
    return _pixel_grid(nb_grid_pts, dx_nm * 1e-6, dy_nm * 1e-6)  # nm → mm


def _pixel_grid(nb_grid_pts, px: float, py: float):
    """(X, Y as (nx, ny) arrays, [px, py]) of a map of pixel px × py from the origin (the pixel
    convention: pixel (i, j) at (i·px, j·py)), in px's and py's unit."""
    nx, ny = int(nb_grid_pts[0]), int(nb_grid_pts[1])
    X = np.broadcast_to((np.arange(nx) * px)[:, None], (nx, ny))
    Y = np.broadcast_to((np.arange(ny) * py)[None, :], (nx, ny))
    return X, Y, [px, py]


#: Igor binary wave v5 (Igor Technical Note 003; igor2's BinHeader5/WaveHeader5): a 64-byte
#: BinHeader5, then WaveHeader5 whose sfA (double[4]: the value of element e of dimension d is
#: sfA[d]·e + sfB[d]) is at +84 and dimUnits (char[4][4], 0–3 characters and a NUL) at +152
_IBW_BIN_HEADER = 64
_IBW_SFA = _IBW_BIN_HEADER + 84
_IBW_DIM_UNITS = _IBW_BIN_HEADER + 152


def _ibw_uncalibrated(path: Path) -> str | None:
    """Why an Igor binary wave (version 5) has no lateral calibration, or None when it has one.

    A wave that was never given x/y scaling keeps Igor's default: sfA = 1 per point and no unit
    (dimUnits empty, no extended dimension unit). SurfaceTopography 1.27 reads that as physical
    sizes of nx × 1, ny × 1 in the height unit — a 1 nm pixel for heights in nm (its test file
    10x10-one_channel_without_name.ibw, a Gwyddion export, reports physical_sizes (10, 10)). A
    dimension counts as uncalibrated when its unit is empty and its sfA is exactly 1; the map does
    when x or y is. Units longer than three characters are stored after the note (the extended
    dimension units, BinHeader5's dimEUnitsSize[4]): a non-empty one counts as a unit."""
    import struct

    with open(path, "rb") as f:
        b = f.read(_IBW_DIM_UNITS + 16)
        if len(b) < _IBW_DIM_UNITS + 16:
            raise InputError(f"{path}: a damaged or truncated Igor binary wave file (its wave "
                             "header is cut short)")
        order = next((o for o in "<>" if struct.unpack_from(o + "h", b)[0] == 5), None)
        if order is None:  # not version 5: SurfaceTopography's reader refuses it before
            return None
        wfm, formula, note, data_eu, *dim_eu = struct.unpack_from(order + "4i4i", b, 4)
        sf_a = struct.unpack_from(order + "4d", b, _IBW_SFA)
        units = [b[_IBW_DIM_UNITS + 4 * d:_IBW_DIM_UNITS + 4 * d + 4].split(b"\0")[0].strip()
                 for d in range(4)]
        if any(dim_eu[:2]):
            if min(wfm, formula, note, data_eu, *dim_eu) < 0:
                raise InputError(f"{path}: a damaged Igor binary wave file (a negative block size "
                                 "in its header)")
            f.seek(_IBW_BIN_HEADER + wfm + formula + note + data_eu)
            for d in range(2):
                ext = f.read(dim_eu[d]).split(b"\0")[0].strip()
                units[d] = ext or units[d]
    bare = [axis for d, axis in enumerate("xy") if not units[d] and sf_a[d] == 1.0]
    if not bare:
        return None
    return (f"pixel size: {' and '.join(bare)} {'have' if len(bare) > 1 else 'has'} Igor's default "
            "scaling, 1 per point without a unit")


def _frt_in_valid_range(info: dict, h: np.ndarray) -> np.ndarray | bool:
    """Pixels of an FRT MicroProf map whose stored value lies in the file's valid range.

    What is established: block 0x0070 of the FRT format holds ``first_valid`` and ``last_valid``,
    "the smallest valid value" and "the largest valid value" of the stored integers (Gwyddion's
    microprof.c, from FRT's specification; it masks only the value 1 and notes "TODO: Use
    first_valid and last_valid"; SurfaceTopography 1.27 follows it, value 1 only). st_frt-1.frt
    (16-bit, valid 5 … 65529) holds 76,456 pixels of value 1 and a row of 500 pixels of value 0,
    which both readers pass as heights of exactly 0.0 m while the surface lies near 79 µm — outside
    the valid range, so invalid; st_frt-2.frt has no value outside the range but 1. Heights are
    the stored value × the height scale of block 0x006C (no offset), so the stored value is
    recovered exactly as height / scale. Applied to 16-bit (unsigned) data only: for 32-bit
    (signed) data no file was at hand to show how the unsigned bounds compare, and the value-1
    rule of the readers stands."""
    rng, grid = info.get("0x70") or {}, info.get("0x66") or {}
    scale = (info.get("0x6c") or {}).get("height_scale_factor")
    try:
        lo, hi, bits = int(rng["first_valid"]), int(rng["last_valid"]), int(grid["bytes_per_pixel"])
        scale = float(scale)
    except (KeyError, TypeError, ValueError):
        return True  # no valid range in the header
    if bits != 16 or not (0 <= lo <= hi <= 0xFFFF) or not np.isfinite(scale) or scale == 0:
        return True
    with np.errstate(invalid="ignore", over="ignore"):
        stored = h / scale
        r = np.rint(stored)
        ok = ~np.isfinite(stored) | (np.abs(stored - r) < 1e-3)
    if not ok.all():  # heights that are not stored integers × scale: the rule cannot be applied
        return True
    return (r >= lo) & (r <= hi)


# --- Zygo .datx in fringes / waves ---------------------------------------------------------------------
def _is_datx(path: Path) -> bool:
    try:
        import h5py

        with h5py.File(path, "r") as h5:
            return "MetaData" in h5
    except Exception:  # noqa: BLE001
        return False


def _datx_lateral_in_length(path: Path) -> bool:
    """Whether both lateral converters of a .datx give a length per pixel (SurfaceTopography reads
    the size as metres whatever the converter says)."""
    import h5py
    from SurfaceTopography.Support.UnitConversion import mangle_length_unit_utf8

    try:
        with h5py.File(path, "r") as h5:
            attrs = h5[_datx_surface_path(h5)].attrs
            for axis in ("X Converter", "Y Converter"):
                c = np.ravel(attrs[axis])[0]
                if mangle_length_unit_utf8(c[2]) not in _LENGTH_TO_MM or not c[3][1] > 0:
                    return False
        return True
    except Exception:  # noqa: BLE001 - let SurfaceTopography's reader decide
        return True


def _datx_surface_path(h5) -> str:
    meta: dict = {}
    for src, link, dst in h5["MetaData"][()]:
        meta.setdefault(src.decode(), {})[link.decode()] = dst.decode()
    node = meta.get("Root", {})
    for key in ("Measurement", "Surface"):
        node = meta.get(node.get(key, ""), {})
    return node.get("Path") or "Measurement/Surface"


def _read_datx_own(path: Path, opts):
    """A .datx that SurfaceTopography's DATX reader refuses (heights in fringes or waves, lateral
    converter without a length): the surface dataset, its No Data value and converters, by h5py."""
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            d = h5[_datx_surface_path(h5)]
            z = np.asarray(d[()], dtype=np.float64)  # rows along y
            attrs = dict(d.attrs)
    except Exception as e:  # noqa: BLE001
        raise InputError(f"{path}: cannot read this Zygo DATX file ({_short(e)})") from None

    def first(v):
        v = np.ravel(v)[0] if np.ndim(v) else v
        return v.decode().strip() if isinstance(v, bytes) else v

    unit = str(first(attrs.get("Unit", b"")))
    no_data = attrs.get("No Data")
    valid = np.isfinite(z)
    if no_data is not None:
        valid &= z != np.ravel(no_data)[0]
    from SurfaceTopography.Support.UnitConversion import mangle_length_unit_utf8

    u = mangle_length_unit_utf8(unit) if unit else None
    if u in _LENGTH_TO_MM:
        if opts.height_unit is not None:
            raise InputError(f"{path}: the file gives its own height unit ({unit}); remove the reader "
                             "option height_unit")
        scale = _LENGTH_TO_MM[u]
    elif unit.lower() in ("fringes", "waves", "wave", "fringe"):
        if opts.wavelength_nm is None:
            raise InputError(f"{path}: Zygo DATX heights in {unit}; give the reader option "
                             "wavelength_nm (a fringe is λ/2 of height, a wave λ)")
        scale = opts.wavelength_nm * 1e-6 * (0.5 if unit.lower().startswith("fringe") else 1.0)
    elif opts.height_unit is not None:
        scale = _LENGTH_TO_MM[opts.height_unit]
    else:
        raise InputError(f"{path}: Zygo DATX heights in {unit or 'no unit'}; give the reader option "
                         "height_unit (nm, µm, mm or m)")
    pix = []
    for axis in ("X Converter", "Y Converter"):
        conv = attrs.get(axis)
        p = None
        try:
            c = np.ravel(conv)[0]
            lu = mangle_length_unit_utf8(c[2]) if c[2] else None
            if lu in _LENGTH_TO_MM and np.isfinite(c[3][1]) and c[3][1] > 0:
                p = float(c[3][1]) * _LENGTH_TO_MM[lu]
        except Exception:  # noqa: BLE001 - no or odd converter: needs the option
            p = None
        pix.append(p)
    if opts.pixel_size_um is not None:
        pix = [opts.pixel_size_um[0] * 1e-3, opts.pixel_size_um[1] * 1e-3]
    elif None in pix:
        raise InputError(f"{path}: Zygo DATX lateral converter in pixels without a size; give the "
                         "reader option pixel_size_um (µm)")
    # the first stored row is the top of Zygo's picture: y up it, as for every .datx (_FIRST_LINE_AT_TOP;
    # a review: this path kept the stored order, the same picture mirrored by its units)
    z, valid = z[::-1], valid[::-1]
    xyz, ch, m = _grid_cloud(z * scale, pix[0], pix[1], path, valid=valid)
    return xyz, ch, {"instrument_format": "datx", "instrument_reader": "Zygo DATX (own, h5py)",
                     "instrument_unit": unit, **m}


def read_areal(path: Path, opts=None):
    """(xyz mm, channels, meta) of an areal instrument file."""
    if path.suffix.lower() == ".x3p":
        return read_x3p(path)
    return read_surface_topography(path, opts)
