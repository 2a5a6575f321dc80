"""PLY point clouds with every channel kept (binary little-endian on write).

open3d reads PLY too, but only positions, normals and colours, converts through its own types, and
returns garbage for a file it cannot read to the end (a truncated list property, a colour channel
the file lacks); a cloud written by PointsPro must come back with its `index`, `residual`, ω... So
every PLY is parsed here with numpy: the vertex element's fixed-size properties become the cloud
(list properties are skipped), the other elements are walked only to check that the file holds
exactly what its header declares — no more (a header whose `element vertex` is smaller than the
data would silently drop points), no less (truncated).

Binary x, y, z float64 alone (what PointsPro writes without channels) is read straight into the
(N, 3) coordinate array; other binary layouts through one structured array; elements with list
properties through a strided view when every list has the same length (triangles), item by item
otherwise. ASCII: one element item per line (every writer's convention), the vertices by
np.loadtxt, and a bad line named by number.

Writing: binary little-endian; x, y, z and float channels as double; an integer channel as `int`
when int32 holds it, `uint` when uint32 does, else as `double` (|v| ≤ 2^53, exact) with a header
comment ``comment pointspro int64 <name>`` that makes the reader return it as int64 again; beyond
2^53 the channel is refused by name (PLY has no 64-bit integer type).
"""
from __future__ import annotations

import mmap
import re
import struct
import warnings
from pathlib import Path

import numpy as np

from ..cloud import EXACT_WHOLE, INTEGER_CHANNELS
from ..errors import InputError

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
#: header comment naming integer channels written as double (beyond uint32): read back as int64
_INT64_COMMENT = "pointspro int64"
_EXACT = EXACT_WHOLE  # every integer of magnitude up to this is exact in a float64 (core/cloud.py)


def _is_list(t) -> bool:
    return isinstance(t, tuple)


def read_ply(path: Path):
    """(xyz (N, 3) float64, channels, meta) of a PLY file; InputError naming what is wrong."""
    path = Path(path)
    with open(path, "rb") as f:
        fmt, elements, header_lines, int64_names = _read_header(f, path)
        vi = next((i for i, e in enumerate(elements) if e[0] == "vertex"), None)
        if vi is None:
            raise InputError(f"{path}: the PLY has no vertex element")
        _, n, props = elements[vi]
        if n == 0:
            raise InputError(f"{path}: empty file — the PLY has no vertices")
        names = [p for p, _ in props]
        for a in "xyz":
            if a not in names:
                raise InputError(f"{path}: PLY vertices have no '{a}' property")
            if _is_list(dict(props)[a]):
                raise InputError(f"{path}: PLY vertex property '{a}' is a list, not a number")
        dup = sorted({p for p in names if names.count(p) > 1})
        if dup:
            raise InputError(f"{path}: PLY vertex property {dup[0]!r} is declared twice")
        _check_memory(f, path, fmt, n, props)
        if fmt == "ascii":
            xyz, cols = _read_ascii(f, path, elements, vi, header_lines)
        else:
            xyz, cols = _read_binary(f, path, fmt, elements, vi)
    if not np.isfinite(xyz).all():
        row = int(np.argwhere(~np.isfinite(xyz))[0, 0])
        raise InputError(f"{path}: vertex {row} has a NaN/inf coordinate")
    for name in int64_names & cols.keys():  # written by PointsPro as double: int64 again
        v = cols[name]
        if v.dtype.kind == "f" and np.all(np.abs(v) <= _EXACT) and np.all(v == np.floor(v)):
            cols[name] = v.astype(np.int64)
    meta = {"format": "ply"}
    # an interferometer's map exported as x, y, z: its pixel grid is recorded (core.io.gridcloud),
    # so that the processed cloud can be written as a map again (cloud.x3p)
    from .gridcloud import detect_grid

    grid = detect_grid(xyz[:, 0], xyz[:, 1])
    if grid is not None:
        meta.update(grid)
    return xyz, cols, meta


