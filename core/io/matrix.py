"""Height matrices in text files: one row of heights per line, with a header giving the size.

Recognised by content, whatever the extension: a header (``#`` comment lines or plain ``key: value``
lines before the numbers) with Gwyddion's ASCII-export keys (``Width``, ``Height``, ``Value units``,
in any of Gwyddion's interface languages), SPIP/Attocube (``x-length``, ``x-pixels``, ``File Format
= ASCII``), Nova (``NX =``, ``Scale X =``) or Wyko ASCII. Example (Gwyddion, 3 × 4 heights in m)::

    # Channel: Height
    # Width: 12.34 µm
    # Height: 5678.9 nm
    # Value units: m
    1 1.5 3
    -2 -3 -6
    ...

Values are parsed by SurfaceTopography's plain-text reader (``format="asc"``), which gets the
units and the lateral size right (checked against the files in tests/data/realdata); we check the
rows first so that a ragged matrix or a non-number is named by line. Conventions:
  * a line of the file is a row of the map (y), a value in it a column (x); row 0 is the first line;
  * ``Width`` is the size of the whole map along x, so Δx = Width / columns (Gwyddion's meaning);
    pixel (i, j) lies at x = i·Δx, y = j·Δy (the first pixel at the origin: SurfaceTopography's
    ``positions()``, the same as every instrument map — see core.io.instruments);
  * heights are converted from ``Value units`` to mm; NaN values are invalid pixels, dropped and
    counted in ``meta["invalid_dropped"]``.
A matrix without lateral calibration needs the reader option ``pixel_size_um``; one without a unit
for its values needs ``height_unit``. A lateral size without a unit of its own (``# Width: 12.34``;
SPIP's ``x-length = 12.34`` without ``x-unit``) is refused naming the key when the file states a unit
for its values — SurfaceTopography would lend it that unit (or nm for SPIP), silently — unless
``pixel_size_um`` is given, which then replaces the sizes. A size of 0, below 0 or not finite, and a
header's ``x-pixels``/``y-pixels`` that disagree with the rows, are refused naming the key. A file
that names no unit at all reads its sizes in ``height_unit``, as SurfaceTopography does.

The header of SurfaceTopography's ``matrix-2.txt`` / ``matrix-4.txt`` is read too (its keys as its
reader has them, case-sensitive): ``h=650 w=650`` (rows, values a row: checked against the data),
``pixel size=3.69862e-007 m`` (Δx = Δy, with its unit) and ``height conversion factor (-> m)=6.3e-8``
(height = value × factor, in the unit after ``->``); ``data unit=rad`` says what the values are.
A pixel size or factor that is no number, 0 or not finite, a unit that is no length, two pixel
sizes, a pixel size without a unit beside a stated height unit, or values in a non-length ``data
unit`` without a conversion factor are refused naming the line.

Rows of many numbers without any header (``read_headerless``; which files, core.io.text) are a
matrix too, read once the reader options ``pixel_size_um`` and ``height_unit`` give what the file
does not state.
"""
from __future__ import annotations

import io
import re
from pathlib import Path

from ..errors import InputError

_GWY_KEYS = ("Width|Šířka|Breite|Anchura|Largeur|Larghezza|幅|폭|Largura|Ширина|"
             "Height|Výška|Höhe|Altura|Hauteur|Altezza|高さ|높이|Высота|"
             "Value units|Jednotky hodnot|Einheiten|Unités|unità valore|値の単位|값 단위|"
             "Unidades de valor|Единицы измерения")
_HEADER = re.compile(
    rf"^\s*#?\s*(?P<key>{_GWY_KEYS}|x-length|y-length|x-pixels|y-pixels|x-unit|y-unit|z-unit|"
    r"File Format|NX|NY|Scale X|Scale Y)\s*(?:=|:|：)", re.I)
_ST_TEXT = (re.compile(r"^a(ISO|BCR)"), re.compile(r"^\s*Wyko ASCII Data File Format"))
_NUMBER_ROW = re.compile(r"^\s*[-+0-9.]")
_NUM = r"[-+]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eEdD][-+]?[0-9]+)?|nan|NaN|NAN|inf|Inf|INF)"
_SEP = re.compile(r"[\s,;]+")
_ROW = re.compile(rf"^\s*{_NUM}(?:[\s,;]+{_NUM})*[\s,;]*$")


