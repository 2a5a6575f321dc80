"""Text exports of CMMs and profilers: CSV / TXT / XYZ / ASC / DAT.

Accepted: a header line or none; preamble lines before the header (instrument, date...); comma,
semicolon, tab or whitespace separators, the header's may differ from the data's (``y x z`` over
tab-separated rows; at whitespace ``x [um]`` is one name); decimal commas when the separator is a
semicolon, tab or space (European exports; with ';' or tab a comma in any data row of the first
1000 lines, not only the first, decides) — a file mixing decimal commas and points is
refused naming the first point; fields in double quotes (``"1","2","3"``); a preamble of up to
1000 lines before the data; UTF-8 (with or without BOM), UTF-16 (BOM, or told by its NUL
bytes) or Latin-1 text; LF, CRLF or CR-alone line ends; lines of blanks read as
empty; comment lines starting with #, //, % or !, except CloudCompare's ``//X Y Z …`` line (or a
``# x y z`` one) right above the data, which names the columns. A line naming the axes must be the
last before the data: one in between (``---``, ``units: mm``) is refused. A length unit in brackets in the
header (``X [µm]``, ``residual [nm]``) converts that column to mm (core.units.length_to_mm: one
correctly rounded operation, none at all for mm, so PointsPro's own files read back bit for bit);
counts and flags (index, row, col …) are never converted; other units (``t [s]``) are kept as read.
``meta["channel_units"]`` states each channel's unit as the file wrote it. Columns beyond x, y, z
become channels named from the header (or ``col4``, ``col5``... without one). Rows with a NaN/inf
value are dropped and counted in ``meta["invalid_dropped"]`` (reader option ``invalid: drop``, the
default of read_cloud) or refused naming line and column (``invalid: error``). A stylus profile —
two columns without a header, or a header with x and z but no y — reads as points on the vertical
plane at azimuth θ, x = s·cos θ, y = s·sin θ (s the file's x), with the channel ``angle`` = θ (the
reader option ``profile_angle_deg``, or the file's own ``angle`` column, default 0°); a ``profile``
column keeps several profiles of one part apart (core.profiles). Each profile's x must be strictly
monotonic: a repeated x or a scan that turns back is refused naming its line. On an x, y, z file
``profile_angle_deg`` names the scan direction of a line of points (the ``angle`` channel). Height
matrices with a header are core.io.matrix's; headerless rows too wide for points (more than 20
numbers, or 8–20 in as many rows: ``_is_matrix_shape``) raise MatrixInText, a
height matrix for core.io.matrix.read_headerless — never points with channels col4 … col650.
Parsing is numpy's C reader (``np.loadtxt``); only when it fails do we walk the lines in Python to
name the exact line and column at fault.
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cloud import EXACT_WHOLE, INTEGER_CHANNELS, repeated_index_message
from ..errors import InputError
from ..units import LENGTH_UNITS, UNITLESS_CHANNELS, is_length_unit, length_to_mm, read_in

COMMENTS = ("#", "//", "%", "!")
_AXIS_ALIASES = {"x": "x", "y": "y", "z": "z", "px": "x", "py": "y", "pz": "z", "pos_x": "x",
                 "pos_y": "y", "pos_z": "z", "x_pos": "x", "y_pos": "y", "z_pos": "z",
                 "xcoord": "x", "ycoord": "y", "zcoord": "z", "x_coord": "x", "y_coord": "y",
                 "z_coord": "z", "meas_x": "x", "meas_y": "y", "meas_z": "z"}


class MatrixInText(InputError):
    """Rows of many numbers without a header naming the columns: a height matrix, not points
    (``_is_matrix_shape``). Its message is the refusal for a matrix that states nothing;
    core.io.formats passes ``data`` (the rows, parsed) and ``first_line`` (1-based) to
    core.io.matrix.read_headerless, which reads it with the reader options or refuses."""

    def __init__(self, message: str, data: np.ndarray, first_line: int):
        super().__init__(message)
        self.data, self.first_line = data, first_line


# Rows without a header naming the columns are x, y, z (+ channels col4 …) while they are no wider than
# a point export writes them. Headerless point exports carry x y z and a few channels — an intensity,
# r g b, normals, CloudCompare's r g b + scalar field + normals (10) — and a CMM's table up to ~15
# (x y z, a direction, deviations, a ball id); a height matrix is a line of the map per row, as wide as
# the map (SurfaceTopography's matrix-2.txt: 650 values a row). So, without a header:
#   more than 20 columns               a matrix;
#   8 to 20 columns in as many rows    a matrix (a square map: matrix-5.txt, 10 × 10);
#   anything else                      points.
# A review of the first rule (more than 10 columns, or 7–10 in up to twice as many rows) found it took
# a 300-row 13-column CMM table and a 4-ball 7-column fiducial export for matrices — refused, or read
# as a 300 × 13 map when a batch's recipe gave the pixel options for its instrument maps.
_POINT_COLUMNS_MAX = 20
_SQUARE_MATRIX_COLUMNS = 8


def _is_matrix_shape(nrows: int, ncols: int) -> bool:
    """Whether headerless rows of ``ncols`` numbers (``nrows`` of them) are a height matrix."""
    if ncols > _POINT_COLUMNS_MAX:
        return True
    return ncols >= _SQUARE_MATRIX_COLUMNS and nrows == ncols


def _is_comment(line: str) -> bool:
    s = line.lstrip()
    return not s or s.startswith(COMMENTS)


def _code(line: str) -> str:
    """``line`` up to its first comment marker (the C readers end a line there)."""
    for c in COMMENTS:
        k = line.find(c)
        if k >= 0:
            line = line[:k]
    return line


_INLINE_COMMENT = re.compile(r"(?:^|(?<=[\s,;]))(?:#|//|%|!)")


def _data_part(line: str) -> str:
    """A candidate data row without its comment: cut where a marker starts a field (_uncommented),
    or at any marker when only that leaves a row of numbers — "1 2 3# first" is the row 1 2 3, as
    the rows' parser reads it (a review: such rows were dropped as a preamble)."""
    u = _uncommented(line)
    if not any(c in u for c in COMMENTS):
        return u
    c = _code(line)
    delim, dc = _sniff_delimiter(c)
    toks = [t for t in _split(c, delim) if t != ""]
    return c if toks and all(_is_number(t, dc) for t in toks) else u


