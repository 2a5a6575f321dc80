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
for its values needs ``height_unit``.
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


def _head_lines(text_head: str, n: int = 60) -> list[str]:
    return text_head.splitlines()[:n]


def is_st_text_format(text_head: str) -> bool:
    """Text formats SurfaceTopography reads whole: ISO 25178-71 SDF (ASCII), Wyko ASCII."""
    first = text_head.lstrip("\ufeff")
    return any(r.match(first) for r in _ST_TEXT)


def has_matrix_header(text_head: str) -> bool:
    """A header naming a matrix's size and unit (two keys at least) before the first numbers."""
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
    return len(keys) >= 2


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


def read_matrix(path: Path, opts):
    """(xyz mm, channels, meta) of a text height matrix with a header."""
    from .instruments import _short, _topography_to_cloud, quiet

    ny, nx = _check_rows(path)
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
        try:
            reader = open_topography(io.StringIO(text), format="asc")
        except Exception as e:  # noqa: BLE001
            raise InputError(f"{path}: cannot read this height matrix ({_short(e)})") from None
        xyz, ch, meta = _topography_to_cloud(path, reader, opts, b"")
    grid = meta.get("grid")
    if grid and grid != [nx, ny]:  # pragma: no cover - the two parsers disagree on the layout
        raise InputError(f"{path}: the matrix has {ny} rows of {nx} values but the header describes "
                         f"{grid[1]} × {grid[0]}")
    name = (reader.channels[0].info.get("raw_metadata") or {}).get("channel_name")
    return xyz, ch, {**meta, "format": "matrix", "instrument_format": "text matrix",
                     **({"channel": name} if name else {})}
