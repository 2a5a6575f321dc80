"""PLY point clouds with every channel kept (binary little-endian float64 on write).

open3d reads PLY too, but only positions, normals and colours, and converts through its own types;
a cloud written by PointsPro must come back with its `index`, `residual`, ω... so the vertex element
is parsed here with a numpy structured dtype. Files whose vertex element holds list properties fall
back to open3d (see formats.py).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


class NotSimplePly(Exception):
    """The file is a PLY this reader does not handle (lists in the vertex element...)."""


def read_ply(path: Path):
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise InputError(f"{path}: not a PLY file (no 'ply' magic line)")
        fmt = None
        elements = []  # (name, count, [(prop, type)])
        while True:
            line = f.readline()
            if not line:
                raise InputError(f"{path}: PLY header has no end_header")
            parts = line.decode("ascii", "replace").split()
            if not parts:
                continue
            if parts[0] == "format":
                fmt = parts[1]
            elif parts[0] == "element":
                elements.append((parts[1], int(parts[2]), []))
            elif parts[0] == "property":
                if parts[1] == "list":
                    if elements and elements[-1][0] == "vertex":
                        raise NotSimplePly("list property in vertex element")
                    elements[-1][2].append((parts[-1], "list"))
                else:
                    elements[-1][2].append((parts[2], _PLY_TYPES[parts[1]]))
            elif parts[0] == "end_header":
                break
        if not elements or elements[0][0] != "vertex":
            raise NotSimplePly("vertex is not the first element")
        _, n, props = elements[0]
        if n == 0:
            raise InputError(f"{path}: empty file — the PLY has no vertices")
        if fmt == "ascii":
            data = np.loadtxt(f, max_rows=n, ndmin=2, dtype=np.float64)
            if data.shape != (n, len(props)):
                raise InputError(f"{path}: PLY vertex data does not match its header")
            cols = {p: data[:, j] for j, (p, _) in enumerate(props)}
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            dt = np.dtype([(p, order + t) for p, t in props])
            buf = f.read(dt.itemsize * n)
            if len(buf) < dt.itemsize * n:
                raise InputError(f"{path}: PLY file is truncated ({len(buf)} of {dt.itemsize * n} bytes)")
            arr = np.frombuffer(buf, dtype=dt, count=n)
            cols = {p: arr[p].astype(np.float64 if arr[p].dtype.kind == "f" else np.int64)
                    for p, _ in props}
    for a in "xyz":
        if a not in cols:
            raise InputError(f"{path}: PLY vertices have no '{a}' property")
    xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")]).astype(np.float64)
    if not np.all(np.isfinite(xyz)):
        row = int(np.argwhere(~np.isfinite(xyz))[0, 0])
        raise InputError(f"{path}: vertex {row} has a NaN/inf coordinate")
    return xyz, cols, {"format": "ply"}


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