_GWY_WIDTH = "Width|Šířka|Breite|Anchura|Largeur|Larghezza|幅|폭|Largura|Ширина"
_GWY_HEIGHT = "Height|Výška|Höhe|Altura|Hauteur|Altezza|高さ|높이|Высота"
_GWY_VALUE = ("Value units|Jednotky hodnot|Einheiten|Unités|unità valore|値の単位|값 단위|"
              "Unidades de valor|Единицы измерения")
_KV = r"\s*(?:=|:|：)\s*"
# the keys SurfaceTopography's text reader takes the lateral sizes, units and pixel counts from
# (case-sensitive, as there)
_SIZE_LINE = re.compile(rf"^\s*#?\s*(?P<key>x-length|y-length|{_GWY_WIDTH}|{_GWY_HEIGHT}){_KV}"
                        r"(?P<rest>.*)$")
_SIZE_VALUE = re.compile(r"(?P<value>[-+]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|nan|inf)"
                         r")(?P<unit>.*)$", re.I)
_UNIT_LINE = re.compile(rf"^\s*#?\s*(?P<key>x-unit|y-unit|Unit X|z-unit|Unit Data|{_GWY_VALUE})"
                        rf"{_KV}(?P<unit>\S*)")
_PIXELS_LINE = re.compile(r"^\s*#?\s*(?P<key>x-pixels|y-pixels|NX|NY)\s*(?:=|:)\s*(?P<n>[0-9]+)\s*$")
_SPIP = re.compile(r"^#\s*File Format\s*=\s*ASCII\s*$")
# SurfaceTopography's asc reader also takes these keys (searched in any header line, case-sensitive):
# `h=650 w=650` (rows, values a row), `pixel size=3.69862e-007 m` (Δx = Δy) and
# `height conversion factor (-> m)=6.30079e-008` (heights = values × factor, in m). Only the
# unambiguous forms count towards telling a matrix's header: h and w alone on their line, `pixel
# size` and `height conversion factor` at the start of theirs (as the files have them).
_HW_LINE = re.compile(r"^\s*#?\s*(?P<k1>[hw])\s*=\s*(?P<n1>[0-9]+)"
                      r"(?:\s+(?P<k2>[hw])\s*=\s*(?P<n2>[0-9]+))?\s*$")
_PIXEL_SIZE = re.compile(r"pixel\s+size\s*=\s*(?P<rest>.*)$")
_HEIGHT_FACTOR = re.compile(r"height\s+conversion\s+factor\s+\(->\s+(?P<unit>.*)\)\s*=\s*(?P<rest>.*)$")
_DATA_UNIT = re.compile(r"^\s*#?\s*data\s+unit\s*=\s*(?P<unit>.*?)\s*$")
_ST_KEY_START = re.compile(r"^\s*#?\s*(?P<key>pixel\s+size|height\s+conversion\s+factor\s+\(->)")
_STREAM = re.compile(r"<_io\.\w+ object at 0x[0-9a-fA-F]+>")


def _header(text: str) -> list[tuple[int, str]]:
    """(0-based line, text) of the header: the lines before the first row of numbers."""
    out = []
    for i, line in enumerate(text.splitlines()):
        s = line.strip()
        if _NUMBER_ROW.match(s) and _ROW.match(s):
            break
        out.append((i, line))
    return out


