"""PCD (Point Cloud Library) and PTS (Leica) point clouds, read with numpy.

open3d reads both, but without a word when the file is wrong: doubles in a binary PCD come back as
zeros, a truncated file or a header whose count is too large gives uninitialised memory, a bad number
in a PTS row turns that row and every later one to 0, a count too small drops points. Here every count,
size and number is checked, and a file that is not what it says is refused in one line naming the
file and the header entry or text line at fault.

PCD (https://pointclouds.org/documentation/tutorials/pcd_file_format.html): a text header —
FIELDS, SIZE, TYPE, COUNT (default 1 each), WIDTH, HEIGHT, POINTS (= WIDTH × HEIGHT), DATA — then the
points as text rows (``DATA ascii``), packed records (``binary``: little-endian, no padding) or LZF
compressed columns (``binary_compressed``). Types F 4/8, I and U 1/2/4/8. x, y, z are required; every
other field of COUNT 1 becomes a channel (float64, or int64 for I/U): ``normal_x/y/z`` as ``nx/ny/nz``,
a packed ``rgb``/``rgba`` as ``red``, ``green``, ``blue`` (and ``alpha``) 0–255 like PLY's; PCL's
padding fields ``_`` and fields of several values (a descriptor histogram) are left out. The file must
end with the points its header declares (trailing whitespace allowed after text rows; zero bytes after
compressed points — PCL's writer leaves them, 4096 bytes less the header's length in its test files,
e.g. 3913 in test/car6.pcd; any other byte there is refused as more data than declared).

PTS: line 1 the number of points, then that many rows ``x y z``, ``x y z intensity``,
``x y z r g b`` or ``x y z intensity r g b``; a file of several scans repeats count + rows (the
channel ``scan`` then says which). Colours are whole numbers, kept as int64.

Points with a NaN/inf coordinate (PCL's organised clouds mark missing pixels so) follow the reader
option ``invalid``: dropped and counted in ``meta["invalid_dropped"]`` (``index`` keeps the input
point) or refused naming the first.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..cloud import EXACT_WHOLE, INTEGER_CHANNELS
from ..errors import InputError
from .ply import line_at, load_rows, nth_line

_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS",
             "DATA")
_PCD_DATA = ("ascii", "binary", "binary_compressed")
_PCD_SIZES = {"F": (4, 8), "I": (1, 2, 4, 8), "U": (1, 2, 4, 8)}
_RENAME = {"normal_x": "nx", "normal_y": "ny", "normal_z": "nz"}
_MAX_HEADER = 1 << 20  # a PCD header is a few hundred bytes: past this, the file is no PCD


def looks_like_pcd(head: bytes) -> bool:
    """Whether the first bytes are a PCD header: comment lines, then VERSION or FIELDS, and FIELDS
    and DATA lines among the first 40."""
    keys = [s.split()[0] for s in (ln.strip() for ln in head.split(b"\n", 40)[:40])
            if s and not s.startswith(b"#")]
    return bool(keys) and keys[0] in (b"VERSION", b"FIELDS") and b"FIELDS" in keys and b"DATA" in keys


# --- PCD -----------------------------------------------------------------------------------------
def _pcd_header(f, path: Path) -> dict:
    """{key: (values, line number)} up to and including DATA; InputError naming the line at fault.
    A file whose first entry is no PCD key is "no points read — not a PCD file"."""
    keys: dict = {}
    ln = 0
    while "DATA" not in keys:
        line = f.readline(_MAX_HEADER)
        ln += 1
        if not line or f.tell() >= _MAX_HEADER:
            if not keys:
                raise InputError(f"{path}: no points read — not a PCD file (no FIELDS … DATA header)")
            raise InputError(f"{path}: PCD header has no DATA line")
        if not line.strip() or line.lstrip().startswith(b"#"):
            continue
        try:
            parts = line.decode("ascii").split()
        except UnicodeDecodeError:
            parts = [""]
        if parts[0] not in _PCD_KEYS:
            if not keys:
                raise InputError(f"{path}: no points read — not a PCD file (line {ln} is no PCD "
                                 "header entry: VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, "
                                 "VIEWPOINT, POINTS, DATA)")
            raise InputError(f"{path}: PCD header line {ln}: {_first(line)} is no PCD header entry")
        if parts[0] in keys:
            raise InputError(f"{path}: PCD header line {ln}: {parts[0]} given twice")
        keys[parts[0]] = (parts[1:], ln)
    return keys


def _first(line: bytes) -> str:
    s = line.strip().decode("utf-8", "replace")
    return repr(s if len(s) <= 40 else s[:37] + "...")


def _ints(path: Path, keys: dict, key: str, n: int | None = None, low: int = 0) -> list[int] | None:
    if key not in keys:
        return None
    vals, ln = keys[key]
    if not vals or (n is not None and len(vals) != n) or not all(v.isdigit() for v in vals) \
            or any(int(v) < low for v in vals):
        what = f"{n} whole numbers" if n and n > 1 else "a whole number"
        raise InputError(f"{path}: PCD header line {ln}: {key} needs {what}"
                         + (f" ≥ {low}" if low else "") + f" (got {' '.join(vals) or 'nothing'})")
    return [int(v) for v in vals]


def _pcd_layout(path: Path, keys: dict) -> tuple[list, int, str]:
    """([(name, type char, size, count)], points, data kind) from a checked header."""
    for k in ("FIELDS", "SIZE", "TYPE"):
        if k not in keys:
            raise InputError(f"{path}: PCD header has no {k} line")
    names, ln = keys["FIELDS"]
    if not names:
        raise InputError(f"{path}: PCD header line {ln}: FIELDS names no field")
    nf = len(names)
    sizes = _ints(path, keys, "SIZE", nf, 1)
    counts = _ints(path, keys, "COUNT", nf, 1) or [1] * nf
    types, tln = keys["TYPE"]
    if len(types) != nf or any(t not in _PCD_SIZES for t in types):
        raise InputError(f"{path}: PCD header line {tln}: TYPE needs one of F, I, U for each of the "
                         f"{nf} fields (got {' '.join(types) or 'nothing'})")
    for name, t, s in zip(names, types, sizes):
        if s not in _PCD_SIZES[t]:
            raise InputError(f"{path}: PCD header line {keys['SIZE'][1]}: field '{name}' of TYPE {t} "
                             f"cannot have SIZE {s} (F: 4, 8; I, U: 1, 2, 4, 8)")
    seen = [n for n in names if n != "_"]
    dup = sorted({n for n in seen if seen.count(n) > 1})
    if dup:
        raise InputError(f"{path}: PCD header line {ln}: field '{dup[0]}' is named twice")
    fields = list(zip(names, types, sizes, counts))
    for a in "xyz":
        if a not in names:
            raise InputError(f"{path}: PCD header line {ln}: no '{a}' field (FIELDS {' '.join(names)})")
        if counts[names.index(a)] != 1:
            raise InputError(f"{path}: PCD header: field '{a}' has COUNT {counts[names.index(a)]}, "
                             "not 1")
    width = _ints(path, keys, "WIDTH", 1)
    height = _ints(path, keys, "HEIGHT", 1)
    points = _ints(path, keys, "POINTS", 1)
    if points is None and width is None:
        raise InputError(f"{path}: PCD header has neither POINTS nor WIDTH: the number of points is "
                         "unknown")
    n = points[0] if points is not None else width[0] * (height[0] if height else 1)
    if points is not None and width is not None and width[0] * (height[0] if height else 1) != n:
        raise InputError(f"{path}: PCD header line {keys['POINTS'][1]}: POINTS {n} is not WIDTH × "
                         f"HEIGHT = {width[0]} × {height[0] if height else 1}")
    data, dln = keys["DATA"]
    if len(data) != 1 or data[0] not in _PCD_DATA:
        raise InputError(f"{path}: PCD header line {dln}: DATA is one of {', '.join(_PCD_DATA)} "
                         f"(got {' '.join(data) or 'nothing'})")
    return fields, n, data[0]


def _dtype(fields) -> np.dtype:
    return np.dtype([(f"f{j}", f"<{t.lower()}{s}", (c,)) if c > 1 else (f"f{j}", f"<{t.lower()}{s}")
                     for j, (_, t, s, c) in enumerate(fields)])


def read_pcd(path: Path, invalid: str = "drop"):
    """(xyz (N, 3) float64, channels, meta) of a PCD file (module doc)."""
    path = Path(path)
    from .memory import check_fits

    with open(path, "rb") as f:
        keys = _pcd_header(f, path)
        fields, n, kind = _pcd_layout(path, keys)
        if n == 0:
            raise InputError(f"{path}: empty file — the PCD header declares 0 points")
        dt = _dtype(fields)
        start = f.tell()
        left = path.stat().st_size - start
        check_fits(path, n, where="PCD header (POINTS)",
                   file_short=kind == "binary" and left < n * dt.itemsize)
        if kind == "ascii":
            columns = _pcd_ascii(f, path, fields, n, start)
        elif kind == "binary":
            columns = _pcd_binary(f, path, fields, dt, n, left)
        else:
            columns = _pcd_compressed(f, path, fields, dt, n, left)
    xyz = np.empty((n, 3), dtype=np.float64)
    names = [name for name, *_ in fields]
    with np.errstate(invalid="ignore"):  # a signalling NaN float32 (garbage): the NaN check names it
        for j, a in enumerate("xyz"):
            xyz[:, j] = columns[names.index(a)].reshape(n)
        cols = _pcd_channels(path, fields, columns, kind)
    xyz, cols, dropped = _drop_invalid(path, xyz, cols, invalid, "point")
    meta = {"format": "pcd", "pcd_data": kind, "invalid_dropped": dropped}
    return xyz, cols, _with_grid(xyz, meta)


def _pcd_ascii(f, path: Path, fields, n: int, start: int) -> list:
    widths = [c for *_, c in fields]
    data = load_rows(f, path, n, sum(widths), ("point", "points"), "the header declares",
                     " ".join(name for name, *_ in fields))
    rest = f.read()
    if rest.strip():
        ln, text = nth_line(f, f.tell() - len(rest))
        raise InputError(f"{path}: the PCD header declares {n} points but the file holds more data "
                         f"({ln}: {text})")
    out, j = [], 0
    for (name, t, s, c) in fields:
        v = data[:, j:j + c]
        j += c
        if t == "F" and name in INTEGER_CHANNELS and np.any(np.abs(v) >= EXACT_WHOLE):
            # parsed as float64: exact as a whole number only below 2⁵³ (a review: 9007199254740993 and
            # …992 read as two equal indices); TYPE I / U SIZE 8 are read exactly (_exact_integers)
            row = int(np.argwhere(np.abs(v) >= EXACT_WHOLE)[0, 0])
            raise InputError(f"{path}, line {line_at(f, start) + row}: field '{name}' is TYPE F but point {row} "
                             f"holds {float(v[row].max())!r}, not a whole number below 2⁵³ = 9007199254740992 "
                             "(exact in a float64 only below it): write it as TYPE I or U SIZE 8")
        if t != "F":
            info = np.iinfo(f"{t.lower()}{s}")
            bad = ~((v == np.floor(v)) & (v >= info.min) & (v <= info.max))
            if bad.any():
                row = int(np.argwhere(bad)[0, 0])
                raise InputError(f"{path}, line {line_at(f, start) + row}: field '{name}' is TYPE {t} "
                                 f"SIZE {s} but point {row} holds {float(v[bad][0])!r}")
            if s == 8:  # beyond 2^53 the text was rounded by float64: read it as written
                try:
                    v = _exact_integers(f, start, n, j - c, c, t)
                except OverflowError:
                    raise InputError(f"{path}: field '{name}' holds a number beyond TYPE {t} SIZE 8"
                                     ) from None
        out.append(v)
    return out


def _exact_integers(f, start: int, n: int, col: int, c: int, t: str) -> np.ndarray:
    """64-bit integer columns of an ASCII PCD, parsed as integers (float64 rounds beyond 2^53)."""
    def whole(tok: bytes) -> int:
        try:
            return int(tok)
        except ValueError:  # 1e3, 12.0: whole (checked) but not written as integers
            return int(float(tok))

    f.seek(start)
    rows = [ln.split() for ln in f.read().splitlines() if ln.strip() and not ln.lstrip().startswith(b"#")]
    return np.array([[whole(r[col + k]) for k in range(c)] for r in rows[:n]],
                    dtype=np.uint64 if t == "U" else np.int64)


def _pcd_binary(f, path: Path, fields, dt: np.dtype, n: int, left: int) -> list:
    need = n * dt.itemsize
    if left < need:
        raise InputError(f"{path}: PCD file is truncated ({max(left, 0)} of the {need} bytes of its "
                         f"{n} points)")
    if left > need:
        extra = left - need
        raise InputError(f"{path}: the PCD header declares {n} points but the file holds more data "
                         f"({extra} bytes after them, {extra / dt.itemsize:.4g} more points' worth)")
    if [(name, t, s, c) for name, t, s, c in fields] == [("x", "F", 8, 1), ("y", "F", 8, 1),
                                                        ("z", "F", 8, 1)]:
        xyz = np.empty((n, 3), dtype=np.float64)  # straight into the coordinates (little-endian)
        _read_exact(f, path, xyz, need)
        return [xyz[:, 0], xyz[:, 1], xyz[:, 2]]
    arr = np.empty(n, dtype=dt)
    _read_exact(f, path, arr, need)
    return [arr[f"f{j}"] for j in range(len(fields))]


def _read_exact(f, path: Path, out: np.ndarray, need: int) -> None:
    view = out.reshape(-1).view(np.uint8)
    got = 0
    while got < need:
        k = f.readinto(view[got:])
        if not k:
            raise InputError(f"{path}: PCD file is truncated ({got} of {need} bytes)")
        got += k


def _pcd_compressed(f, path: Path, fields, dt: np.dtype, n: int, left: int) -> list:
    """DATA binary_compressed: two uint32 (compressed, uncompressed size), then LZF of the fields
    one after another (all the points' x, then all their y …)."""
    head = f.read(8)
    if len(head) < 8:
        raise InputError(f"{path}: PCD file is truncated (no compressed-data sizes after DATA)")
    csize, usize = struct.unpack("<II", head)
    need = n * dt.itemsize
    if usize != need:
        raise InputError(f"{path}: PCD compressed data unpack to {usize} bytes, but the header's "
                         f"{n} points of {dt.itemsize} bytes are {need}")
    if left - 8 < csize:
        raise InputError(f"{path}: PCD file is truncated ({max(left - 8, 0)} of the {csize} bytes of "
                         "compressed data)")
    raw = lzf_decompress(f.read(csize), usize)
    if left - 8 > csize and not _zeros_to_end(f):  # PCL pads its files with zeros (module doc)
        raise InputError(f"{path}: the PCD header declares {n} points but the file holds more data "
                         f"({left - 8 - csize} bytes after the compressed points, not all zero)")
    if raw is None:
        raise InputError(f"{path}: the PCD's compressed point data are damaged (LZF does not unpack "
                         f"to the {usize} bytes stated)")
    out, off = [], 0
    for (_, t, s, c) in fields:
        a = np.frombuffer(raw, dtype=f"<{t.lower()}{s}", count=n * c, offset=off)
        out.append(a.reshape(n, c) if c > 1 else a)
        off += n * s * c
    return out


def _zeros_to_end(f) -> bool:
    """Whether every byte from here to the end of the file is zero (read in 1 MiB pieces)."""
    while chunk := f.read(1 << 20):
        if chunk.count(0) != len(chunk):
            return False
    return True


def lzf_decompress(src: bytes, size: int) -> bytearray | None:
    """LZF (liblzf, as PCL compresses) unpacked to exactly ``size`` bytes; None when ``src`` is not
    such a stream. Runs of literals are copied by slices: ~1 s for 10⁶ points of float noise."""
    out = bytearray(size)
    ip, op, end = 0, 0, len(src)
    while ip < end:
        ctrl = src[ip]
        ip += 1
        if ctrl < 32:  # ctrl + 1 literal bytes
            k = ctrl + 1
            if ip + k > end or op + k > size:
                return None
            out[op:op + k] = src[ip:ip + k]
            ip += k
            op += k
            continue
        k = ctrl >> 5  # a back reference: length, distance
        if k == 7:
            if ip >= end:
                return None
            k += src[ip]
            ip += 1
        k += 2
        if ip >= end:
            return None
        ref = op - ((ctrl & 0x1F) << 8) - src[ip] - 1
        ip += 1
        if ref < 0 or op + k > size:
            return None
        if ref + k <= op:
            out[op:op + k] = out[ref:ref + k]
        else:  # overlapping: the last op - ref bytes repeated
            d = op - ref
            out[op:op + k] = (bytes(out[ref:op]) * (k // d + 1))[:k]
        op += k
    return out if op == size else None


def _pcd_channels(path: Path, fields, columns: list, kind: str) -> dict:
    """The channels of the fields other than x, y, z (module doc)."""
    cols: dict = {}

    def add(name, v):
        if name in cols:
            raise InputError(f"{path}: PCD field '{name}' is given twice (as {name} and as a packed "
                             "colour)")
        cols[name] = v

    for (name, t, s, c), v in zip(fields, columns):
        if name in ("x", "y", "z", "_") or c != 1:
            continue
        v = v.reshape(-1)
        if name in ("rgb", "rgba") and s == 4:  # 0xAARRGGBB, stored in a float (PCL) or not
            if kind != "ascii":
                bits = v.view(np.uint32)
            elif t == "F" and not np.all((v == np.floor(v)) & (v >= 0) & (v < 2**32)):
                bits = v.astype(np.float32).view(np.uint32)  # the float's bits printed as a float
            else:  # PCL prints the packed colour as an integer, whatever its TYPE
                bits = v.astype(np.int64).astype(np.uint32)
            bits = bits.astype(np.int64)
            add("red", (bits >> 16) & 255)
            add("green", (bits >> 8) & 255)
            add("blue", bits & 255)
            if name == "rgba":
                add("alpha", (bits >> 24) & 255)
            continue
        if t == "F":
            add(_RENAME.get(name, name), v.astype(np.float64))
        else:
            if v.dtype == np.uint64 and v.size and v.max() >= 2**63:
                raise InputError(f"{path}: PCD field '{name}' holds {int(v.max())}, beyond the "
                                 "int64 range of a channel")
            add(_RENAME.get(name, name), v.astype(np.int64))
    return cols


# --- PTS -----------------------------------------------------------------------------------------
_PTS_COLUMNS = {3: (), 4: ("intensity",), 6: ("red", "green", "blue"),
                7: ("intensity", "red", "green", "blue")}


def read_pts(path: Path, invalid: str = "drop"):
    """(xyz (N, 3) float64, channels, meta) of a PTS file (module doc)."""
    path = Path(path)
    from .memory import check_fits

    blocks = []  # (rows, the byte where their count line starts)
    ncols = None
    with open(path, "rb") as f:
        while True:
            line, pos = _next_line(f)
            if line is None:
                break
            if not blocks and line.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte-order mark
                line = line[3:]
            toks = line.split()
            if len(toks) != 1 or not toks[0].isdigit():
                if not blocks:
                    raise InputError(f"{path}, line {line_at(f, pos)}: a PTS file starts with its "
                                     f"number of points (got {_first(line)})")
                b = blocks[-1]
                raise InputError(f"{path}: line {line_at(f, b[1])} declares {len(b[0])} points but "
                                 f"the file holds more rows (line {line_at(f, pos)}: {_first(line)})")
            count = int(toks[0])
            check_fits(path, count + sum(len(b[0]) for b in blocks), where="PTS count line")
            if count == 0:
                blocks.append((np.empty((0, ncols or 3)), pos))
                continue
            if ncols is None:
                first, fpos = _next_line(f)
                if first is None:
                    raise InputError(f"{path}: the file is truncated: line {line_at(f, pos)} declares "
                                     f"{count} points, the file holds 0")
                ncols = len(first.split())
                if ncols not in _PTS_COLUMNS:
                    raise InputError(f"{path}, line {line_at(f, fpos)}: a PTS row is x y z, "
                                     "x y z intensity, x y z r g b or x y z intensity r g b — this "
                                     f"one has {ncols} values")
                f.seek(fpos)
            what = " ".join(("x", "y", "z", *_PTS_COLUMNS[ncols]))
            data = load_rows(f, path, count, ncols, ("point", "points"),
                             lambda pos=pos: f"line {line_at(f, pos)} declares", what)
            blocks.append((data, pos))
    if not blocks or not sum(len(b[0]) for b in blocks):
        raise InputError(f"{path}: empty file — no points" + (" (its count is 0)" if blocks else ""))
    data = np.concatenate([b[0] for b in blocks]) if len(blocks) > 1 else blocks[0][0]
    xyz = np.ascontiguousarray(data[:, :3])
    cols = {}
    for j, name in enumerate(_PTS_COLUMNS[ncols], start=3):
        v = data[:, j]
        if name != "intensity":
            bad = ~(v == np.floor(v))
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                raise InputError(f"{path}: point {row}: the colour {name} is {float(v[row])!r}, not a "
                                 "whole number")
            v = v.astype(np.int64)
        cols[name] = v
    if len(blocks) > 1:
        cols["scan"] = np.repeat(np.arange(len(blocks)), [len(b[0]) for b in blocks])
    xyz, cols, dropped = _drop_invalid(path, xyz, cols, invalid, "point")
    meta = {"format": "pts", "invalid_dropped": dropped}
    if len(blocks) > 1:
        meta["pts_scans"] = len(blocks)
    return xyz, cols, _with_grid(xyz, meta)


def _next_line(f) -> tuple[bytes | None, int]:
    """(the next non-blank line, the byte it starts at); (None, end) at the end of the file."""
    while True:
        pos = f.tell()
        line = f.readline()
        if not line:
            return None, pos
        if line.strip():
            return line, pos


# --- shared --------------------------------------------------------------------------------------
def _drop_invalid(path: Path, xyz: np.ndarray, cols: dict, invalid: str, what: str):
    """Points with a NaN/inf coordinate dropped (``invalid: drop``; ``index`` keeps the input
    point) or the first refused by number (``invalid: error``)."""
    keep = np.isfinite(xyz).all(axis=1)
    if keep.all():
        return xyz, cols, 0
    first = int(np.flatnonzero(~keep)[0])
    if invalid != "drop":
        raise InputError(f"{path}: {what} {first} has a NaN/inf coordinate")
    if not keep.any():
        raise InputError(f"{path}: every {what} has a NaN/inf coordinate — nothing left to read")
    cols = {k: v[keep] for k, v in cols.items()}
    cols.setdefault("index", np.flatnonzero(keep).astype(np.int64))
    return xyz[keep], cols, int((~keep).sum())


def _with_grid(xyz: np.ndarray, meta: dict) -> dict:
    from .gridcloud import detect_grid

    grid = detect_grid(xyz[:, 0], xyz[:, 1])
    if grid is not None:
        meta.update(grid)
    return meta
