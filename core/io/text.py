"""Text exports of CMMs and profilers: CSV / TXT / XYZ / ASC / DAT.

Accepted: a header line or none; preamble lines before the header (instrument, date...); comma,
semicolon, tab or whitespace separators; decimal commas when the separator is a semicolon, tab or
space (European exports); comment lines starting with #, //, % or !; a unit in brackets in the header
(``X [µm]``) scales x, y, z to mm. Columns beyond x, y, z become channels named from the header (or
``col4``, ``col5``... without one). Parsing is numpy's C reader (``np.loadtxt``); only when it fails
do we walk the lines in Python to name the exact line and column at fault.
"""
from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

from ..errors import InputError

COMMENTS = ("#", "//", "%", "!")
_UNITS = {"mm": 1.0, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "micron": 1e-3, "nm": 1e-6, "m": 1e3,
          "cm": 10.0, "in": 25.4, "inch": 25.4}
_AXIS_ALIASES = {"x": "x", "y": "y", "z": "z", "px": "x", "py": "y", "pz": "z", "pos_x": "x",
                 "pos_y": "y", "pos_z": "z", "x_pos": "x", "y_pos": "y", "z_pos": "z",
                 "xcoord": "x", "ycoord": "y", "zcoord": "z", "x_coord": "x", "y_coord": "y",
                 "z_coord": "z", "meas_x": "x", "meas_y": "y", "meas_z": "z"}


def _is_comment(line: str) -> bool:
    s = line.lstrip()
    return not s or s.startswith(COMMENTS)


def _split(line: str, delim: str | None) -> list[str]:
    parts = line.strip().split(delim) if delim else line.split()
    return [p.strip() for p in parts]


def _is_number(tok: str, decimal_comma: bool) -> bool:
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
    elif "," in line and not re.search(r"\d,\d+\s+-?\d", line):
        delim = ","
    else:
        delim = None
    decimal_comma = delim != "," and "," in line
    return delim, decimal_comma