def _uncommented(line: str) -> str:
    """``line`` up to a comment marker that starts a field (after whitespace or a separator): "1 2 3 #
    first point" is a row; "Pt# X Y Z" and "X Y Z Refl[%]" keep their names (a review: cut at any
    marker, "Pt#" became a title and the point numbers x)."""
    m = _INLINE_COMMENT.search(line)
    return line[:m.start()] if m else line


def _split(line: str, delim: str | None) -> list[str]:
    parts = line.strip().split(delim) if delim else line.split()
    return [p.strip() for p in parts]


# The separators a header may be written with, whatever the data's: tab, ';', ',', whitespace.
_SEPARATORS = ("\t", ";", ",", None)
# At whitespace, a unit in brackets or parentheses is part of the name before it: "x [um]", "x(mm)".
_UNIT = r"(?:\[[^\]]*\]|\([^)]*\))"
_WS_FIELD = re.compile(rf"(?:[^\s\[(]|{_UNIT})+(?:\s+{_UNIT})?|\S+")


def _header_tokens(line: str, delim: str | None) -> list[str]:
    """A header's fields split at ``delim`` (without the empty one after a trailing separator); at
    whitespace (None) a unit token belongs to the name before it, so ``x [um] y [um]`` is two
    fields, as ``x [um],y [um]`` is."""
    if delim is None:
        return _WS_FIELD.findall(line)
    toks = _split(line, delim)
    return toks[:-1] if toks and toks[-1] == "" else toks


def _names_axes(toks: list[str], decimal_comma: bool = False) -> bool:
    """Fields that name the axes (x and z, after ``_AXIS_ALIASES``) and hold no number: a header,
    not a title ("Part 7, run 3")."""
    if len(toks) < 2 or any(_is_number(t, decimal_comma) for t in toks):
        return False
    return {"x", "z"} <= {_AXIS_ALIASES.get(n, n) for n, _, _ in map(_header_name, toks)}


def names_axes_above_data(text_head: str, is_data_row) -> bool:
    """Whether the last non-blank line above the first data row (``is_data_row``) names the axes
    (``x y z``, ``# X[mm],Y[mm],Z[mm]``): columns of points, even under a preamble whose ``Width:``
    and ``Height:`` lines look like a height matrix's header (a review: a part's drawing size in the
    preamble made an x y z file a 3 × 6 matrix)."""
    above = None
    for line in text_head.splitlines()[:200]:
        s = line.strip()
        if not s:
            continue
        if is_data_row(s):
            break
        above = s
    else:
        return False
    if above is None:
        return False
    above = above.lstrip("#%/ \t")
    return any(_names_axes(_header_tokens(above, d)) for d in _SEPARATORS)


def _is_number(tok: str, decimal_comma: bool) -> bool:
    """Whether ``tok`` is a number, also written in double quotes (``"1.5"``: numpy's and pandas'
    readers take the quotes off)."""
    if len(tok) >= 2 and tok[0] == tok[-1] == '"':
        tok = tok[1:-1]
    if "_" in tok or not tok.isascii():  # Python's float() takes 1_000 and full-width digits, the
        return False  # readers do not: "could not parse the numeric data" named no line
    try:
        float(tok.replace(",", ".") if decimal_comma else tok)
        return True
    except ValueError:
        return False


def _sniff_delimiter(line: str) -> tuple[str | None, bool]:
    """(delimiter, decimal_comma) from the first data line."""
    if "\t" in line:
        delim = "\t"
    elif ";" in line:
        delim = ";"
    elif "," in line and not re.search(r"\d,\d+\s+-?\d", line) and not _comma_only_last(line):
        delim = ","
    else:
        delim = None
    decimal_comma = delim != "," and "," in line
    return delim, decimal_comma


def _comma_only_last(line: str) -> bool:
    """"0 0 1,25": columns at whitespace with a decimal comma in the last only (integer x, y) — split
    at the comma it is no row of numbers ("0 0 1" | "25"), at whitespace it is (a review: "no
    numeric data rows" for a European export)."""
    ws = line.split()
    return (len(ws) > 1 and not all(_is_number(t, False) for t in _split(line, ",") if t != "")
            and all(_is_number(t, True) for t in ws))


def _header_name(tok: str) -> tuple[str, bool, str | None]:
    """Normalised channel name, whether the unit is a length (converted to mm), unit text."""
    t = tok.strip().strip('"').strip("'").strip()
    unit = None
    m = re.match(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$", t)
    if m:
        t, unit = m.group(1), m.group(2).strip()
    name = re.sub(r"[^0-9a-zA-Z_]+", "_", t.strip()).strip("_").lower()
    if name and name[0].isdigit():
        name = "c_" + name
    return name, is_length_unit(unit), unit


def read_table(path: Path, required: tuple[str, ...], units: dict[str, str] | None = None,
               reader: str = "it") -> dict[str, np.ndarray]:
    """A headed text table of a recipe's parameter (e.g. a calibration series ``t, xd, ref``) as
    columns by name, parsed as point files are; ``required`` names must be in the header. ``units``:
    columns read as a time ("s") or an angle ("deg"), converted from the unit the header states
    (``t [ms]``, ``c [rad]``) or refused naming the file, the column and ``reader`` (the step) when it
    is no such unit (core.units.read_in). Its messages name the file, line and column but never quote
    its content: a recipe may name any file, and the message goes into logs and summary.json."""
    path = Path(path)
    _check_readable(path)
    try:
        _, cols, meta = read_text(path, need_xyz=False, quote=False)
    except OSError as e:
        raise InputError(f"{path}: cannot read it ({e.strerror or type(e).__name__})") from None
    if meta.get("header_line") is None:
        raise InputError(f"{path}: needs a header line naming the columns ({', '.join(required)})")
    missing = [n for n in required if n not in cols]
    if missing:
        raise InputError(f"{path}, line {meta['header_line']}: no {'/'.join(missing)} column")
    for n, unit in (units or {}).items():
        if n in cols:
            cols[n] = read_in(cols[n], meta["channel_units"].get(n), unit,
                              f"{path}, line {meta['header_line']}", n, reader, quote=False)
    return cols


def read_parameter_text(path: Path, what: str = "file") -> str:
    """The UTF-8 text of a recipe's parameter file (a model, a map): InputError naming the file
    when it is missing, unreadable or not text — never quoting its content."""
    path = Path(path)
    _check_readable(path, what)
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not a {what} (not UTF-8 text at byte {e.start})") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read the {what} ({e.strerror or type(e).__name__})") from None