def _check_header(path: Path, text: str, opts, nrows: int, ncols: int) -> str:
    """The text to give SurfaceTopography's reader, after the checks of the module doc: unchanged,
    or without its unit-less size lines (``pixel_size_um`` given), or with ``# Value units`` added
    (``height_unit`` given to a file whose sizes have units but whose values have none)."""
    from .instruments import bad_header_scale

    sizes: dict = {}   # "x" / "y" → (line, key, value text, unit text)
    units: dict = {}   # "x", "y", "z", "lateral" → unit
    pixel: list = []   # (line, value text, unit text) of each `pixel size=`
    factor = None      # (line, unit, value text) of `height conversion factor (-> unit)=`
    data_unit = None   # (line, unit) of `data unit=`
    spip = False
    for i, line in _header(text):
        body = line.lstrip("\ufeff")
        if _SPIP.match(body.strip()):
            spip = True
            continue
        m = _HW_LINE.match(body)
        if m:
            for k, n in ((m.group("k1"), m.group("n1")), (m.group("k2"), m.group("n2"))):
                have = ncols if k == "w" else nrows
                if k and int(n) != have:
                    raise InputError(f"{path}, line {i + 1}: the header's {k}={n} but the matrix has "
                                     f"{have} {'values a row' if k == 'w' else 'rows'}")
            continue
        m = _PIXEL_SIZE.search(body)
        if m:
            v = _SIZE_VALUE.match(m.group("rest").strip())
            pixel.append((i, v.group("value"), v.group("unit").strip()) if v else
                         (i, m.group("rest").strip() or "(nothing)", ""))
            continue
        m = _HEIGHT_FACTOR.search(body)
        if m:
            factor = (i, m.group("unit").strip(), m.group("rest").strip() or "(nothing)")
            continue
        m = _DATA_UNIT.match(body)
        if m:
            data_unit = (i, m.group("unit"))
            continue
        m = _PIXELS_LINE.match(body)
        if m:
            key, n = m.group("key"), int(m.group("n"))
            along_x = key in ("x-pixels", "NX")
            have = ncols if along_x else nrows
            if n != have:
                raise InputError(f"{path}, line {i + 1}: the header's {key} = {n} but the matrix has "
                                 f"{have} {'values a row' if along_x else 'rows'}")
            continue
        m = _UNIT_LINE.match(body)
        if m:
            key, unit = m.group("key"), m.group("unit").strip()
            axis = {"x-unit": "x", "y-unit": "y", "Unit X": "lateral"}.get(key, "z")
            if unit:
                units[axis] = unit
            continue
        m = _SIZE_LINE.match(body)
        if m:
            key = m.group("key")
            axis = "x" if key == "x-length" or re.fullmatch(_GWY_WIDTH, key) else "y"
            rest = m.group("rest").strip()
            v = _SIZE_VALUE.match(rest)
            label = body[:m.end("key")].strip()  # the key as written: "# Width", "x-length"
            sizes[axis] = (i, label, v.group("value"), v.group("unit").strip()) if v else \
                (i, label, rest or "(nothing)", "")
    for axis, (i, label, value, _) in sizes.items():
        err = bad_header_scale(f"{path}, line {i + 1}", label, value, f"{axis} positions",
                               positive=True)
        if err is not None:
            raise err
    if factor is not None:
        i, unit, value = factor
        err = bad_header_scale(f"{path}, line {i + 1}", "height conversion factor", value, "heights")
        if err is not None:
            raise err
        if not _is_length(unit):
            raise InputError(f"{path}, line {i + 1}: the height conversion factor converts to "
                             f"'{unit[:20]}', which is no length unit (nm, µm, mm, m …)")
        units["z"] = unit
    elif data_unit is not None and data_unit[1] and not _is_length(data_unit[1]):
        i, unit = data_unit
        raise InputError(f"{path}, line {i + 1}: the values are in '{unit[:20]}' (data unit), not a "
                         "length, and the header gives no 'height conversion factor (-> m)=…' that "
                         "makes them heights")
    if pixel and sizes:  # SurfaceTopography would take the size in pixels and multiply it
        (i, label, *_), k = min(sizes.values()), pixel[0][0]
        raise InputError(f"{path}, line {max(i, k) + 1}: the header gives both a pixel size (line "
                         f"{k + 1}) and the map's size ({label}, line {i + 1}); keep one of them")
    pixel_unitless = False
    if len(pixel) > 1:
        if opts.pixel_size_um is None:
            raise InputError(f"{path}, line {pixel[1][0] + 1}: a second pixel size (line "
                             f"{pixel[0][0] + 1} has one) — which is x and which y is not said; give "
                             "the reader option pixel_size_um ([x, y] in µm)")
    elif pixel:
        i, value, unit = pixel[0]
        err = bad_header_scale(f"{path}, line {i + 1}", "pixel size", value, "x and y positions",
                               positive=True)
        if err is not None:
            raise err
        if unit and not _is_length(unit):
            raise InputError(f"{path}, line {i + 1}: the pixel size's unit '{unit[:20]}' is no "
                             "length unit (nm, µm, mm, m …)")
        pixel_unitless = not unit
    if opts.pixel_size_um is not None and (len(pixel) > 1 or pixel_unitless):
        # SurfaceTopography would lend a unit-less pixel size the heights' unit (and take the last
        # of two for both axes); the option replaces them: the lines go
        lines = text.splitlines(keepends=True)
        for i, *_ in pixel:
            lines[i] = "\n"
        text = "".join(lines)
    elif pixel_unitless and "z" in units:
        i, value, _ = pixel[0]
        raise InputError(f"{path}, line {i + 1}: the pixel size has no unit ('pixel size={value}'); "
                         f"write e.g. 'pixel size={value} µm' or give the reader option pixel_size_um")
    # the unit SurfaceTopography gives each size: its own, its axis's unit key, else the x one (Nova's
    # `Unit X`, `x-unit`) — except in SPIP files, where a y-length without y-unit is taken as nm
    lent = {"x": units.get("x") or units.get("lateral"),
            "y": units.get("y") or (None if spip else units.get("x") or units.get("lateral"))}
    unitless = [(i, label, value) for axis, (i, label, value, unit) in sorted(sizes.items())
                if not (unit or lent[axis])]
    if opts.pixel_size_um is not None and (unitless or len(sizes) == 1):
        # the option replaces sizes that cannot be read as lengths (SurfaceTopography would refuse
        # the option next to a size): the size lines go
        lines = text.splitlines(keepends=True)
        for i, *_ in sizes.values():
            lines[i] = "\n"
        return "".join(lines)
    if unitless and ("z" in units or spip):
        i, label, value = unitless[0]
        line = _header(text)[i][1].strip()
        if label.lstrip("# ") in ("x-length", "y-length"):
            fix = f"add a line '# {label.lstrip('# ')[0]}-unit = µm' (the unit it is in)"
        else:
            fix = f"write e.g. '{line} µm'"
        raise InputError(f"{path}, line {i + 1}: {label} has no unit ('{line}'); {fix} or give the "
                         "reader option pixel_size_um")
    if len(sizes) == 1:
        (axis, (i, label, _, _)), = sizes.items()
        other = "y" if axis == "x" else "x"
        raise InputError(f"{path}, line {i + 1}: the header gives the map's {axis} size ({label}) "
                         f"but not its {other} size; add it, or give the reader option "
                         "pixel_size_um")
    if "z" not in units and opts.height_unit is not None and (
            (sizes and not unitless) or (len(pixel) == 1 and not pixel_unitless)):
        # SurfaceTopography converts the sizes' units only to a unit the file states
        unit = "µm" if opts.height_unit in ("um", "μm") else opts.height_unit
        return f"# Value units: {unit}\n" + text
    return text