def _read_header(f, path: Path) -> tuple[str, list, int, set]:
    """(format, [(element, count, [(property, dtype code or ("list", count code, item code))])],
    the number of header lines, the channels a ``comment pointspro int64`` names); InputError naming
    the header line at fault."""
    if f.readline().strip() != b"ply":
        raise InputError(f"{path}: not a PLY file (no 'ply' magic line)")
    fmt = None
    elements: list = []
    int64_names: set = set()
    ln = 1

    def bad(what: str):
        raise InputError(f"{path}: PLY header line {ln}: {what}")

    types = ", ".join(sorted(set(_PLY_TYPES)))
    while True:
        line = f.readline()
        ln += 1
        if not line:
            raise InputError(f"{path}: PLY header has no end_header")
        parts = line.decode("ascii", "replace").split()
        if not parts:
            continue
        if parts[0] == "format":
            if len(parts) < 2 or parts[1] not in _PLY_FORMATS:
                bad(f"the format is not one of {', '.join(_PLY_FORMATS)}")
            fmt = parts[1]
        elif parts[0] == "element":
            if len(parts) < 3 or not parts[2].isdigit():
                bad("an element needs a name and a count (element vertex 1234)")
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property":
            if not elements:
                bad("a property before any element")
            if len(parts) > 1 and parts[1] == "list":
                if (len(parts) < 5 or parts[2] not in _PLY_TYPES or parts[3] not in _PLY_TYPES
                        or _PLY_TYPES[parts[2]][0] == "f"):
                    bad(f"a list property needs an integer count type, an item type ({types}) and a "
                        "name (property list uchar int vertex_indices)")
                elements[-1][2].append((parts[4], ("list", _PLY_TYPES[parts[2]], _PLY_TYPES[parts[3]])))
            elif len(parts) < 3 or parts[1] not in _PLY_TYPES:
                bad(f"a property needs a type ({types}) and a name")
            else:
                elements[-1][2].append((parts[2], _PLY_TYPES[parts[1]]))
        elif parts[0] == "comment" and " ".join(parts[1:3]) == _INT64_COMMENT:
            int64_names.update(parts[3:])
        elif parts[0] == "end_header":
            break
    if fmt is None:
        raise InputError(f"{path}: PLY header has no format line")
    return fmt, elements, ln, int64_names


def _fixed_size(props) -> int:
    """Bytes of an item's fixed-size properties (a list counted as its length field alone)."""
    return sum(np.dtype(t[1] if _is_list(t) else t).itemsize for _, t in props)


def _check_memory(f, path: Path, fmt: str, n: int, props) -> None:
    """Refuse, from the header alone, a cloud too large for the memory available (core.io.memory):
    nothing of the vertex data is read."""
    from .memory import check_fits

    left = path.stat().st_size - f.tell()
    # binary: the items' fixed sizes; text: at least one digit and one separator a value (a review: a
    # header of 10¹² vertices over 8 bytes was advised to decimate, not told the file is short)
    short = left < (_fixed_size(props) if fmt != "ascii" else 2 * len(props)) * n
    check_fits(path, n, where="PLY header (element vertex)", file_short=short)


def _columns(fields: dict, props) -> tuple[np.ndarray, dict]:
    """(xyz float64, the other channels as float64 or int64) from the vertex properties' arrays."""
    n = len(fields["x"])
    xyz = np.empty((n, 3), dtype=np.float64)
    with np.errstate(invalid="ignore"):  # a signalling NaN float32 (garbage): the NaN check names it
        for j, a in enumerate("xyz"):
            xyz[:, j] = fields[a]
        cols = {p: fields[p].astype(np.float64 if fields[p].dtype.kind == "f" else np.int64)
                for p, t in props if p not in ("x", "y", "z") and not _is_list(t)}
    return xyz, cols


def _more_data(path: Path, n: int, extra: str) -> InputError:
    return InputError(f"{path}: the PLY header declares {n} vertices but the file holds more data "
                      f"({extra}) — the header's counts are wrong or two files were joined")