def json_problem(e: BaseException) -> str:
    """Why a parameter file's JSON was refused, quoting none of it: a syntax error's line and
    column, the key missing, or a value of the wrong kind."""
    import json

    if isinstance(e, json.JSONDecodeError):
        return f"not JSON: {e.msg} at line {e.lineno}, column {e.colno}"
    if isinstance(e, KeyError) and e.args and isinstance(e.args[0], str):
        return f"no key '{e.args[0]}'"
    return "a value is not of the expected kind (numbers, lists of numbers)"


def _check_readable(path: Path, what: str = "file") -> None:
    if not path.exists():
        raise InputError(f"{path}: {what} not found")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a {what}")


def read_text(path: Path, need_xyz: bool = True, invalid: str = "error", quote: bool = True,
              profile_angle_deg: float | None = None) -> tuple[np.ndarray | None, dict, dict]:
    """Read a text export. Returns (xyz (N,3) float64 mm, channels, meta); with ``need_xyz=False``
    a header without x, y, z is allowed and every column comes back as a channel (xyz None).
    ``invalid``: "drop" removes rows holding a NaN/inf (``index`` keeps the input row), "error"
    names the first. ``quote=False``: messages name the line and column but quote nothing of the
    file (a parameter file, which is not the user's measurement). ``profile_angle_deg``: the azimuth
    of a stylus profile (see the module doc)."""
    raw = path.read_bytes()
    try:
        text, encoding = _decode(raw)
    except UnicodeDecodeError as e:  # only UTF-16 is decoded strictly
        raise InputError(f"{path}: UTF-16 text that does not decode at byte {e.start} — save it "
                         "as UTF-8") from None
    # Only the head is split into lines to find the layout; the body goes to the C reader whole.
    head = _head_lines(text)
    cr_only = len(head) == 1 and "\r" in text
    if cr_only:  # classic Mac OS line ends (CR alone): one "line" holding the whole file otherwise
        text = text.replace("\r", "\n")
        head = _head_lines(text)
    lines = _LazyLines(text, head)
    lay = _find_layout(path, head, lines, quote)
    data = _parse_numbers(path, raw, text, lines, lay, encoding, quote, cr_only)
    if need_xyz and lay.header is None and _is_matrix_shape(*data.shape):
        first = lay.first_data + 1
        raise MatrixInText(f"{path}, line {first}: {data.shape[0]} rows of {data.shape[1]} numbers "
                           "and no header naming the columns — a height matrix, not x y z points; "
                           "it states no pixel size and no height unit: give the reader options "
                           "pixel_size_um and height_unit", data, first)
    meta: dict = {"format": "text", "delimiter": lay.delim or "whitespace",
                  "decimal_comma": lay.decimal_comma,
                  "header_line": lay.header[0] + 1 if lay.header else None}
    if lay.header:
        names, lengths, units = _header_columns(path, lay, need_xyz, quote)
        if not need_xyz:
            _check_finite(path, lines, lay.first_data, data, names, quote)
            meta["channel_units"] = {n: u for n, u in zip(names, units) if u}
            return None, {n: (length_to_mm(data[:, j], u) if is_len and n not in UNITLESS_CHANNELS
                              else data[:, j])
                          for j, (n, is_len, u) in enumerate(zip(names, lengths, units))}, meta
    else:
        names, lengths, units = _plain_columns(path, lay)
    xyz, cols = _xyz_in_mm(path, lay, data, names, lengths, units)
    meta["channel_units"] = {n: u for n, u in zip(names, units) if u and n not in ("x", "y", "z")}
    # the file's own index (PointsPro's cloud.csv: the original input's row) numbers no line of this
    # file; one the reader makes is the data row (the dynamic step names lines through it)
    meta["index_in_file"] = "index" in names
    stated = {n: u for n, u in zip(names, units) if u and n in ("x", "y", "z")}
    if stated:  # x, y, z are mm once read; the units the file stated them in, for the report
        meta["xyz_units_stated"] = stated
    keep = _rows_to_keep(path, lines, lay.first_data, data, names, invalid, quote)
    meta["invalid_dropped"] = 0 if keep is None else int((~keep).sum())
    rows = np.arange(len(data))
    if keep is not None:
        # which columns: a NaN in a quality or temperature channel drops the point whole, and 14 % of
        # a file went with no word but a count in report.json (a review) — the batch says it now
        bad = ~np.isfinite(data[~keep])
        meta["invalid_columns"] = {n: int(bad[:, j].sum()) for j, n in enumerate(names) if bad[:, j].any()}
        if lines.split_is_cheap():  # a 100 MB file's lines split for it: +0.7 s, +0.2 GB (a review)
            meta["invalid_first_line"] = _data_line_number(lines.all(), lay.first_data,
                                                           int(np.flatnonzero(~keep)[0]))
        xyz = xyz[keep]
        rows = rows[keep]
        cols = {n: a[keep] for n, a in cols.items()}
        if "index" not in cols:
            cols["index"] = np.flatnonzero(keep).astype(np.int64)
    _check_index(path, lines, lay.first_data, cols, names, rows, quote)
    from .formats import beyond_any_machine

    why = beyond_any_machine(xyz)
    if why:  # named by its line here (read_cloud's own check names a point of the other formats)
        raise InputError(f"{path}, line {_data_line_number(lines.all(), lay.first_data, int(rows[why[0]]))}: "
                         f"{why[1]}")
    if "y" not in names:
        xyz, cols, meta["profile"] = _profile_placed(path, lines, lay.first_data, xyz, cols, rows,
                                                     profile_angle_deg)
    elif profile_angle_deg is not None:  # an x, y, z line whose scan direction the user names
        if "angle" in cols:
            raise InputError(f"{path}: has its own angle column; leave out the reader option "
                             "profile_angle_deg")
        cols["angle"] = np.full(len(xyz), float(profile_angle_deg))
    return xyz, cols, meta


@dataclass
class _Layout:
    """Where the numbers are and how they are written."""

    first_data: int  # 0-based line of the first data row
    delim: str | None  # None: whitespace
    decimal_comma: bool
    ncols: int
    trailing_empty: bool  # "1,2,3," rows: an empty field after the last delimiter
    header: tuple[int, list[str]] | None = None  # (0-based line, names as written)
    comma_line: int | None = None  # 0-based line of the first decimal comma


# Lines split up front to find the layout: a preamble (instrument, part, operator …) may be this long.
_HEAD_LINES = 1000