def _is_length(unit: str) -> bool:
    from SurfaceTopography.Support.UnitConversion import is_length_unit, mangle_length_unit_utf8

    return bool(unit) and is_length_unit(mangle_length_unit_utf8(unit))


def _head_lines(text_head: str, n: int = 60) -> list[str]:
    return text_head.splitlines()[:n]


def is_st_text_format(text_head: str) -> bool:
    """Text formats SurfaceTopography reads whole: ISO 25178-71 SDF (ASCII), Wyko ASCII."""
    first = text_head.lstrip("\ufeff")
    return any(r.match(first) for r in _ST_TEXT)


def matrix_header_keys(text_head: str) -> set[str]:
    """The keys of a matrix header (Gwyddion, SPIP, Nova, `h=`/`w=`, `pixel size=` …) before the
    first numbers."""
    keys = set()
    for line in _head_lines(text_head):
        s = line.strip()
        if not s:
            continue
        if _NUMBER_ROW.match(s):
            break
        m = _HEADER.match(s)
        if m:
            keys.add(m.group("key").lower())
        m = _HW_LINE.match(s)
        if m:
            keys.update(k for k in (m.group("k1"), m.group("k2")) if k)
        m = _ST_KEY_START.match(s)
        if m:
            keys.add(" ".join(m.group("key").split()))
    return keys


