"""Reading and writing point clouds; the reader is chosen by the file's content, not its name.

read (see docs/formats.md for units and the pixel convention):
  point clouds   x y z text columns (.csv .txt .xyz .asc .dat … — core.io.text, CloudCompare's
                 ``//X Y Z`` header included), .ply (all vertex properties kept), .pcd .pts
                 (core.io.ply, core.io.pcd: our numpy readers, every count checked), LAS/LAZ
                 (core.io.las) and E57 (core.io.e57) of laser scanners — the optional extra
                 ``pip install 'pointspro[scanners]'``; metres → mm
  height maps    every format SurfaceTopography reads — Zygo .datx and MetroPro .dat, Digital Surf
                 .sur, ISO 25178-71 .sdf, Wyko/Bruker .opd, Bruker .di, Sensofar .plu/.plux, Keyence
                 .vk4/.zon, Gwyddion .gwy, FRT .frt, Alicona .al3d, Igor .ibw, Agilent .mi … — found
                 by content (core.io.instruments); .x3p through x3pio (and our own reader for
                 Sensofar's namespace-less main.xml); text height matrices with a Gwyddion / SPIP /
                 Wyko / Nova header (core.io.matrix)
  A text file is told apart by content: x y z columns, a stylus profile (x, z columns: core.io.text,
  core.profiles), or a height matrix with a header. A file whose extension lies about its
  content is read for what it is; one that matches no reader is refused naming what it looks like.
write: .csv (all channels, `index` included, shortest round-trip decimal, each column's unit in the
       header: ``x [mm],y [mm],z [mm],index,residual [mm]``), .ply (binary: float64, each integer
       channel in a type that holds it — core.io.ply)

Reader options (``read_cloud(path, pixel_size_um=…, …)``, a recipe's ``input:`` block):
  pixel_size_um  lateral pixel size, one number or [x, y], for maps whose file has no calibration
  wavelength_nm  for heights stored in fringes (× λ/2) or waves (× λ)
  height_unit    nm, µm, mm or m, for heights whose file names no unit
  invalid        drop (default) or error: x y z rows with NaN/inf; the dropped count is in
                 ``cloud.meta["invalid_dropped"]`` (instrument maps always drop invalid pixels and
                 count them the same way)
  profile_angle_deg  the azimuth of a stylus profile (x, z columns; or an x, y, z line): core.profiles
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..cloud import PointCloud, repeated_index_message
from ..errors import InputError
from ..units import channel_unit
from .atomic import atomic_path

TEXT_SUFFIXES = (".csv", ".txt", ".xyz", ".asc", ".dat")
OPEN3D_SUFFIXES = (".pcd", ".pts")  # the name kept: read by core.io.pcd (open3d read them once)
from .instruments import AREAL_SUFFIXES  # noqa: E402

SCANNER_SUFFIXES = (".las", ".laz", ".e57")  # core.io.las, core.io.e57: the `scanners` extra

READ_SUFFIXES = tuple(dict.fromkeys(TEXT_SUFFIXES + (".ply",) + OPEN3D_SUFFIXES + SCANNER_SUFFIXES
                                    + AREAL_SUFFIXES))
WRITE_SUFFIXES = (".csv", ".ply")

#: length units accepted by ``height_unit`` → factor to mm
HEIGHT_UNITS = {"nm": 1e-6, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "mm": 1.0, "m": 1e3}
INVALID_POLICIES = ("drop", "error")


@dataclass(frozen=True)
class ReaderOptions:
    """Validated reader options (see the module doc). Build with :meth:`parse`."""

    pixel_size_um: tuple[float, float] | None = None
    wavelength_nm: float | None = None
    height_unit: str | None = None
    invalid: str = "drop"
    profile_angle_deg: float | None = None

    KEYS = ("pixel_size_um", "wavelength_nm", "height_unit", "invalid", "profile_angle_deg")

    @classmethod
    def parse(cls, data: Mapping[str, Any] | None) -> "ReaderOptions":
        """Options from a mapping; raises ValueError naming the key at fault (callers prefix the
        file or the recipe line)."""
        if data is None:
            return cls()
        if isinstance(data, ReaderOptions):
            return data
        if not isinstance(data, Mapping):
            raise ValueError(f"reader options must be a mapping of {', '.join(cls.KEYS)}")
        for k in data:
            if k not in cls.KEYS:
                raise ValueError(f"unknown reader option '{k}' (options: {', '.join(cls.KEYS)})")
        px = data.get("pixel_size_um")
        if px is not None:
            vals = list(px) if isinstance(px, (list, tuple)) else [px]
            if len(vals) not in (1, 2) or not all(_positive(v) for v in vals):
                raise ValueError(f"key 'pixel_size_um': a positive number or [x, y] of positive "
                                 f"numbers (µm) (got {px!r})")
            px = (float(vals[0]), float(vals[-1]))
        wl = data.get("wavelength_nm")
        if wl is not None:
            if not _positive(wl):
                raise ValueError(f"key 'wavelength_nm': a positive number (nm) (got {wl!r})")
            wl = float(wl)
        hu = data.get("height_unit")
        if hu is not None and (not isinstance(hu, str) or hu not in HEIGHT_UNITS):
            raise ValueError(f"key 'height_unit': one of nm, µm, mm, m (got {hu!r})")
        inv = data.get("invalid", "drop")
        if not isinstance(inv, str) or inv not in INVALID_POLICIES:
            raise ValueError(f"key 'invalid': drop or error (got {inv!r})")
        pa = data.get("profile_angle_deg")
        if pa is not None:
            if (not isinstance(pa, (int, float)) or isinstance(pa, bool) or not np.isfinite(float(pa))):
                raise ValueError(f"key 'profile_angle_deg': the profile's azimuth in degrees (got {pa!r})")
            pa = float(pa)
        return cls(px, wl, hu, inv, pa)

    def to_dict(self) -> dict:
        """The options that differ from the defaults, as a recipe would write them."""
        d: dict = {}
        if self.pixel_size_um is not None:
            px = self.pixel_size_um
            d["pixel_size_um"] = px[0] if px[0] == px[1] else list(px)
        if self.wavelength_nm is not None:
            d["wavelength_nm"] = self.wavelength_nm
        if self.height_unit is not None:
            d["height_unit"] = self.height_unit
        if self.invalid != "drop":
            d["invalid"] = self.invalid
        if self.profile_angle_deg is not None:
            d["profile_angle_deg"] = self.profile_angle_deg
        return d


def _positive(v) -> bool:
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        return False
    try:
        f = float(v)
    except OverflowError:  # an integer beyond float64 (1e400 written without a point)
        return False
    return bool(np.isfinite(f) and f > 0)


# --- content sniffing ----------------------------------------------------------------------------
_HEAD_BYTES = 65536
_FOREIGN_MAGICS = (  # files people drop by mistake: name them
    (b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
    (b"%PDF", "a PDF document"), (b"BM", "a BMP image"), (b"\x1f\x8b", "a gzip archive"),
    (b"7z\xbc\xaf", "a 7-zip archive"), (b"Rar!", "a RAR archive"),
    (b"\xd0\xcf\x11\xe0", "an old Microsoft Office document"), (b"ISO-10303-21", "a STEP CAD file"),
    (b"solid ", "an ASCII STL mesh"),
)


def _sniff(path: Path) -> tuple[bytes, bool]:
    """(first bytes, is_text): text when the head and the tail hold no NUL byte and decode."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(_HEAD_BYTES)
        tail = b""
        if size > _HEAD_BYTES:
            f.seek(max(size - 4096, _HEAD_BYTES))
            tail = f.read()
    if b"\0" in head or b"\0" in tail:
        return head, _printable_utf16(head)

    try:
        head.decode("utf-8")
        return head, True
    except UnicodeDecodeError as e:
        if e.start > len(head) - 4:  # a multi-byte character cut by the read
            return head, True
    sample = head[:4096]
    printable = sum(b >= 32 or b in (9, 10, 13) for b in sample)
    return head, printable >= 0.95 * len(sample)