def _head_lines(text: str, n: int = _HEAD_LINES) -> list[str]:
    """The first ``n`` lines of ``text``, as ``str.split`` at line feeds gives them, without copying
    the rest of a big file (a split with ``maxsplit`` does: 50 ms on 40 MB)."""
    end = 0
    for _ in range(n):
        k = text.find("\n", end)
        if k < 0:
            return text.split("\n")
        end = k + 1
    return text[:end].split("\n")[:n]


def utf16_codec(raw: bytes) -> str | None:
    """The UTF-16 codec of ``raw`` — by its BOM, else by the NUL bytes of ASCII text in UTF-16 (every
    other byte zero) — or None."""
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "utf-16"
    sample = raw[:4096]
    sample = sample[:len(sample) // 2 * 2]
    if len(sample) < 4 or b"\0" not in sample:
        return None
    even, odd = sample[0::2].count(0), sample[1::2].count(0)
    half = len(sample) // 2
    if odd >= 0.9 * half and even <= 0.1 * half:
        return "utf-16-le"
    if even >= 0.9 * half and odd <= 0.1 * half:
        return "utf-16-be"
    return None


def _decode(raw: bytes) -> tuple[str, str]:
    """(text, encoding): UTF-16 (BOM, or the NUL bytes of BOM-less UTF-16: decoded strictly, a
    UnicodeDecodeError otherwise), UTF-8 (with or without BOM), else Latin-1 (Windows exports with
    µ)."""
    utf16 = utf16_codec(raw)
    if utf16:
        return raw.decode(utf16), utf16
    try:
        return raw.decode("utf-8-sig"), "utf-8-sig"
    except UnicodeDecodeError:
        return raw.decode("latin-1"), "latin-1"


def _find_layout(path, head: list[str], lines: "_LazyLines", quote: bool = True) -> _Layout:
    """The first data line, the delimiter, the column count and the header (if any)."""
    first_data, candidates = _first_data_line(path, head, lines, quote)
    delim, decimal_comma = _sniff_delimiter(_data_part(lines[first_data]))
    comma_line = first_data if decimal_comma else None
    if delim in (";", "\t") and not decimal_comma:
        # "1;2;3" then "4,5;5;6": a decimal comma in any data row of the head decides, not the first
        # row alone (a comma is no separator here). At whitespace "4, 5, 6" may be comma-separated.
        comma_line = next((i for i in range(first_data + 1, len(head))
                           if "," in head[i] and _comma_row(head[i], delim)), None)
        decimal_comma = comma_line is not None
    first_toks = _split(_data_part(lines[first_data]), delim)
    trailing_empty = bool(first_toks) and first_toks[-1] == ""
    ncols = len(first_toks) - (1 if trailing_empty else 0)
    lay = _Layout(first_data, delim, decimal_comma, ncols, trailing_empty, comma_line=comma_line)
    if candidates:
        lay.header = _find_header(path, lines, candidates[-1], lay, quote)
        _check_nothing_between(path, lines, candidates, lay, quote)
    if lay.header is None:
        lay.header = _comment_header(lines, first_data, lay)
    return lay


def _comma_row(line: str, delim: str) -> bool:
    """Whether ``line`` is a row of numbers with a decimal comma ("4,5;5;6"), not a footer or a note
    ("End, 2 points") nor "1,000.5" (a thousands comma: refused later, naming it)."""
    code = _code(line)
    toks = [t for t in _split(code, delim) if t != ""]
    return "," in code and bool(toks) and all(_is_number(t, True) for t in toks)


def _comment_header(lines: "_LazyLines", first_data: int, lay: _Layout) -> tuple[int, list[str]] | None:
    """CloudCompare's ASCII export names its columns in a comment right above the data:
    ``//X Y Z SF``, ``//X,Y,Z,R,G,B,Scalar field`` or ``//X [um] Y [um] Z [um]``; so may a ``#``
    comment (``# x[um] y[um] z[um]``). That line is the header when it names x, y and z and has one
    name a column — split at the data's separator, else at the one other that gives as many (a
    space inside the last name is kept after ``//``: ``//X Y Z Scalar field``); any other comment
    stays a comment."""
    i = first_data - 1
    while i >= 0 and not lines[i].strip():
        i -= 1
    if i < 0:
        return None
    s = lines[i].lstrip()
    if s.startswith("//"):
        body = s[2:].strip()
    elif s.startswith("#"):
        body = s.lstrip("#").strip()
    else:
        return None
    toks = _header_tokens(body, lay.delim)
    if s.startswith("//") and len(toks) > lay.ncols and lay.delim is None and lay.ncols >= 4:
        toks = toks[:lay.ncols - 1] + [" ".join(toks[lay.ncols - 1:])]
    fits = [t for t in [toks] + [_header_tokens(body, d) for d in _SEPARATORS if d != lay.delim]
            if len(t) == lay.ncols and _names_xyz_once(t)]
    if not fits or any(t != fits[0] for t in fits):  # none, or several ways: a comment
        return None
    return i, fits[0]


def _names_xyz_once(toks: list[str]) -> bool:
    """Whether the fields name x, y and z, and no column twice."""
    names = [_AXIS_ALIASES.get(n, n) for n, _, _ in map(_header_name, toks)]
    return {"x", "y", "z"} <= set(names) and len(set(names)) == len(names)


def _first_data_line(path, head: list[str], lines: "_LazyLines", quote: bool = True
                     ) -> tuple[int, list[int]]:
    """(first all-numeric line, the non-numeric non-comment lines before it) — 0-based; looked for
    in the head (``_HEAD_LINES``), so a preamble of any length up to that is skipped."""
    candidates = []
    for i, line in enumerate(head):
        line = line.rstrip("\r")
        if _is_comment(line):
            continue
        line = _data_part(line)  # "1 2 3 # first point": the rows' parser ends a line at its comment too
        delim, dc = _sniff_delimiter(line)
        toks = _split(line, delim)
        if all(_is_number(t, dc) for t in toks if t != "") and any(t != "" for t in toks):
            return i, candidates
        candidates.append(i)
    beyond = lines.beyond(len(head))
    if beyond and not candidates:
        raise InputError(f"{path}: no numeric data rows in the first {len(head)} lines (comments and "
                         "blank lines only)")
    if candidates:
        ln = candidates[0] + 1
        where = f"in the first {len(head)} lines" if beyond else "found"
        if not quote:
            raise InputError(f"{path}: no numeric data rows {where} (from line {ln} on)")
        raise InputError(f"{path}: no numeric data rows {where} (first line {ln}: "
                         f"{lines[candidates[0]].strip()[:60]!r})")
    raise InputError(f"{path}: empty file — no data rows")


def _find_header(path, lines: "_LazyLines", i: int, lay: _Layout, quote: bool = True
                 ) -> tuple[int, list[str]] | None:
    """The header is the last non-numeric line before the data when it has as many fields: split at
    the data's separator, else at the one other separator (tab, ';', ',', whitespace) that gives as
    many fields naming the axes — "y x z" over tab-separated rows, "y;x;z" over "1,2,3"."""
    hline = _uncommented(lines[i])  # "x y z  # probe centres": the names before the comment
    htoks = _header_tokens(hline, lay.delim)
    numeric = [_is_number(t, lay.decimal_comma) for t in htoks]
    if len(htoks) == lay.ncols and all(numeric):  # numbers, split otherwise than the rows after
        raise InputError(f"{path}, line {i + 1}: a row of numbers whose separators differ from "
                         f"those of line {lay.first_data + 1} (tabs and spaces mixed?)")
    if len(htoks) == lay.ncols and sum(numeric) > len(htoks) / 2:
        # mostly numbers: a damaged data line, not a header
        j = numeric.index(False)
        raise InputError(f"{path}, line {i + 1}, column {j + 1}: {_q(htoks[j], quote)}is "
                         "not a number")
    if len(htoks) == lay.ncols:
        return i, htoks
    # Written with another separator than the rows: ignored, "y;x;z" over "1,2,3" would read y as x
    # and "x [um] y [um] z [um]" over "1000,2000,3" µm as mm. Only a split that names the axes is
    # taken: a title ("Measured by A. Smith") may split into as many words as there are columns.
    others = [t for t in (_header_tokens(hline, d) for d in _SEPARATORS if d != lay.delim)
              if _names_axes(t, lay.decimal_comma)]
    fits = {tuple(t) for t in others if len(t) == lay.ncols}
    if len(fits) == 1:
        return i, list(fits.pop())
    # A header that names the axes but not as many columns as the data holds: read without it,
    # "y,x,z" over four columns would silently become x, y, z, col4, and "x,y,z" over a short first
    # row a stylus profile. A title line ("Part 7, run 3") names no axes and stays a title.
    named = htoks if _names_axes(htoks, lay.decimal_comma) else others[0] if others else None
    if fits:
        raise InputError(f"{path}, line {i + 1}: the header splits into {lay.ncols} names in more "
                         f"than one way — write it with the separator of the data (line "
                         f"{lay.first_data + 1})")
    if named:
        names = f" ({', '.join(t.strip() for t in named)})" if quote else ""
        raise InputError(f"{path}, line {i + 1}: the header names {len(named)} columns{names} but "
                         f"line {lay.first_data + 1} holds {lay.ncols} value(s)")
    return None


def _check_nothing_between(path, lines: "_LazyLines", candidates: list[int], lay: _Layout,
                           quote: bool = True) -> None:
    """A line naming the axes must be the last before the data: with a line in between ("---",
    "units: mm", a first row with a stray field or a quoted "1,000.5") it would be taken for a
    title and the columns read as x, y, z in mm — y for x, µm for mm. A title naming no axes
    ("Part 7, run 3") may stand anywhere."""
    for n in range(len(candidates) - 2, -1, -1):
        k = candidates[n]
        low = lines[k].lower()  # a preamble may be long: only a line with an x and a z can name them
        if "x" not in low or "z" not in low or not any(
                _names_axes(_header_tokens(lines[k], d), lay.decimal_comma) for d in _SEPARATORS):
            continue
        m = candidates[n + 1]
        where = f"between the header (line {k + 1}) and the data (line {lay.first_data + 1})"
        toks = _header_tokens(lines[m], lay.delim)
        numeric = [_is_number(t, lay.decimal_comma) for t in toks]
        if toks and all(numeric):  # numbers, split otherwise than the rows after
            raise InputError(f"{path}, line {m + 1}: a row of numbers whose separators differ from "
                             f"those of line {lay.first_data + 1}, {where}")
        if sum(numeric) > len(toks) / 2:  # a data row with a stray field: say which
            j = numeric.index(False)
            raise InputError(f"{path}, line {m + 1}, column {j + 1}: {_q(toks[j], quote)}is not a "
                             f"number — a line that is not all numbers stands {where}")
        raise InputError(f"{path}, line {m + 1}: a line that is neither numbers nor a comment "
                         f"stands {where} — remove it or make it a comment")


def _parse_numbers(path, raw: bytes, text: str, lines: "_LazyLines", lay: _Layout,
                   encoding: str, quote: bool = True, cr_only: bool = False) -> np.ndarray:
    """The data rows as an (N, ncols) array: pandas' C reader for big files, else numpy's; a
    failure is named by line and column (``_diagnose``). ``cr_only``: the file's line ends are CR
    alone, ``text`` has them as LF (the readers of the path would count lines otherwise)."""
    # numpy's reader is ~2x slower with several comment markers, so pass only those present.
    present = [c for c in COMMENTS if c in text]
    comments = None if not present else present[0] if len(present) == 1 else present
    usecols = range(lay.ncols) if lay.trailing_empty else None
    if lay.decimal_comma:
        _check_decimal_marks(path, text, lines.offset(lay.first_data), lay, quote)
    data = None
    # pandas reads the file's bytes: not for UTF-16 (the numpy path reads the decoded text)
    if len(raw) > _FAST_BYTES and not cr_only and encoding in ("utf-8-sig", "latin-1"):
        data = _arrow_parse(path, lay.first_data, lay.delim, lay.decimal_comma, comments, lay.ncols,
                            lay.trailing_empty, encoding, raw)
        # pandas counts skipped lines as CSV rows, a quote joining lines: a preamble with quotes
        # ('"q' twice) made it skip a data row, silently (a review); numpy's path reads such files
        if data is None and '"' not in text[:lines.offset(lay.first_data)]:
            data = _fast_parse(path, lay.first_data, lay.delim, lay.decimal_comma, comments, lay.ncols,
                               lay.trailing_empty, encoding)
    # "1","2","3": numpy takes the quotes off when told to; looked for only when there are any
    quotechar = '"' if data is None and '"' in text else None
    try:
        if data is not None:
            pass
        elif lay.decimal_comma or encoding != "utf-8-sig" or cr_only:
            data = _loadtxt_text(text.split("\n")[lay.first_data:], lay, comments, usecols, quotechar)
        else:
            data = np.loadtxt(path, delimiter=lay.delim, comments=comments, ndmin=2, dtype=np.float64,
                              usecols=usecols, skiprows=lay.first_data, encoding="utf-8-sig",
                              quotechar=quotechar)
    except ValueError:
        # Lines of blanks only ("   ", a stray tab) read as the empty lines they look like; numpy
        # takes them for a row of empty fields. Looked for only now, so good files pay nothing.
        body = text.split("\n")[lay.first_data:]
        try:
            if not any(ln and not ln.strip() for ln in body):
                raise ValueError  # no line of blanks: the failure is elsewhere
            data = _loadtxt_text([ln for ln in body if ln.strip()], lay, comments, usecols,
                                 quotechar)
        except ValueError:
            _diagnose(path, lines.all(), lay.first_data, lay.delim, lay.decimal_comma, lay.ncols,
                      lay.trailing_empty, quote)
            raise InputError(f"{path}: could not parse the numeric data") from None  # pragma: no cover
    if data.shape[1] != lay.ncols:  # pragma: no cover - loadtxt keeps the width
        raise InputError(f"{path}: expected {lay.ncols} columns, got {data.shape[1]}")
    return data


def _loadtxt_text(body: list[str], lay: _Layout, comments, usecols, quotechar=None) -> np.ndarray:
    """numpy's reader on data lines already decoded (decimal commas made points)."""
    text = "\n".join(body)
    if lay.decimal_comma:
        text = text.replace(",", ".")
    return np.loadtxt(io.StringIO(text), delimiter=lay.delim, comments=comments, ndmin=2,
                      dtype=np.float64, usecols=usecols, quotechar=quotechar)


def _check_decimal_marks(path, text: str, start: int, lay: _Layout, quote: bool = True) -> None:
    """A file of decimal commas must write no decimal point in its data (from ``start``, the first
    data line's offset in ``text``): "4,5" and "4.5" mixed — or "1.000,5" — would read half wrong,
    so the first point is named by line and column. A point in a comment is no number's."""
    pos = text.find(".", start)
    while pos >= 0:
        a = text.rfind("\n", 0, pos) + 1
        b = text.find("\n", pos)
        b = len(text) if b < 0 else b
        code = _code(text[a:b].rstrip("\r"))
        if "." in code:
            toks = _split(code, lay.delim)
            j = next(k for k, t in enumerate(toks) if "." in t)
            ln = text.count("\n", 0, a) + 1
            comma = lay.comma_line + 1 if lay.comma_line is not None else lay.first_data + 1
            raise InputError(f"{path}, line {ln}, column {j + 1}: {_q(toks[j], quote)}has a decimal "
                             f"point but line {comma} a decimal comma — write every number one way")
        pos = text.find(".", b)


def _header_columns(path, lay: _Layout, need_xyz: bool, quote: bool = True):
    """(names, whether each unit is a length, unit texts) from the header; x, y, z required when ``need_xyz``."""
    line, written = lay.header
    names, lengths, units = zip(*(_header_name(t) for t in written))
    names = [_AXIS_ALIASES.get(n, n) for n in names]
    for j, n in enumerate(names):
        if not n:
            raise InputError(f"{path}, line {line + 1}: column {j + 1} has no name")
    dup = {n for n in names if names.count(n) > 1}
    if dup and not quote:
        cols = [j + 1 for j, n in enumerate(names) if n in dup]
        raise InputError(f"{path}, line {line + 1}: duplicate column names (columns "
                         f"{', '.join(map(str, cols))})")
    if dup:
        raise InputError(f"{path}, line {line + 1}: duplicate column name(s) {sorted(dup)}")
    if not need_xyz:
        return names, lengths, units
    if "y" not in names and "x" in names and "z" in names:
        return names, lengths, units  # a stylus profile: x along the scan, z
    missing = [a for a in "xyz" if a not in names]
    if missing:
        raise InputError(f"{path}, line {line + 1}: no {'/'.join(missing)} column in the header "
                         f"(columns: {', '.join(written)})")
    return names, lengths, units


def _plain_columns(path, lay: _Layout):
    """Names without a header: x, y, z, col4, col5…; no units."""
    if lay.ncols == 2:  # a stylus profile: x, z
        return ["x", "z"], [None, None], [None, None]
    if lay.ncols < 3:
        raise InputError(f"{path}, line {lay.first_data + 1}: {lay.ncols} column(s); need at least "
                         "x, y, z")
    names = ["x", "y", "z"] + [f"col{j + 1}" for j in range(3, lay.ncols)]
    return names, [None] * lay.ncols, [None] * lay.ncols


def _xyz_in_mm(path, lay: _Layout, data, names, lengths, units):
    """(xyz (N,3) in mm, the other columns by name). A length unit in the header (``X [µm]``,
    ``residual [nm]``) converts that column to mm in one correctly rounded operation
    (core.units.length_to_mm; mm itself is left as read, bit for bit); x, y, z with a unit that is
    no length are refused; counts, labels and flags (index, row, col …) are never converted; other
    units (``t [s]``) are kept as read and stated in ``meta["channel_units"]``."""
    cols = {n: data[:, j] for j, n in enumerate(names)}
    xyz = np.column_stack([cols.pop("x"), cols.pop("y") if "y" in cols else np.zeros(len(data)),
                           cols.pop("z")])
    # a coordinate without a unit beside one stated in another length (`x [µm], y [µm], z`): read as
    # mm it would be silently 1000× off if the writer meant the same µm (a review) — refused
    stated = {a: units[names.index(a)] for a in "xyz"
              if a in names and units[names.index(a)] and lengths[names.index(a)]}
    bare = [a for a in "xyz" if a in names and not units[names.index(a)]]
    other = sorted({u for u in stated.values() if u.strip().lower() != "mm"})
    if bare and other:
        raise InputError(f"{path}, line {lay.header[0] + 1}: {' and '.join(sorted(stated))} "
                         f"{'is' if len(stated) == 1 else 'are'} given in {' and '.join(other)} but "
                         f"{' and '.join(bare)} {'has' if len(bare) == 1 else 'have'} no unit (it would "
                         f"be read as mm): state it, e.g. {bare[0]} [{other[0]}] or {bare[0]} [mm]")
    for a in "xyz":
        if a not in names:
            continue
        j = names.index(a)
        if units[j] is not None:
            if not lengths[j]:
                raise InputError(f"{path}, line {lay.header[0] + 1}: unknown unit [{units[j]}] for {a}; "
                                 f"known: {', '.join(LENGTH_UNITS)}")
            xyz[:, "xyz".index(a)] = length_to_mm(xyz[:, "xyz".index(a)], units[j])
    for j, n in enumerate(names):
        if n in cols and lengths[j] and n not in UNITLESS_CHANNELS:
            cols[n] = length_to_mm(cols[n], units[j])
    return xyz, cols


def _rows_to_keep(path, lines, first_data, data, names, invalid: str, quote: bool = True
                  ) -> np.ndarray | None:
    """The rows without NaN/inf (None: all) with ``invalid: drop``; with "error", the first named."""
    if invalid != "drop":
        _check_finite(path, lines, first_data, data, names, quote)
        return None
    keep = np.isfinite(data).all(axis=1)
    if keep.all():
        return None
    if not keep.any():
        try:
            _check_finite(path, lines, first_data, data, names, quote)
        except InputError as e:  # name the first, then say why it is fatal
            raise InputError(f"{str(e).split(': ', 1)[0]}: every data row holds a NaN/inf value "
                             "— nothing left to read") from None
    return keep


def _check_index(path, lines, first_data, cols: dict, names, rows, quote: bool = True) -> None:
    """The integer columns of the file (index, line, fiducial, sensor) must be whole numbers below 2⁵³,
    read exactly from float64 — cast as they are, 1e300 or 9.3e18 wrapped to -9223372036854775808 with
    no more than a RuntimeWarning — and non-negative (docs/formats.md), the index never repeated; the
    first bad value is named by line and column."""
    for n in (n for n in names if n in INTEGER_CHANNELS and n in cols):
        v = cols[n]
        # ≥ 0 for all four (docs/formats.md): a line, ball or sensor number of −1 is no number at all
        # < 2⁵³: the file's numbers are parsed as float64, exact as whole numbers only that far — 2⁵³ + 1
        # read as 2⁵³, 2⁶² + 3 as 2⁶² + 4, with no message (a review); beyond it a value is refused
        bad = ~((v == np.floor(v)) & (v >= 0.0) & (v < EXACT_WHOLE))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            ln = _data_line_number(lines.all(), first_data, int(rows[row]))
            val = f"{float(v[row])!r} " if quote else ""
            what = ("a non-negative whole number below 2⁵³ = 9007199254740992 (the index numbers the "
                    "input rows)" if n == "index" else "a whole number from 0 to below 2⁵³ = 9007199254740992")
            if v[row] == np.floor(v[row]) and v[row] >= EXACT_WHOLE:
                what += ": a file's numbers are read as float64, exact whole numbers only below it"
            raise InputError(f"{path}, line {ln}, column {names.index(n) + 1} ({n}): {val}is not "
                             f"{what}")
    why = repeated_index_message(cols["index"]) if "index" in cols else None
    if why:
        raise InputError(f"{path}: {why}")


_FAST_BYTES = 4_000_000


def _arrow_parse(path, first_data, delim, decimal_comma, comments, ncols, trailing_empty, encoding, raw):
    """Arrow's CSV reader (pyarrow, which the CSV writer uses already) for the common export — one
    comma, semicolon or tab between values, decimal points, no comment markers, UTF-8: no pandas
    import (0.3 s of a batch process's start) and parsing on the process's threads (10⁶ rows 0.40 →
    0.21 s, pandas' import included). Its float parsing is correctly rounded (round trip of 17-digit values tested). Anything
    else — comments, whitespace columns, decimal commas, a BOM on the first data line, a parse error,
    an empty field, a blank line of spaces — returns None and pandas' or numpy's path runs, which
    names the line and column at fault."""
    if (comments is not None or delim is None or decimal_comma or encoding != "utf-8-sig"
            or (first_data == 0 and raw.startswith(b"\xef\xbb\xbf"))):
        return None
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:  # pragma: no cover - a dependency
        return None
    from ..parallel import thread_count

    width = ncols + 1 if trailing_empty else ncols
    names = [f"c{i}" for i in range(width)]
    try:
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(skip_rows=first_data, column_names=names,
                                           use_threads=thread_count() > 1),
            parse_options=pacsv.ParseOptions(delimiter=delim, ignore_empty_lines=True),
            convert_options=pacsv.ConvertOptions(column_types={c: pa.float64() for c in names},
                                                 null_values=[""], strings_can_be_null=False))
    except Exception:  # noqa: BLE001 - any failure: the other paths parse and diagnose
        return None
    cols = [table.column(i) for i in range(width)]
    if trailing_empty:
        if cols[-1].null_count != len(cols[-1]):
            return None
        cols = cols[:ncols]
    if any(c.null_count for c in cols):
        return None
    data = np.empty((table.num_rows, ncols))
    for i, c in enumerate(cols):  # from the chunks' value buffers: Arrow's to_numpy imports pandas
        row = 0
        for ch in c.chunks:
            data[row:row + len(ch), i] = np.frombuffer(ch.buffers()[1], dtype=np.float64, count=len(ch),
                                                       offset=8 * ch.offset)
            row += len(ch)
    return data if np.isfinite(data).all() else None