def _header_name(tok: str) -> tuple[str, float | None, str | None]:
    """Normalised channel name, unit scale to mm (None if none), unit text."""
    t = tok.strip().strip('"').strip("'").strip()
    unit = None
    m = re.match(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$", t)
    if m:
        t, unit = m.group(1), m.group(2).strip()
    name = re.sub(r"[^0-9a-zA-Z_]+", "_", t.strip()).strip("_").lower()
    if name and name[0].isdigit():
        name = "c_" + name
    scale = _UNITS.get(unit.lower() if unit else "", None) if unit else None
    return name, scale, unit


def read_table(path: Path, required: tuple[str, ...]) -> dict[str, np.ndarray]:
    """A headed text table (e.g. a calibration series ``t, xd, ref``) as columns by name, with the
    same parsing and messages as point files; ``required`` names must be in the header."""
    _, cols, meta = read_text(Path(path), need_xyz=False)
    if meta.get("header_line") is None:
        raise InputError(f"{path}: needs a header line naming the columns ({', '.join(required)})")
    missing = [n for n in required if n not in cols]
    if missing:
        raise InputError(f"{path}, line {meta['header_line']}: no {'/'.join(missing)} column "
                         f"(columns: {', '.join(cols)})")
    return cols


def read_text(path: Path, need_xyz: bool = True) -> tuple[np.ndarray | None, dict, dict]:
    """Read a text export. Returns (xyz (N,3) float64 mm, channels, meta); with ``need_xyz=False``
    a header without x, y, z is allowed and every column comes back as a channel (xyz None)."""
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
        encoding = "utf-8-sig"
    except UnicodeDecodeError:
        text = raw.decode("latin-1")  # Windows exports with µ in the header
        encoding = "latin-1"
    # Only the head is split into lines to find the layout; the body goes to the C reader whole.
    head = text.split("\n", 200)[:200]
    lines = _LazyLines(text, head)

    # --- find the first data line, the header and the layout --------------------------------
    first_data = None
    candidates = []  # (line number, text) of non-numeric, non-comment lines before the data
    for i, line in enumerate(head):
        line = line.rstrip("\r")
        if _is_comment(line):
            continue
        delim, dc = _sniff_delimiter(line)
        toks = _split(line, delim)
        if all(_is_number(t, dc) for t in toks if t != "") and any(t != "" for t in toks):
            first_data = i
            break
        candidates.append(i)
        if len(candidates) > 50:
            break
    if first_data is None:
        if candidates:
            ln = candidates[0] + 1
            raise InputError(f"{path}: no numeric data rows found (first line {ln}: "
                             f"{lines[candidates[0]].strip()[:60]!r})")
        raise InputError(f"{path}: empty file — no data rows")
    delim, decimal_comma = _sniff_delimiter(lines[first_data])
    first_toks = _split(lines[first_data], delim)
    trailing_empty = bool(first_toks) and first_toks[-1] == ""
    ncols = len(first_toks) - (1 if trailing_empty else 0)

    header = None
    if candidates:
        hline = lines[candidates[-1]]
        htoks = _split(hline, delim)
        if htoks and htoks[-1] == "":
            htoks = htoks[:-1]
        numeric = [_is_number(t, decimal_comma) for t in htoks]
        if len(htoks) == ncols and sum(numeric) > len(htoks) / 2:
            # mostly numbers: a damaged data line, not a header
            j = numeric.index(False)
            raise InputError(f"{path}, line {candidates[-1] + 1}, column {j + 1}: {htoks[j][:40]!r} is "
                             "not a number")
        if len(htoks) == ncols:
            header = (candidates[-1], htoks)
        elif len(_split(hline, None)) == ncols and delim is None:
            header = (candidates[-1], _split(hline, None))

    # --- parse with numpy's C reader ----------------------------------------------------------
    # numpy's reader is ~2x slower with several comment markers, so pass only those present.
    present = [c for c in COMMENTS if c in text]
    comments = None if not present else present[0] if len(present) == 1 else present
    usecols = range(ncols) if trailing_empty else None
    data = None
    if len(raw) > _FAST_BYTES:
        data = _fast_parse(path, first_data, delim, decimal_comma, comments, ncols, trailing_empty,
                           encoding)
    try:
        if data is not None:
            pass
        elif decimal_comma or encoding != "utf-8-sig":
            body = "\n".join(text.split("\n")[first_data:])
            if decimal_comma:
                body = body.replace(",", ".")
            data = np.loadtxt(io.StringIO(body), delimiter=delim, comments=comments, ndmin=2,
                              dtype=np.float64, usecols=usecols)
        else:
            data = np.loadtxt(path, delimiter=delim, comments=comments, ndmin=2, dtype=np.float64,
                              usecols=usecols, skiprows=first_data, encoding="utf-8-sig")
    except ValueError:
        _diagnose(path, lines.all(), first_data, delim, decimal_comma, ncols, trailing_empty)
        raise InputError(f"{path}: could not parse the numeric data")  # pragma: no cover
    if data.shape[1] != ncols:  # pragma: no cover - loadtxt keeps the width
        raise InputError(f"{path}: expected {ncols} columns, got {data.shape[1]}")

    # --- names --------------------------------------------------------------------------------
    meta: dict = {"format": "text", "delimiter": delim or "whitespace", "decimal_comma": decimal_comma,
                  "header_line": header[0] + 1 if header else None}
    if header:
        names, scales, units = zip(*(_header_name(t) for t in header[1]))
        names = [_AXIS_ALIASES.get(n, n) for n in names]
        for j, n in enumerate(names):
            if not n:
                raise InputError(f"{path}, line {header[0] + 1}: column {j + 1} has no name")
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise InputError(f"{path}, line {header[0] + 1}: duplicate column name(s) {sorted(dup)}")
        missing = [a for a in "xyz" if a not in names]
        if not need_xyz:
            _check_finite(path, lines, first_data, data, names)
            return None, {n: data[:, j] for j, n in enumerate(names)}, meta
        if missing:
            raise InputError(f"{path}, line {header[0] + 1}: no {'/'.join(missing)} column in the header "
                             f"(columns: {', '.join(header[1])})")
    else:
        if ncols < 3:
            raise InputError(f"{path}, line {first_data + 1}: {ncols} column(s); need at least x, y, z")
        names = ["x", "y", "z"] + [f"col{j + 1}" for j in range(3, ncols)]
        scales, units = [None] * ncols, [None] * ncols

    cols = {n: data[:, j] for j, n in enumerate(names)}
    xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")])
    for a, j in (("x", names.index("x")), ("y", names.index("y")), ("z", names.index("z"))):
        if units[j] is not None:
            if scales[j] is None:
                raise InputError(f"{path}, line {header[0] + 1}: unknown unit [{units[j]}] for {a}; "
                                 f"known: {', '.join(sorted(_UNITS))}")
            xyz[:, "xyz".index(a)] *= scales[j]
    meta["channel_units"] = {n: u for n, u in zip(names, units) if u and n not in "xyz"}

    _check_finite(path, lines, first_data, data, names)
    if "index" in cols:
        idx = cols["index"]
        if np.any(idx != np.round(idx)) or np.any(idx < 0):
            raise InputError(f"{path}: the index column must hold non-negative integers")
        if len(np.unique(idx)) != len(idx):
            raise InputError(f"{path}: the index column has repeated values")
    return xyz, cols, meta


_FAST_BYTES = 4_000_000


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


def _check_finite(path, lines, first_data, data, names) -> None:
    """Values must be measurements: the first NaN/inf named by line and column."""
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        ln = _data_line_number(lines.all(), first_data, int(row))
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


def _data_line_number(lines, first_data, row) -> int:
    k = -1
    for i in range(first_data, len(lines)):
        if not _is_comment(lines[i]):
            k += 1
            if k == row:
                return i + 1
    return first_data + row + 1


def _diagnose(path, lines, first_data, delim, decimal_comma, ncols, trailing_empty):
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
        for j, t in enumerate(toks):
            if not _is_number(t, decimal_comma):
                raise InputError(f"{path}, line {i + 1}, column {j + 1}: {t[:40]!r} is not a number")
