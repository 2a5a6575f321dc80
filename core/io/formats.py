"""Reading and writing point clouds by file extension.

read:  .csv .txt .xyz .asc .dat (text exports), .ply (all vertex properties kept), .pcd .pts (open3d),
       areal instrument files .datx .dat (MetroPro, told from text by its magic) .sur .sdf .x3p
       (core.io.instruments)
write: .csv (all channels, `index` included, shortest round-trip decimal), .ply (binary, float64)
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..cloud import PointCloud
from ..errors import InputError
from .atomic import atomic_path

TEXT_SUFFIXES = (".csv", ".txt", ".xyz", ".asc", ".dat")
OPEN3D_SUFFIXES = (".pcd", ".pts")
from .instruments import AREAL_SUFFIXES, is_metropro

READ_SUFFIXES = TEXT_SUFFIXES + (".ply",) + OPEN3D_SUFFIXES + AREAL_SUFFIXES
WRITE_SUFFIXES = (".csv", ".ply")


def read_cloud(path) -> PointCloud:
    """Read a measurement file into a PointCloud (frame `measuring`, `index` = row of the input)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a data file")
    if not os.access(path, os.R_OK):
        raise InputError(f"{path}: permission denied")
    suffix = path.suffix.lower()
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file — no data rows")
    if suffix in AREAL_SUFFIXES or (suffix == ".dat" and is_metropro(path)):
        from .instruments import read_areal

        xyz, cols, meta = read_areal(path)
    elif suffix in TEXT_SUFFIXES:
        from .text import read_text

        xyz, cols, meta = read_text(path)
    elif suffix == ".ply":
        from .ply import NotSimplePly, read_ply

        try:
            xyz, cols, meta = read_ply(path)
        except NotSimplePly:
            xyz, cols, meta = _read_open3d(path)
    elif suffix in OPEN3D_SUFFIXES:
        xyz, cols, meta = _read_open3d(path)
    else:
        raise InputError(f"{path}: unknown file type '{suffix}'; PointsPro reads "
                         f"{', '.join(READ_SUFFIXES)}")
    meta = {**meta, "source": str(path), "frame": "measuring", "units": "mm"}
    try:
        return PointCloud(xyz, cols, meta)
    except ValueError as e:
        raise InputError(f"{path}: {e}") from None


def _read_open3d(path: Path):
    import open3d as o3d  # lazy: heavy

    pc = o3d.io.read_point_cloud(str(path))
    xyz = np.asarray(pc.points, dtype=np.float64)
    if len(xyz) == 0:
        raise InputError(f"{path}: no points read (empty or not a {path.suffix} point cloud)")
    if not np.all(np.isfinite(xyz)):
        row = int(np.argwhere(~np.isfinite(xyz))[0, 0])
        raise InputError(f"{path}: point {row} has a NaN/inf coordinate")
    cols = {}
    if pc.has_normals():
        n = np.asarray(pc.normals, dtype=np.float64)
        cols.update(nx=n[:, 0], ny=n[:, 1], nz=n[:, 2])
    if pc.has_colors():
        c = np.asarray(pc.colors, dtype=np.float64)
        cols.update(red=c[:, 0], green=c[:, 1], blue=c[:, 2])
    return xyz.copy(), cols, {"format": path.suffix.lower().lstrip(".")}


def _format_column(a: np.ndarray) -> list[str]:
    if a.dtype.kind in "iu":
        return list(map(str, a.tolist()))
    return list(map(repr, a.tolist()))  # shortest string that reads back bit-exact


def write_csv(cloud: PointCloud, path) -> None:
    """CSV with a header: x, y, z (mm), index, then the other channels; written atomically."""
    names = cloud.column_names
    arrays = [cloud[n] for n in names]
    chunk = 100_000  # formatted strings cost ~50 bytes a value: bound the memory, not the speed
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        f.write(",".join(names) + "\n")
        for start in range(0, cloud.n, chunk):
            cols = [_format_column(a[start:start + chunk]) for a in arrays]
            f.writelines(",".join(row) + "\n" for row in zip(*cols))


def write_ply_cloud(cloud: PointCloud, path) -> None:
    from .ply import write_ply

    ch = {n: cloud[n] for n in cloud.column_names[3:]}
    with atomic_path(path) as tmp:
        write_ply(tmp, np.asarray(cloud.xyz), ch)


def write_cloud(cloud: PointCloud, path) -> None:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        write_csv(cloud, path)
    elif suffix == ".ply":
        write_ply_cloud(cloud, path)
    else:
        raise InputError(f"{path}: cannot write '{suffix}'; PointsPro writes {', '.join(WRITE_SUFFIXES)}")