def _fast_parse(path, first_data, delim, decimal_comma, comments, ncols, trailing_empty, encoding):
    """pandas' C reader (already installed with SurfaceTopography), ~12× faster than np.loadtxt on
    big exports (10⁶ rows: 0.14 s against 1.7 s) and exact (round-trip float64 tested). Any doubt —
    a parse error, an empty or missing field (NaN), a multi-character comment marker — returns None
    and the numpy path runs, which names the line and column at fault."""
    if comments is not None and not (isinstance(comments, str) and len(comments) == 1):
        return None
    try:
        import pandas as pd
    except ImportError:  # pragma: no cover - a dependency of SurfaceTopography
        return None
    try:
        df = pd.read_csv(path, sep=delim if delim else r"\s+", header=None, skiprows=first_data,
                         comment=comments, decimal="," if decimal_comma else ".", dtype=np.float64, engine="c", skipinitialspace=True, encoding=encoding,
                         skip_blank_lines=True)
    except Exception:  # noqa: BLE001 - any failure: the numpy path parses and diagnoses
        return None
    data = df.to_numpy(dtype=np.float64)
    if trailing_empty and data.ndim == 2 and data.shape[1] == ncols + 1 and np.isnan(data[:, -1]).all():
        data = data[:, :ncols]  # "1,2,3," rows: the empty field after the last delimiter
    if data.ndim != 2 or data.shape[1] != ncols or not np.isfinite(data).all():
        return None
    return data