# --- binary --------------------------------------------------------------------------------------
def _read_binary(f, path: Path, fmt: str, elements, vi: int) -> tuple[np.ndarray, dict]:
    """(xyz, the other channels): the vertex data read straight from the file into numpy arrays.

    x, y, z as three float64 properties in that order and nothing else (the usual map, and what
    PointsPro writes) are read into the (n, 3) coordinate array itself: one copy of the bytes, from
    the file to where they stay (byte-swapped in place from big-endian). Other layouts are read into
    one structured array, whose columns are then copied out once each (x, y, z into the coordinate
    array, every other property to float64 or int64). A vertex element after others, or with list
    properties, is read through a memory map of the file; every element after it is walked to check
    that the file ends where the header says."""
    order = "<" if fmt == "binary_little_endian" else ">"
    _, n, props = elements[vi]
    size = path.stat().st_size
    start = f.tell()
    if vi == 0 and not any(_is_list(t) for _, t in props):
        dt = np.dtype([(p, order + t) for p, t in props])
        need = dt.itemsize * n
        left = size - start
        if left < need:  # before reading: a damaged count must not allocate terabytes
            raise InputError(f"{path}: PLY file is truncated ({max(left, 0)} of {need} bytes)")
        if len(elements) == 1 and left > need:  # before reading: no cloud with points left out
            extra = left - need
            raise _more_data(path, n, f"{extra} bytes after the vertices, "
                                      f"{extra / dt.itemsize:.4g} more vertices' worth")
        if props == [("x", "f8"), ("y", "f8"), ("z", "f8")]:
            xyz = np.empty((n, 3), dtype=np.float64)
            _read_into(f, path, xyz, need)
            if np.dtype(order + "f8") != np.dtype(np.float64):  # not the machine's byte order
                xyz.byteswap(inplace=True)
            cols: dict = {}
        else:
            arr = np.empty(n, dtype=dt)
            _read_into(f, path, arr, need)
            xyz, cols = _columns({p: arr[p] for p, _ in props}, props)
        if len(elements) > 1:
            _walk(f, path, order, elements, vi, 1, start + need, size)
        return xyz, cols
    return _walk(f, path, order, elements, vi, 0, start, size)


def _walk(f, path: Path, order: str, elements, vi: int, first: int, pos: int, size: int):
    """Walk ``elements[first:]`` from byte ``pos`` to the end of the file through a memory map; the
    vertices' (xyz, channels) when they are among them. InputError when an element runs past the
    end, or bytes are left after the last."""
    mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    try:
        out = None
        for i in range(first, len(elements)):
            name, count, props = elements[i]
            fields, pos = _binary_element(mm, path, order, name, count, props, pos, size,
                                          keep=i == vi, nverts=elements[vi][1])
            if i == vi:
                out = _columns(fields, props)
                del fields
        if pos != size:
            raise _more_data(path, elements[vi][1], f"{size - pos} bytes after the last declared "
                                                    f"element, '{elements[-1][0]}'")
        return out
    finally:
        try:
            mm.close()
        except BufferError:  # a view still alive (an exception's frame): closed when it goes
            pass


def _short(path: Path, name: str, item: int, count: int) -> InputError:
    return InputError(f"{path}: PLY file is truncated or its header is wrong: element '{name}' "
                      f"{item} of {count} runs past the end of the file")


