"""PLY point clouds with every channel kept (binary little-endian float64 on write).

open3d reads PLY too, but only positions, normals and colours, and converts through its own types;
a cloud written by PointsPro must come back with its `index`, `residual`, ω... so the vertex element
is parsed here with a numpy structured dtype. Files whose vertex element holds list properties fall
back to open3d (see formats.py).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


class NotSimplePly(Exception):
    """The file is a PLY this reader does not handle (lists in the vertex element...)."""


_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")


def read_ply(path: Path):
    with open(path, "rb") as f:
        fmt, elements = _read_header(f, path)
        if not elements or elements[0][0] != "vertex":
            raise NotSimplePly("vertex is not the first element")
        _, n, props = elements[0]
        if n == 0:
            raise InputError(f"{path}: empty file — the PLY has no vertices")
        names = [p for p, _ in props]
        for a in "xyz":
            if a not in names:
                raise InputError(f"{path}: PLY vertices have no '{a}' property")
        dup = sorted({p for p in names if names.count(p) > 1})
        if dup:
            raise InputError(f"{path}: PLY vertex property {dup[0]!r} is declared twice")
        _check_memory(f, path, fmt, n, props)
        if fmt == "ascii":
            cols = _read_ascii(f, path, n, props)
            xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")])
        else:
            xyz, cols = _read_binary(f, path, fmt, n, props)
    if not np.isfinite(xyz).all():
        row = int(np.argwhere(~np.isfinite(xyz))[0, 0])
        raise InputError(f"{path}: vertex {row} has a NaN/inf coordinate")
    meta = {"format": "ply"}
    # an interferometer's map exported as x, y, z: its pixel grid is recorded (core.io.gridcloud),
    # so that the processed cloud can be written as a map again (cloud.x3p)
    from .gridcloud import detect_grid

    grid = detect_grid(xyz[:, 0], xyz[:, 1])
    if grid is not None:
        meta.update(grid)
    return xyz, cols, meta


def _read_header(f, path: Path) -> tuple[str, list]:
    """(format, [(element, count, [(property, dtype or "list")])]); InputError naming the header line
    at fault."""
    if f.readline().strip() != b"ply":
        raise InputError(f"{path}: not a PLY file (no 'ply' magic line)")
    fmt = None
    elements: list = []
    ln = 1

    def bad(what: str):
        raise InputError(f"{path}: PLY header line {ln}: {what}")

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
                if elements[-1][0] == "vertex":
                    raise NotSimplePly("list property in vertex element")
                elements[-1][2].append((parts[-1], "list"))
            elif len(parts) < 3 or parts[1] not in _PLY_TYPES:
                bad(f"a property needs a type ({', '.join(sorted(set(_PLY_TYPES)))}) and a name")
            else:
                elements[-1][2].append((parts[2], _PLY_TYPES[parts[1]]))
        elif parts[0] == "end_header":
            break
    if fmt is None:
        raise InputError(f"{path}: PLY header has no format line")
    return fmt, elements


def _check_memory(f, path: Path, fmt: str, n: int, props) -> None:
    """Refuse, from the header alone, a cloud too large for the memory available (core.io.memory):
    nothing of the vertex data is read."""
    from .memory import check_fits

    short = False
    if fmt != "ascii":
        need = np.dtype([(p, t) for p, t in props]).itemsize * n
        short = path.stat().st_size - f.tell() < need
    check_fits(path, n, where="PLY header (element vertex)", file_short=short)


def _read_ascii(f, path: Path, n: int, props) -> dict:
    try:
        with warnings.catch_warnings():  # "input contained no data": the shape check names it
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(f, max_rows=n, ndmin=2, dtype=np.float64)
    except ValueError:
        raise InputError(f"{path}: PLY vertex data are not numbers as its header says") from None
    if data.shape != (n, len(props)):
        raise InputError(f"{path}: PLY vertex data does not match its header")
    return {p: data[:, j] for j, (p, _) in enumerate(props)}


def _read_binary(f, path: Path, fmt: str, n: int, props) -> tuple[np.ndarray, dict]:
    """(xyz, the other channels): the vertex data read straight from the file into numpy arrays.

    x, y, z as three float64 properties in that order and nothing else (the usual map, and what
    PointsPro writes) are read into the (n, 3) coordinate array itself: one copy of the bytes, from
    the file to where they stay (byte-swapped in place from big-endian). Other layouts are read into
    one structured array, whose columns are then copied out once each (x, y, z into the coordinate
    array, every other property to float64 or int64)."""
    order = "<" if fmt == "binary_little_endian" else ">"
    dt = np.dtype([(p, order + t) for p, t in props])
    need = dt.itemsize * n
    left = path.stat().st_size - f.tell()
    if left < need:  # before reading: a damaged count must not allocate terabytes
        raise InputError(f"{path}: PLY file is truncated ({max(left, 0)} of {need} bytes)")
    if props == [("x", "f8"), ("y", "f8"), ("z", "f8")]:
        xyz = np.empty((n, 3), dtype=np.float64)
        _read_into(f, path, xyz, need)
        if np.dtype(order + "f8") != np.dtype(np.float64):  # not the machine's byte order
            xyz.byteswap(inplace=True)
        return xyz, {}
    arr = np.empty(n, dtype=dt)
    _read_into(f, path, arr, need)
    xyz = np.empty((n, 3), dtype=np.float64)
    for j, a in enumerate("xyz"):
        xyz[:, j] = arr[a]
    cols = {p: arr[p].astype(np.float64 if arr[p].dtype.kind == "f" else np.int64)
            for p, _ in props if p not in ("x", "y", "z")}
    return xyz, cols


def _read_into(f, path: Path, out: np.ndarray, need: int) -> None:
    """Fill ``out`` (C-contiguous, ``need`` bytes) from the file; InputError when it ends first."""
    view = out.reshape(-1).view(np.uint8)
    got = 0
    while got < need:  # a single read returns at most ~2 GB on Linux
        k = f.readinto(view[got:])
        if not k:
            raise InputError(f"{path}: PLY file is truncated ({got} of {need} bytes)")
        got += k


def write_ply(path: Path, xyz: np.ndarray, channels: dict) -> None:
    names = ["x", "y", "z", *channels]
    cols = [xyz[:, 0], xyz[:, 1], xyz[:, 2], *channels.values()]
    dt = np.dtype([(n, "<i4" if c.dtype.kind in "iu" else "<f8") for n, c in zip(names, cols)])
    arr = np.empty(len(xyz), dtype=dt)
    for n, c in zip(names, cols):
        arr[n] = c
    header = ["ply", "format binary_little_endian 1.0", "comment written by PointsPro (mm)",
              f"element vertex {len(xyz)}"]
    header += [f"property {'int' if dt[n].kind == 'i' else 'double'} {n}" for n in names]
    header.append("end_header")
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(arr.tobytes())