def _profile_placed(path, lines, first_data, xyz, cols, rows, angle_opt):
    """A stylus profile's points on their vertical plane: x = s·cos θ, y = s·sin θ (s the file's x),
    θ from the reader option or the file's ``angle`` column (default 0°), the ``angle`` channel set.
    Each profile (the ``profile`` column, else each angle) must scan x strictly one way."""
    n = len(xyz)
    if n < 2:
        raise InputError(f"{path}: a profile of {n} point{'s' if n != 1 else ''} — a stylus profile "
                         "needs a scan of several points")
    if angle_opt is not None and "angle" in cols:
        raise InputError(f"{path}: has its own angle column; leave out the reader option "
                         "profile_angle_deg")
    angle = cols["angle"] if "angle" in cols else np.full(n, 0.0 if angle_opt is None else float(angle_opt))
    key = cols["profile"] if "profile" in cols else angle
    s = xyz[:, 0]
    for v in dict.fromkeys(key.tolist()):
        g = np.flatnonzero(key == v)
        d = np.diff(s[g])
        if not d.size:
            continue
        rep = np.flatnonzero(d == 0)
        turn = np.flatnonzero(np.sign(d[1:]) != np.sign(d[0])) + 1 if d[0] != 0 else np.array([], int)
        if rep.size and (not turn.size or rep[0] <= turn[0]):
            i = int(rep[0])
            ln = _data_line_number(lines.all(), first_data, int(rows[g[i + 1]]))
            prev = _data_line_number(lines.all(), first_data, int(rows[g[i]]))
            raise InputError(f"{path}, line {ln}: x = {s[g[i]]:.9g} mm repeats line {prev}'s — a profile "
                             "holds one height per position; remove one of them")
        if turn.size:
            i = int(turn[0])
            ln = _data_line_number(lines.all(), first_data, int(rows[g[i + 1]]))
            raise InputError(f"{path}, line {ln}: the scan is not monotonic in x ({s[g[i - 1]]:.9g} → "
                             f"{s[g[i]]:.9g} → {s[g[i + 1]]:.9g} mm) — a profile is one scan in one "
                             "direction: sort it, or tell profiles apart with a `profile` column")
    t = np.radians(angle)
    out = np.column_stack([s * np.cos(t), s * np.sin(t), xyz[:, 2]])
    exact = np.isin(angle, (0.0,))  # cos 0 = 1, sin 0 = 0: x as read, bit for bit
    out[exact, 0], out[exact, 1] = s[exact], 0.0
    cols = {**cols, "angle": np.asarray(angle, dtype=np.float64)}
    angles = sorted(set(np.asarray(angle, dtype=np.float64).tolist()))
    info = {"angle_deg": angles[0] if len(angles) == 1 else angles,
            "profiles": len(set(key.tolist())), "from": "x, z columns"}
    return out, cols, info