def _binary_element(mm, path: Path, order: str, name: str, n: int, props, pos: int, size: int,
                    keep: bool = False, nverts: int = 0) -> tuple[dict | None, int]:
    """({property: array} when ``keep``, the byte after the element) of the element of ``n`` items
    at byte ``pos``: a fixed-size layout by its size; lists of one length each (triangles) through
    a strided view whose length fields are all checked; lists of varying lengths item by item.

    A face's vertex_indices (or vertex_index) must be 3 or more indices below ``nverts``: a vertex
    count that is wrong in the header shifts the faces, which then show it."""
    if n == 0:
        return ({p: np.empty(0) for p, t in props if not _is_list(t)} if keep else None), pos
    lists = [j for j, (_, t) in enumerate(props) if _is_list(t)]
    if not lists:
        dt = np.dtype([(f"p{j}", order + t) for j, (_, t) in enumerate(props)])
        end = pos + dt.itemsize * n
        if end > size:
            raise _short(path, name, (size - pos) // dt.itemsize, n)
        if not keep:
            return None, end
        arr = np.frombuffer(mm, dt, n, pos)
        return {p: arr[f"p{j}"].copy() for j, (p, _) in enumerate(props)}, end
    if pos + _fixed_size(props) * n > size:  # every item at least its fixed part: cheap refusal
        raise _short(path, name, (size - pos) // max(_fixed_size(props), 1), n)
    # the lengths of the first item's lists: is every item alike?
    lengths, p = {}, pos
    for j, (_, t) in enumerate(props):
        if _is_list(t):
            k = _count(mm, order, t[1], p, size, path, name, 0, n)
            lengths[j] = k
            p += np.dtype(t[1]).itemsize + k * np.dtype(t[2]).itemsize
        else:
            p += np.dtype(t).itemsize
    fields = []
    for j, (_, t) in enumerate(props):
        if _is_list(t):
            fields.append((f"c{j}", order + t[1]))
            if lengths[j]:
                fields.append((f"v{j}", order + t[2], (lengths[j],)))
        else:
            fields.append((f"p{j}", order + t))
    dt = np.dtype(fields)
    end = pos + dt.itemsize * n
    if end <= size:
        arr = np.frombuffer(mm, dt, n, pos)
        if all(np.all(arr[f"c{j}"] == k) for j, k in lengths.items()):
            for j, k in lengths.items():
                if name == "face" and props[j][0] in _FACE_LISTS:
                    _check_face(path, nverts, k, arr[f"v{j}"] if k else None)
            if not keep:
                return None, end
            return {p: arr[f"p{j}"].copy() for j, (p, t) in enumerate(props) if not _is_list(t)}, end
        del arr
    return _varying_items(mm, path, order, name, n, props, pos, size, keep)


_FACE_LISTS = ("vertex_indices", "vertex_index")


def _check_face(path: Path, nverts: int, k: int, idx: np.ndarray | None, item: int = 0) -> None:
    if k < 3:
        raise InputError(f"{path}: PLY face {item} lists {k} vertex indices (a face has 3 or more) — "
                         "the file does not match its header's counts")
    if idx is not None and idx.size and (idx.min() < 0 or idx.max() >= nverts):
        bad = int(np.argwhere((idx < 0) | (idx >= nverts))[0, 0])
        v = idx.reshape(len(idx), -1)[bad]
        raise InputError(f"{path}: PLY face {bad} refers to vertex {int(v[(v < 0) | (v >= nverts)][0])}, "
                         f"but the header declares {nverts} vertices — the file does not match its "
                         "header's counts")


def _count(mm, order: str, code: str, p: int, size: int, path: Path, name: str, item: int,
           n: int) -> int:
    k = np.dtype(code).itemsize
    if p + k > size:
        raise _short(path, name, item, n)
    v = struct.unpack_from(order + {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i",
                                    "u4": "I"}[code], mm, p)[0]
    if v < 0:
        raise InputError(f"{path}: PLY element '{name}' {item} has a list of negative length ({v})")
    return v


def _varying_items(mm, path: Path, order: str, name: str, n: int, props, pos: int, size: int,
                   keep: bool) -> tuple[dict | None, int]:
    """An element whose lists differ in length from item to item, walked one item at a time (the
    fixed-size properties then gathered from the recorded offsets)."""
    # the item as segments: fixed bytes, then a list (count code, item size) or None at the end
    segs: list = []
    fixed = 0
    where: dict = {}  # fixed property → (segment, offset in it)
    for j, (p, t) in enumerate(props):
        if _is_list(t):
            segs.append((fixed, t[1], np.dtype(t[2]).itemsize, name == "face" and p in _FACE_LISTS))
            fixed = 0
        else:
            where[p] = (len(segs), fixed)
            fixed += np.dtype(t).itemsize
    segs.append((fixed, None, 0, False))
    segs = [(fx, code, np.dtype(code).itemsize if code else 0, isize, face)
            for fx, code, isize, face in segs]
    starts = np.empty((n, len(segs)), dtype=np.int64) if keep else None
    p = pos
    for i in range(n):
        for s, (fx, code, csize, isize, face) in enumerate(segs):
            if keep:
                starts[i, s] = p
            p += fx
            if code is not None:
                k = _count(mm, order, code, p, size, path, name, i, n)
                if face and k < 3:
                    _check_face(path, 0, k, None, i)
                p += csize + k * isize
        if p > size:
            raise _short(path, name, i, n)
    if not keep:
        return None, p
    buf = np.frombuffer(mm, np.uint8)
    out = {}
    for prop, t in props:
        if _is_list(t):
            continue
        s, off = where[prop]
        width = np.dtype(t).itemsize
        idx = starts[:, s, None] + off + np.arange(width)
        out[prop] = np.ascontiguousarray(buf[idx]).view(order + t).reshape(n).copy()
    del buf
    return out, p


def _read_into(f, path: Path, out: np.ndarray, need: int) -> None:
    """Fill ``out`` (C-contiguous, ``need`` bytes) from the file; InputError when it ends first."""
    view = out.reshape(-1).view(np.uint8)
    got = 0
    while got < need:  # a single read returns at most ~2 GB on Linux
        k = f.readinto(view[got:])
        if not k:
            raise InputError(f"{path}: PLY file is truncated ({got} of {need} bytes)")
        got += k


# --- ASCII ---------------------------------------------------------------------------------------
_NUMBER = re.compile(rb"^[-+]?(\d+\.?\d*([eE][-+]?\d+)?|\.\d+([eE][-+]?\d+)?|nan|inf|infinity)$",
                     re.IGNORECASE)


def line_at(f, offset: int) -> int:
    """The number (from 1) of the line that starts at byte ``offset`` of the open file (whose
    position is left as it was)."""
    here = f.tell()
    f.seek(0)
    n, left = 1, offset
    while left > 0:
        chunk = f.read(min(left, 1 << 24))
        if not chunk:
            break
        n += chunk.count(b"\n")
        left -= len(chunk)
    f.seek(here)
    return n


def _shown(token: bytes) -> str:
    s = token.decode("utf-8", "replace")
    return repr(s if len(s) <= 40 else s[:37] + "...")


def rows_error(f, path: Path, start: int, n: int, ncols: int, names: tuple[str, str],
               declared, expected: str) -> InputError:
    """The InputError for the text rows from byte ``start`` that np.loadtxt refused or found too few
    of: the first of the ``n`` rows with a number of values other than ``ncols`` or a value that is
    no number, named by line — or, when they are all good, the rows missing (truncated).

    ``names``: a row's name, singular and plural (vertex, vertices); ``declared``: what states ``n``
    ("the header declares", "line 1 declares"; or a function giving it); ``expected``: what the
    values are (x, y, z …)."""
    one, many = names
    if callable(declared):  # its line number counted only now, for the message
        declared = declared()
    ln = line_at(f, start)
    f.seek(start)
    row = 0
    lines = iter(f)
    for raw in lines:
        toks = raw.split()
        if not toks or toks[0].startswith(b"#"):
            ln += 1
            continue
        if len(toks) != ncols:
            if len(toks) < ncols and not any(r.strip() for r in lines):
                return InputError(f"{path}, line {ln}: the file is truncated: {one} {row} holds "
                                  f"{len(toks)} of its {ncols} values ({declared} {n} {many})")
            return InputError(f"{path}, line {ln}: {one} {row} holds {len(toks)} values where "
                              f"{ncols} are expected ({expected})")
        for t in toks:
            if not _NUMBER.match(t):
                return InputError(f"{path}, line {ln}: {_shown(t)} is not a number ({one} {row})")
        row += 1
        ln += 1
        if row == n:
            break
    if row < n:
        return InputError(f"{path}: the file is truncated: {declared} {n} {many}, the file holds "
                          f"{row}")
    return InputError(f"{path}: the {many} are not rows of {ncols} numbers ({expected})")


def load_rows(f, path: Path, n: int, ncols: int, names: tuple[str, str], declared,
              expected: str) -> np.ndarray:
    """(n, ncols) float64 of the next ``n`` text rows of ``f`` (np.loadtxt; the file then stands
    right after them); InputError naming the line at fault or the rows missing (rows_error)."""
    start = f.tell()
    try:
        with warnings.catch_warnings():  # "input contained no data": the shape check names it
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(f, max_rows=n, ndmin=2, dtype=np.float64)
    except ValueError:
        raise rows_error(f, path, start, n, ncols, names, declared, expected) from None
    if data.shape != (n, ncols):
        raise rows_error(f, path, start, n, ncols, names, declared, expected)
    return data


def nth_line(f, pos: int, skip: int = 0) -> tuple[str, str]:
    """("line N", its text) of the first non-blank line from byte ``pos`` after ``skip`` such
    lines (for a message)."""
    f.seek(pos)
    seen = 0
    for k, raw in enumerate(f.read().splitlines()):
        if raw.strip():
            if seen == skip:
                return f"line {line_at(f, pos) + k}", _shown(raw.strip())
            seen += 1
    return "the end", "''"


def _read_ascii(f, path: Path, elements, vi: int, header_lines: int) -> tuple[np.ndarray, dict]:
    """The vertices of an ASCII PLY (one item a line), after skipping the elements before them; the
    lines after them must be as many as the other elements' items."""
    for name, count, _ in elements[:vi]:
        for i in range(count):
            if not _next_nonblank(f):
                raise InputError(f"{path}: the file is truncated: element '{name}' has {i} of the "
                                 f"{count} lines its header declares")
    _, n, props = elements[vi]
    what = ", ".join(p for p, _ in props)
    if any(_is_list(t) for _, t in props):
        fields = _ascii_list_rows(f, path, n, props)
    else:
        data = load_rows(f, path, n, len(props), ("vertex", "vertices"), "the header declares", what)
        fields = {p: data[:, j] for j, (p, _) in enumerate(props)}
    for p, t in props:  # integer properties: whole numbers of their type, kept as integers
        if not _is_list(t) and t[0] in "iu":
            fields[p] = _ascii_integers(path, p, t, fields[p])
        elif not _is_list(t) and p in INTEGER_CHANNELS:
            _exact_as_text(path, p, fields[p])
    xyz, cols = _columns(fields, props)
    pos = f.tell()
    want = sum(count for _, count, _ in elements[vi + 1:])
    rest = [ln for ln in f.read().splitlines() if ln.strip()]
    if len(rest) > want:
        ln, text = nth_line(f, pos, want)
        after = (" after the vertices" if want == 0 else
                 f" after the {want} lines of {', '.join(repr(e[0]) for e in elements[vi + 1:])}")
        raise _more_data(path, n, f"{ln}: {text}{after}")
    if len(rest) < want:
        got = len(rest)
        for name, count, _ in elements[vi + 1:]:
            if got < count:
                raise InputError(f"{path}: the file is truncated: element '{name}' has {got} of the "
                                 f"{count} lines its header declares")
            got -= count
    return xyz, cols


def _exact_as_text(path: Path, prop: str, v: np.ndarray) -> None:
    """An integer channel (index, line, fiducial, sensor) written as a floating property in an ASCII
    PLY is parsed as float64, exact as a whole number only below 2⁵³: 9007199254740993 read as
    9007199254740992 with no word (a review); refused, naming the vertex (as the text reader does)."""
    big = np.flatnonzero(np.abs(v) >= _EXACT)
    if big.size:
        raise InputError(f"{path}: vertex {int(big[0])}, property '{prop}': {float(v[big[0]])!r} is not a whole "
                         "number below 2⁵³ = 9007199254740992 — an ASCII PLY's numbers are read as float64, "
                         "exact whole numbers only below it")


def _next_nonblank(f) -> str:
    """The next line that is not blank ("" at the end of the file)."""
    line = f.readline()
    while line and not line.strip():
        line = f.readline()
    return line


def _ascii_integers(path: Path, prop: str, code: str, v: np.ndarray) -> np.ndarray:
    info = np.iinfo(code)
    bad = ~((v == np.floor(v)) & (v >= info.min) & (v <= info.max))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise InputError(f"{path}: vertex {row}: property '{prop}' is declared "
                         f"{next(k for k, c in _PLY_TYPES.items() if c == code)} but holds "
                         f"{float(v[row])!r}")
    return v.astype(np.int64)


def _ascii_list_rows(f, path: Path, n: int, props) -> dict:
    """The fixed-size properties of ASCII vertices that hold list properties too (one line each)."""
    fixed = [p for p, t in props if not _is_list(t)]
    rows = np.empty((n, len(fixed)), dtype=np.float64)
    start = f.tell()
    for i in range(n):
        line = _next_nonblank(f)
        if not line:
            raise InputError(f"{path}: the file is truncated: the header declares {n} vertices, the "
                             f"file holds {i}")
        toks = line.split()
        k = j = 0
        try:
            for _, t in props:
                if _is_list(t):
                    c = toks[k]
                    if not c.isdigit():
                        raise ValueError("a list length", c)
                    k += 1 + int(c)
                else:
                    if not _NUMBER.match(toks[k]):
                        raise ValueError("a number", toks[k])
                    rows[i, j] = float(toks[k])
                    j += 1
                    k += 1
            if k != len(toks):
                raise IndexError
        except (IndexError, ValueError) as e:
            ln = nth_line(f, start, i)[0]
            if isinstance(e, ValueError):
                raise InputError(f"{path}, {ln}: {_shown(e.args[1])} is not {e.args[0]} "
                                 f"(vertex {i})") from None
            raise InputError(f"{path}, {ln}: vertex {i} holds {len(toks)} values, not what its "
                             "properties and list lengths add up to") from None
    return {p: rows[:, j] for j, p in enumerate(fixed)}


# --- writing -------------------------------------------------------------------------------------
def _ply_type(name: str, c: np.ndarray) -> tuple[str, str]:
    """(PLY type, numpy type) that holds the channel's values exactly; ValueError beyond 2^53."""
    if c.dtype.kind not in "iub":
        return "double", "<f8"
    if c.size == 0:
        return "int", "<i4"
    lo, hi = int(c.min()), int(c.max())
    if -2**31 <= lo and hi < 2**31:
        return "int", "<i4"
    if lo >= 0 and hi < 2**32:
        return "uint", "<u4"
    if -_EXACT <= lo and hi <= _EXACT:
        return "double", "<f8"
    raise ValueError(f"channel '{name}' holds whole numbers up to {hi if hi > _EXACT else lo}, beyond "
                     "±2^53: PLY has no 64-bit integer type and a double would round them — write "
                     "--cloud-format csv or npz")


def write_ply(path: Path, xyz: np.ndarray, channels: dict, shown=None) -> None:
    """Binary little-endian PLY of x, y, z (double) and the channels (module doc: each integer
    channel in a type that holds it); InputError naming ``shown`` (default ``path``) and the
    channel whose integers no PLY type holds, before anything is written."""
    names = ["x", "y", "z", *channels]
    cols = [xyz[:, 0], xyz[:, 1], xyz[:, 2], *(np.asarray(c) for c in channels.values())]
    types = []
    for n, c in zip(names, cols):
        try:
            types.append(_ply_type(n, c))
        except ValueError as e:
            raise InputError(f"{shown or path}: {e}") from None
    dt = np.dtype([(n, t) for n, (_, t) in zip(names, types)])
    arr = np.empty(len(xyz), dtype=dt)
    for n, c in zip(names, cols):
        arr[n] = c
    wide = [n for n, c, (pt, _) in zip(names, cols, types) if pt == "double" and c.dtype.kind in "iub"]
    header = ["ply", "format binary_little_endian 1.0", "comment written by PointsPro (mm)"]
    if wide:
        header.append(f"comment {_INT64_COMMENT} {' '.join(wide)}")
    header.append(f"element vertex {len(xyz)}")
    header += [f"property {pt} {n}" for n, (pt, _) in zip(names, types)]
    header.append("end_header")
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(arr.tobytes())