def is_number_row(line: str) -> bool:
    """Where a matrix header ends: the first line that starts like a number (matrix_header_keys)."""
    return bool(_NUMBER_ROW.match(line))


def has_matrix_header(text_head: str) -> bool:
    """A header naming a matrix's size and unit (two keys at least) before the first numbers."""
    return len(matrix_header_keys(text_head)) >= 2


def _check_rows(path: Path):
    """(rows, columns) of the data; a ragged row or a stray token is named by line."""
    ncols, first, rows = None, None, 0
    with open(path, encoding="utf-8", errors="replace") as f:
        for ln, line in enumerate(f, 1):
            s = line.strip()
            if not s or s.startswith(("#", "%", "//")):
                continue
            if not _NUMBER_ROW.match(s) and rows == 0:
                continue  # header line
            if "," in s or ";" in s:  # SurfaceTopography's matrix reader splits at whitespace only
                raise InputError(f"{path}, line {ln}: values separated by ',' or ';', or written with a "
                                 "decimal comma — a height matrix is read with decimal points between "
                                 "spaces or tabs (Gwyddion: export with 'decimal dot')")
            toks = _SEP.split(s)
            if not _ROW.match(s):
                bad = next((f"column {j}: {t[:40]!r} is not a number" for j, t in enumerate(toks, 1)
                            if not re.fullmatch(_NUM, t)), "not a row of numbers")
                raise InputError(f"{path}, line {ln}, {bad}")
            if ncols is None:
                ncols, first = len(toks), ln
            elif len(toks) != ncols:
                raise InputError(f"{path}, line {ln}: {len(toks)} values where the matrix rows from "
                                 f"line {first} on have {ncols} (ragged matrix, or a truncated file)")
            rows += 1
    if rows == 0:
        raise InputError(f"{path}: a matrix header but no rows of heights")
    return rows, ncols


_SIZE = re.compile(r"^#\s*(Width|Height)\s*:\s*([-+0-9.eE]+)\s*(\S*)", re.MULTILINE)


def _check_single_line(path: Path, text: str, ny: int, nx: int) -> None:
    """One row (or column) of heights is a profile when the header's other size is about one pixel
    (a Gwyddion profile: Width 4 mm over 400 values, Height 0.01 mm); when it spans many pixels the
    file is what is left of a map cut after its first line (a review: matrix-3.txt cut there read
    as one row, its cut last value "1.9473e-0" as 1.9473 m). The format stores no counts."""
    if ny > 1 and nx > 1:
        return
    sizes = {k: (float(v), u) for k, v, u in _SIZE.findall(text[:4096]) if re.fullmatch(_NUM, v)}
    if "Width" not in sizes or "Height" not in sizes or sizes["Width"][1] != sizes["Height"][1]:
        return
    px, py = sizes["Width"][0] / nx, sizes["Height"][0] / ny
    if min(px, py) > 0 and max(px, py) > 2.0 * min(px, py):
        across = round(max(sizes["Height"][0] / px, sizes["Width"][0] / py))
        raise InputError(f"{path}: one {'row' if ny == 1 else 'column'} of heights, but the header's "
                         f"{'Height' if ny == 1 else 'Width'} spans about {across} of its pixels — the "
                         "file looks cut after its first line")