def _check_finite(path, lines, first_data, data, names, quote: bool = True) -> None:
    """Values must be measurements: the first NaN/inf named by line and column."""
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        ln = _data_line_number(lines.all(), first_data, int(row))
        if not quote:
            raise InputError(f"{path}, line {ln}, column {col + 1}: not a finite number (NaN/inf is "
                             "not a measurement)")
        raise InputError(f"{path}, line {ln}, column {col + 1} ({names[col]}): "
                         f"{float(data[row, col])!r} is not a finite number (NaN/inf is not a measurement)")


class _LazyLines:
    """The file's lines: the head is split up front, the rest only when an error needs a line number."""

    def __init__(self, text: str, head: list[str]):
        self._text, self._head, self._all = text, head, None

    def __getitem__(self, i: int) -> str:
        return (self._head if i < len(self._head) - 1 else self.all())[i].rstrip("\r")

    def all(self) -> list[str]:
        if self._all is None:
            self._all = self._text.splitlines()
        return self._all

    def split_is_cheap(self, limit: int = 20_000_000) -> bool:
        """Whether ``all()`` costs little: split already, or a text of at most ``limit`` characters."""
        return self._all is not None or len(self._text) <= limit

    def offset(self, i: int) -> int:
        """Where line ``i`` (of the head) starts in the text."""
        return sum(len(h) + 1 for h in self._head[:i])

    def beyond(self, n: int) -> bool:
        """Whether the text goes on after its first ``n`` lines (those of the head)."""
        return self.offset(n) < len(self._text)