def _printable_utf16(head: bytes) -> bool:
    """UTF-16 text (a BOM, or ASCII with every other byte NUL) whose first characters are printable:
    read as text (core.io.text decodes it). The printable test keeps a binary map of small 16-bit
    numbers, whose high bytes are NUL as well, out."""
    from .text import utf16_codec

    codec = utf16_codec(head)
    if codec is None:
        return False
    sample = head[:4096]
    text = sample[:len(sample) // 2 * 2].decode(codec, errors="replace")
    return bool(text) and sum(c.isprintable() or c in "\t\r\n" for c in text) >= 0.95 * len(text)


_MESH_NOTE = " (a nominal for `register` or `surface: {type: mesh}`)"
_OBJ_VERTEX = re.compile(rb"^v[ \t]+[-+.0-9]", re.M)
_OBJ_FACE = re.compile(rb"^f[ \t]+[0-9]", re.M)


def foreign_kind(head: bytes) -> str | None:
    """What a file that is no measurement looks like (a PNG image, a PDF, an STL, OBJ or OFF mesh…),
    or None."""
    for magic, what in _FOREIGN_MAGICS:
        if head.startswith(magic):
            return what + (_MESH_NOTE if what.endswith("mesh") else "")
    if re.match(rb"\s*OFF\s", head):
        return "an OFF mesh" + _MESH_NOTE
    if _OBJ_VERTEX.search(head) and _OBJ_FACE.search(head):  # Wavefront OBJ: `v x y z`, `f i j k`
        return "an OBJ mesh" + _MESH_NOTE
    return None


def read_cloud(path, options: ReaderOptions | Mapping | None = None, **kw) -> PointCloud:
    """Read a measurement file into a PointCloud (frame `measuring`, a PointsPro .npz the frame it
    states; `index` = row of the input, or pixel number of a map). ``options`` / keywords: the reader options of the module doc."""
    from ..pathnames import why_not_a_file

    path = Path(path)
    why = why_not_a_file(path, "data file")
    if why is not None:
        raise InputError(f"{path}: {why}")
    if not os.access(path, os.R_OK):
        raise InputError(f"{path}: permission denied")
    try:
        opts = ReaderOptions.parse({**(ReaderOptions.parse(options).to_dict()), **kw})
    except ValueError as e:
        raise InputError(f"{path}: {e}") from None
    suffix = path.suffix.lower()
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file — no data rows")
    head, is_text = _sniff(path)
    from .memory import check_stated

    check_stated(path, head, is_text)  # too large for memory: said before reading (issue 26)
    from .pcd import looks_like_pcd

    if head.startswith((b"ply\n", b"ply\r\n")):
        from .ply import read_ply

        xyz, cols, meta = read_ply(path)
    elif looks_like_pcd(head):  # a PCD header, whatever the extension
        from .pcd import read_pcd

        xyz, cols, meta = read_pcd(path, invalid=opts.invalid)
    elif head.startswith(b"LASF"):  # LAS / LAZ (laspy, the `scanners` extra)
        from .las import read_las

        xyz, cols, meta = read_las(path)
    elif head.startswith(b"ASTM-E57"):  # E57 (pye57, the `scanners` extra)
        from .e57 import read_e57

        xyz, cols, meta = read_e57(path)
    elif suffix == ".pcd":  # no PCD header: read_pcd says "no points read — not a PCD file"
        from .pcd import read_pcd

        xyz, cols, meta = read_pcd(path, invalid=opts.invalid)
    elif suffix == ".pts":
        from .pcd import read_pts

        xyz, cols, meta = read_pts(path, invalid=opts.invalid)
    elif head.startswith(b"PK\x03\x04") and _zip_has(path, "pointspro_meta.npy"):  # --cloud-format npz
        from .npz import read_npz

        xyz, cols, meta = read_npz(path, invalid=opts.invalid)
    elif head.startswith(b"PK\x03\x04") and _zip_has(path, "main.xml"):
        from .instruments import read_x3p

        xyz, cols, meta = read_x3p(path)
    elif is_text:
        xyz, cols, meta = _read_text_by_content(path, head, suffix, opts)
    else:
        from .instruments import read_surface_topography

        xyz, cols, meta = read_surface_topography(path, opts, head=head)
    if opts.wavelength_nm is not None and str(meta.get("instrument_unit", "")).lower() not in \
            ("fringe", "fringes", "wave", "waves"):  # was ignored silently (MetroPro, .sur: own unit)
        what = meta.get("instrument_reader") or meta.get("format") or "this"
        raise InputError(f"{path}: reader option wavelength_nm is for maps whose heights are in fringes "
                         f"or waves (Zygo .datx); the {what} file states its heights in a length unit "
                         f"({meta.get('instrument_unit') or 'mm'}) — remove the option")
    # every file is in the measuring frame but a PointsPro .npz, which states its own (core/io/npz.py)
    frame = meta.get("frame", "measuring") if meta.get("format") == "npz" else "measuring"
    meta = {**meta, "source": str(path), "frame": frame, "units": "mm"}
    meta.setdefault("invalid_dropped", 0)
    _check_index_unique(path, cols)
    why = beyond_any_machine(xyz) if meta.get("format") != "text" else None  # text: by its line, read_text
    if why:
        row, text = why
        idx = cols.get("index") if hasattr(cols, "get") else None
        raise InputError(f"{path}: the point with index {int(idx[row]) if idx is not None else row}: {text}")
    try:
        return PointCloud(xyz, cols, meta)
    except ValueError as e:
        raise InputError(f"{path}: {e}") from None


#: the largest coordinate a measurement holds (mm): 10¹² mm = 10⁶ km — room for a projected frame's
#: northing (UTM: up to 10⁷ m) and an Earth-centred frame (6.4·10⁶ m), a LAS file's coordinates
#: (10⁹ mm refused a real UTM cloud: a review), and far below where the pose fit's squares overflow
#: (~1e150). A corrupt 1e300 overflowed them — "RuntimeWarning: overflow" lines, then the surface
#: blamed ("1 point at r up to inf mm lies outside the conic's domain") with no word of the file's
#: line (a review)
MAX_COORDINATE_MM = 1e12


def beyond_any_machine(xyz) -> tuple[int, str] | None:
    """(row, what) of the first point with a coordinate beyond ``MAX_COORDINATE_MM``, or None."""
    xyz = np.asarray(xyz)
    if not xyz.size or (float(xyz.max()) <= MAX_COORDINATE_MM and float(xyz.min()) >= -MAX_COORDINATE_MM):
        return None  # two reductions, no temporaries (10⁶ points: ~2 ms)
    big = np.abs(xyz) > MAX_COORDINATE_MM  # (a NaN, which the readers drop, is no coordinate here)
    if not big.any():
        return None
    row = int(np.flatnonzero(big.any(axis=1))[0])
    axis = int(np.flatnonzero(big[row])[0])
    return row, (f"{'xyz'[axis]} = {float(xyz[row, axis])!r} mm lies beyond any measuring machine (|{'xyz'[axis]}| "
                 f"≤ {MAX_COORDINATE_MM:.0e} mm) — a corrupt value or a wrong unit")


def _check_index_unique(path: Path, cols) -> None:
    """A repeated index is refused by every reader, as by the text reader (a review: an ASCII PLY's
    `3, 3` was read as is)."""
    idx = cols.get("index") if hasattr(cols, "get") else None
    why = None if idx is None else repeated_index_message(idx)
    if why:
        raise InputError(f"{path}: {why}")


def _zip_has(path: Path, name: str) -> bool:
    import zipfile

    try:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
    except (zipfile.BadZipFile, OSError, ValueError):
        # a damaged X3P or PointsPro .npz: its own reader names the damage
        return (name, path.suffix.lower()) in (("main.xml", ".x3p"), ("pointspro_meta.npy", ".npz"))
    if name == "main.xml":  # an X3P zipped with its folder (x3ptools: csafe-logo/main.xml) too:
        from .instruments import x3p_main_xml_names  # read_x3p reads it or says where main.xml is

        return bool(x3p_main_xml_names(n.replace("\\", "/") for n in names))
    return name in names


def _read_text_by_content(path: Path, head: bytes, suffix: str, opts: ReaderOptions):
    """x y z columns, a header-described height matrix, or a text format of SurfaceTopography."""
    from . import matrix
    from .instruments import read_surface_topography, st_extension_names, st_magic_names

    text_head = head.decode("utf-8", errors="replace")
    if matrix.is_st_text_format(text_head):  # ISO 25178-71 SDF text, Wyko ASCII …
        return read_surface_topography(path, opts, head=head)
    if suffix not in TEXT_SUFFIXES and st_magic_names(head):  # a text header, binary further on
        return read_surface_topography(path, opts, head=head)
    from .text import MatrixInText, names_axes_above_data, read_text

    if matrix.has_matrix_header(text_head) and not names_axes_above_data(text_head, matrix.is_number_row):
        return matrix.read_matrix(path, opts)

    try:
        got = read_text(path, invalid=opts.invalid, profile_angle_deg=opts.profile_angle_deg)
    except MatrixInText as e:  # rows too wide for points, without a header: a height matrix
        return matrix.read_headerless(path, e.data, e.first_line, opts, text_head)
    except InputError as e:
        what = foreign_kind(head)
        if what:
            raise InputError(f"{path}: {what}, not a measurement file") from None
        if st_magic_names(head):
            return read_surface_topography(path, opts, head=head)
        claimed = st_extension_names(suffix)
        if claimed and suffix not in TEXT_SUFFIXES:
            raise InputError(f"{e} — the content is text, not a {claimed} file as the extension "
                             f"'{suffix}' says") from None
        raise
    given = [k for k in ("height_unit", "pixel_size_um", "wavelength_nm") if getattr(opts, k) is not None]
    if given:  # an x, y, z text file: height_unit was ignored silently (z taken as mm)
        raise InputError(f"{path}: reader option {', '.join(given)} is for instrument maps that state no "
                         "unit; an x y z text file states its units in its header (`x [mm],y [mm],z [um]`) "
                         "or is in mm — remove the option")
    return got


def _format_column(a: np.ndarray) -> list[str]:
    if a.dtype.kind in "iu":
        return list(map(str, a.tolist()))
    return list(map(repr, a.tolist()))  # shortest string that reads back bit-exact


def write_number_columns(f, arrays, delimiter: str = ",") -> None:
    """Rows of the given float/integer columns to the binary file ``f``, each number the shortest
    decimal that reads back to the same float64 (Arrow's CSV writer; see write_csv)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    table = pa.Table.from_arrays([_arrow_column(pa, np.asarray(a)) for a in arrays],
                                 names=[f"c{i}" for i in range(len(arrays))])
    pacsv.write_csv(table, f, write_options=pacsv.WriteOptions(
        include_header=False, quoting_style="none", batch_size=65_536, delimiter=delimiter))


def _arrow_column(pa, a: np.ndarray):
    """``a`` as an Arrow array over the same memory (float64 or int64/uint64; float32 widened first, so
    the file holds the float64 value read back). Built from buffers: ``pa.array`` imports pandas
    (0.7 s) to check for its types."""
    if a.dtype.kind == "f":
        a, t = np.ascontiguousarray(a, dtype=np.float64), pa.float64()
    elif a.dtype.kind == "u" and a.dtype.itemsize == 8:
        a, t = np.ascontiguousarray(a), pa.uint64()
    else:
        a, t = np.ascontiguousarray(a, dtype=np.int64), pa.int64()
    return pa.Array.from_buffers(t, a.size, [None, pa.py_buffer(a)])


def csv_header(cloud: PointCloud) -> list[str]:
    """The column titles of ``cloud`` as write_csv writes them, each with its unit:
    ``x [mm]``, ``y [mm]``, ``z [mm]``, ``index``, ``residual [mm]`` … (core.units.channel_unit: lengths
    in mm, a non-length unit the input stated as it was, none for counts and flags)."""
    stated = cloud.meta.get("channel_units") or {}
    out = []
    for n in cloud.column_names:
        unit = channel_unit(n, stated.get(n) if isinstance(stated, dict) else None)
        ok = unit and not any(c in unit for c in ',;[]()"\'\t\r\n')
        out.append(f"{n} [{unit}]" if ok else n)
    return out


def write_csv(cloud: PointCloud, path) -> None:
    """CSV with a header naming each column and its unit: x, y, z (mm), index, then the other
    channels (csv_header); written atomically. Read back by read_cloud bit for bit.

    Numbers are the shortest decimal that reads back to the same float64 (docs/formats.md):
    Apache Arrow's CSV writer (double-conversion's ``ToShortest``, the digits Python's ``repr``
    gives; an integral value without ".0", a small one without an exponent: ``0.00001``) formats
    ~7× faster than ``repr`` per value (5.2 → 0.7 s for 10⁶ rows × 5 columns; issue 17). Columns
    that are neither float nor integer (none of PointsPro's own) are formatted by ``repr``."""
    names = cloud.column_names
    arrays = [np.asarray(cloud[n]) for n in names]
    header = ",".join(csv_header(cloud)) + "\n"
    with atomic_path(path) as tmp:
        if all(a.dtype.kind in "iuf" for a in arrays):
            with open(tmp, "wb") as f:
                f.write(header.encode("utf-8"))
                write_number_columns(f, arrays)
            return
        chunk = 100_000  # formatted strings cost ~50 bytes a value: bound the memory, not the speed
        with open(tmp, "w", encoding="utf-8", newline="\n") as f:
            f.write(header)
            for start in range(0, cloud.n, chunk):
                cols = [_format_column(a[start:start + chunk]) for a in arrays]
                f.writelines(",".join(row) + "\n" for row in zip(*cols))


def write_ply_cloud(cloud: PointCloud, path) -> None:
    from .ply import write_ply

    ch = {n: cloud[n] for n in cloud.column_names[3:]}
    with atomic_path(path) as tmp:
        write_ply(tmp, np.asarray(cloud.xyz), ch, shown=path)


def write_cloud(cloud: PointCloud, path) -> None:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        write_csv(cloud, path)
    elif suffix == ".ply":
        write_ply_cloud(cloud, path)
    else:
        raise InputError(f"{path}: cannot write '{suffix}'; PointsPro writes {', '.join(WRITE_SUFFIXES)}")
