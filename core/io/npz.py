"""A processed cloud as a NumPy ``.npz`` (``pointspro --batch --cloud-format npz``).

One array per column, named as in cloud.csv: ``x``, ``y``, ``z`` (mm) and every channel, float64
(integer channels — ``index``, ``line`` … — int64, so rows stay exact); and ``pointspro_meta``: a JSON
string with the units, the frame, the column order and the channels' units. It loads with
``numpy.load(path)`` alone (no pickle) and reads back through ``read_cloud``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from .atomic import atomic_path

META_KEY = "pointspro_meta"


def write_npz_cloud(cloud, path) -> None:
    """Every column of ``cloud`` and its metadata into ``path`` (atomically)."""
    names = cloud.column_names
    arrays = {n: np.asarray(cloud[n], dtype=np.int64 if cloud[n].dtype.kind in "iu" else np.float64)
              for n in names}
    meta = {"units": cloud.meta.get("units", "mm"), "frame": cloud.meta.get("frame", "measuring"),
            "columns": names, "channel_units": dict(cloud.meta.get("channel_units") or {}),
            "source": cloud.meta.get("source")}
    arrays[META_KEY] = np.array(json.dumps(meta))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: savez adds no ".npz"
        np.savez(f, **arrays)


def read_npz(path: Path):
    """(xyz, channels, meta) of a cloud written by ``write_npz_cloud``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z[META_KEY]))
            cols = {n: np.array(z[n]) for n in meta["columns"]}
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(f"{path}: not a PointsPro cloud .npz ({type(e).__name__}: {e})") from None
    if meta.get("units", "mm") != "mm":
        raise InputError(f"{path}: units {meta.get('units')!r}, PointsPro reads mm")
    xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")]).astype(np.float64)
    out_meta = {"format": "npz"}
    if meta.get("channel_units"):
        out_meta["channel_units"] = meta["channel_units"]
    return xyz, cols, out_meta