def _data_line_number(lines, first_data, row) -> int:
    k = -1
    for i in range(first_data, len(lines)):
        if not _is_comment(lines[i]):
            k += 1
            if k == row:
                return i + 1
    return first_data + row + 1


def _q(token: str, quote: bool) -> str:
    """``'token' `` (40 characters at most) to quote in a message, or nothing when ``quote`` is off."""
    return f"{token[:40]!r} " if quote else ""


def _diagnose(path, lines, first_data, delim, decimal_comma, ncols, trailing_empty, quote=True):
    """Walk the data lines to name the first bad one (only runs after the fast reader failed)."""
    for i in range(first_data, len(lines)):
        line = lines[i]
        if _is_comment(line):
            continue
        toks = _split(line, delim)
        if trailing_empty and toks and toks[-1] == "":
            toks = toks[:-1]
        if len(toks) != ncols:
            raise InputError(f"{path}, line {i + 1}: {len(toks)} column(s), expected {ncols} "
                             f"as on line {first_data + 1}")
        raw = line.split(delim) if delim else None
        for j, t in enumerate(toks):
            if raw is not None and j < len(raw) and t.startswith('"') and not raw[j].startswith('"'):
                # numpy's reader takes a quote only at the start of a field (pandas' after spaces too)
                raise InputError(f"{path}, line {i + 1}, column {j + 1}: {_q(raw[j], quote)}has a space "
                                 "before its opening quote — write the quote first (\"1.5\") or no quotes")
            if not _is_number(t, decimal_comma):
                hint = (" (a decimal comma where the rows above have none — write every number "
                        "one way)"
                        if delim in (";", "\t") and _is_number(t, True) else "")
                raise InputError(f"{path}, line {i + 1}, column {j + 1}: {_q(t, quote)}is not a "
                                 f"number{hint}")