def read_matrix(path: Path, opts):
    """(xyz mm, channels, meta) of a text height matrix with a header."""
    from .instruments import _short, _topography_to_cloud, check_map_geometry, quiet

    ny, nx = _check_rows(path)
    _check_single_line(path, path.read_bytes()[:4096].decode("utf-8", "replace"), ny, nx)
    with quiet():
        from SurfaceTopography.IO import open_topography

        # The text is decoded here, not by SurfaceTopography's reader, which opens the file in the
        # locale's encoding: under a C/POSIX locale without UTF-8 mode that is ASCII, and the 'µm'
        # of a Gwyddion header stops it. UTF-8 first (Gwyddion, SPIP), else Latin-1 (older Windows
        # exports), which decodes any byte.
        raw = path.read_bytes()
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            text = raw.decode("latin-1")
        given = text
        text = _check_header(path, text, opts, ny, nx)
        if text is not given and opts.height_unit is not None and text.startswith("# Value units:"):
            import dataclasses  # height_unit is now the file's stated unit: used, not given twice

            opts = dataclasses.replace(opts, height_unit=None)
        try:
            reader = open_topography(io.StringIO(text), format="asc")
        except Exception as e:  # noqa: BLE001
            why = _short(Exception(_STREAM.sub(path.name, str(e)) or type(e).__name__))
            raise InputError(f"{path}: cannot read this height matrix ({why})") from None
        xyz, ch, meta = _topography_to_cloud(path, reader, opts, b"")
        check_map_geometry(path, xyz, ch, heights=False)  # values are written as they are
    grid = meta.get("grid")
    if grid and grid != [nx, ny]:  # pragma: no cover - the two parsers disagree on the layout
        raise InputError(f"{path}: the matrix has {ny} rows of {nx} values but the header describes "
                         f"{grid[1]} × {grid[0]}")
    name = (reader.channels[0].info.get("raw_metadata") or {}).get("channel_name")
    return xyz, ch, {**meta, "format": "matrix", "instrument_format": "text matrix",
                     **({"channel": name} if name else {})}


def read_headerless(path: Path, data, first_line: int, opts, text_head: str):
    """(xyz mm, channels, meta) of rows of many numbers without a header naming columns (``data``:
    the rows as parsed by core.io.text, which decided they are a matrix): a header with one matrix
    key (``pixel size=`` alone …) goes to read_matrix, whose checks name what else is missing;
    otherwise the reader options ``pixel_size_um`` and ``height_unit`` must give the pixel size and
    the heights' unit — refused naming the one(s) missing. Pixel (i, j) at (i·Δx, j·Δy) as in every
    map; NaN (and |h| ≥ 10³⁰) pixels are invalid, dropped and counted."""
    import numpy as np

    from .instruments import _grid_cloud, _unit_to_mm, check_map_geometry

    if matrix_header_keys(text_head):
        return read_matrix(path, opts)
    ny, nx = data.shape
    missing = [what for what, key in (("pixel size", "pixel_size_um"), ("height unit", "height_unit"))
               if getattr(opts, key) is None]
    if missing:
        give = {"pixel size": "pixel_size_um (µm)",
                "height unit": "height_unit (nm, µm, mm or m)"}
        example = ", ".join(e for what, e in (("pixel size", "pixel_size_um: 1.1"),
                                              ("height unit", "height_unit: nm")) if what in missing)
        raise InputError(
            f"{path}, line {first_line}: {ny} rows of {nx} numbers and no header naming the columns "
            f"— a height matrix, not x y z points, and it states no {' and no '.join(missing)}: "
            f"give the reader option{'s' if len(missing) > 1 else ''} "
            f"{' and '.join(give[k] for k in missing)}, e.g. `input: {{{example}}}` in the recipe; "
            "if the rows are points, add a header line naming the columns (x y z …)")
    unit = "µm" if opts.height_unit in ("um", "μm") else opts.height_unit
    z = np.asarray(data, dtype=np.float64) * _unit_to_mm(unit)  # as instrument maps are converted
    valid = np.isfinite(z) & (np.abs(np.asarray(data)) < 1e30)
    dx, dy = (p * 1e-3 for p in opts.pixel_size_um)  # µm → mm
    xyz, ch, meta = _grid_cloud(z, dx, dy, path, valid=valid)
    check_map_geometry(path, xyz, ch, heights=False)  # values are written as they are
    return xyz, ch, {**meta, "format": "matrix", "instrument_format": "text matrix",
                     "instrument_reader": "rows of heights without a header",
                     "instrument_unit": unit}
