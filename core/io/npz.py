"""A processed cloud as a NumPy ``.npz`` (``pointspro --batch --cloud-format npz``).

One array per column, named as in cloud.csv: ``x``, ``y``, ``z`` (mm) and every channel, float64
(integer channels — ``index``, ``line`` … — int64, so rows stay exact); and ``pointspro_meta``: a JSON
string with the units, the frame, the column order and the channels' units. It loads with
``numpy.load(path)`` alone (no pickle) and reads back through ``read_cloud``. On reading, an array
that is not a 1-D column of real numbers as long as x, or ``columns`` without x, y or z, is refused
naming it; rows with a NaN/inf x, y or z are dropped and counted (``invalid="error"``: refused).
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..cloud import FRAMES
from ..errors import InputError
from .atomic import atomic_path

META_KEY = "pointspro_meta"


def write_npz_cloud(cloud, path) -> None:
    """Every column of ``cloud`` and its metadata into ``path`` (atomically)."""
    from ..units import channel_unit

    names = cloud.column_names
    arrays = {n: np.asarray(cloud[n], dtype=np.int64 if cloud[n].dtype.kind in "iu" else np.float64)
              for n in names}
    # each channel's unit as its numbers are held (as cloud.csv's header states it): a length read
    # in nm or µm was converted to mm on reading, so it is mm here, not the unit the input stated
    stated = cloud.meta.get("channel_units") or {}
    units = {n: u for n in names[3:] if (u := channel_unit(n, stated.get(n) if isinstance(stated, dict) else None))}
    meta = {"units": cloud.meta.get("units", "mm"), "frame": cloud.meta.get("frame", "measuring"),
            "columns": names, "channel_units": units, "source": cloud.meta.get("source")}
    arrays[META_KEY] = np.array(json.dumps(meta))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: savez adds no ".npz"
        np.savez(f, **arrays)


def read_npz(path: Path, invalid: str = "drop"):
    """(xyz, channels, meta) of a cloud written by ``write_npz_cloud``.

    Every column listed in ``pointspro_meta`` must be a 1-D array of real numbers, all of one length,
    x, y and z among them; anything else is refused naming the array. Rows whose x, y or z is NaN/inf
    are dropped and counted in ``meta["invalid_dropped"]`` (``index`` keeps the row), as x y z text;
    with ``invalid="error"`` the first is refused by row and column."""
    try:
        # the file opened here: np.load leaves its own handle open when the zip cannot be read (a
        # truncated .npz: "ResourceWarning: unclosed file" beside the message — a review)
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            if META_KEY not in z.files:
                raise InputError(f"{path}: not a PointsPro cloud .npz (no {META_KEY} array)")
            meta = json.loads(str(z[META_KEY]))
            if not isinstance(meta, dict):
                raise InputError(f"{path}: not a PointsPro cloud .npz ({META_KEY} is not a JSON "
                                 "object)")
            names = meta.get("columns")
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise InputError(f"{path}: {META_KEY}'s 'columns' is not a list of column names")
            for axis in ("x", "y", "z"):
                if axis not in names:
                    raise InputError(f"{path}: {META_KEY}'s 'columns' has no '{axis}' — a PointsPro "
                                     "cloud .npz holds x, y and z")
            dup = next((n for n in names if names.count(n) > 1), None)
            if dup is not None:
                raise InputError(f"{path}: {META_KEY}'s 'columns' names '{dup}' twice")
            missing = next((n for n in names if n not in z.files), None)
            if missing is not None:
                raise InputError(f"{path}: column '{missing}' is listed in {META_KEY} but the file "
                                 "has no array of that name")
            cols = {n: np.array(z[n]) for n in names}
    except InputError:
        raise
    except zipfile.BadZipFile as e:  # a zip's directory is at its end: a cut file loses it first
        raise InputError(f"{path}: a damaged or truncated .npz ({e})") from None
    except (OSError, ValueError, KeyError, TypeError, EOFError) as e:
        raise InputError(f"{path}: not a PointsPro cloud .npz ({type(e).__name__}: {e})") from None
    if meta.get("units", "mm") != "mm":
        raise InputError(f"{path}: units {meta.get('units')!r}, PointsPro reads mm")
    n = len(cols["x"]) if cols["x"].ndim == 1 else None
    for name, a in cols.items():
        if a.ndim != 1:
            raise InputError(f"{path}: array '{name}' has shape {a.shape}; a column is 1-D")
        if a.dtype.kind not in "biuf":  # complex, strings, dates: no coordinate or channel
            raise InputError(f"{path}: array '{name}' holds {a.dtype} values, not real numbers")
        if len(a) != n:
            raise InputError(f"{path}: array '{name}' has {len(a)} values where 'x' has {n} — the "
                             "columns differ in length")
    xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")]).astype(np.float64)
    frame = meta.get("frame") or "measuring"  # none stated: the measuring frame, as every file
    if frame not in FRAMES:
        raise InputError(f"{path}: {META_KEY}'s frame {frame!r} is not one of {', '.join(FRAMES)}")
    # the frame the cloud was written in: a batch's cloud after `misalignment` is in the part frame
    # (read back as "measuring" until 2026-11-27, as text and PLY clouds, which state no frame)
    out_meta = {"format": "npz", "invalid_dropped": 0, "frame": frame}
    ok = np.isfinite(xyz).all(axis=1)
    if not ok.all():
        row = int(np.flatnonzero(~ok)[0])
        col = "xyz"[int(np.flatnonzero(~np.isfinite(xyz[row]))[0])]
        where = f"row {row}, column '{col}': {float(xyz[row, 'xyz'.index(col)])!r}"
        if invalid != "drop":
            raise InputError(f"{path}, {where} is not a finite number")
        if not ok.any():
            raise InputError(f"{path}: every row holds a NaN/inf x, y or z (the first: {where}) — "
                             "nothing left to read")
        if "index" not in cols:
            cols["index"] = np.arange(len(xyz), dtype=np.int64)
        xyz = xyz[ok]
        cols = {k: v[ok] for k, v in cols.items()}
        out_meta["invalid_dropped"] = int((~ok).sum())
    if isinstance(meta.get("channel_units"), dict) and meta["channel_units"]:
        from ..units import is_length_unit

        # lengths are held in mm: a file written before 2026-11-27 stated the input's nm or µm beside
        # numbers in mm
        out_meta["channel_units"] = {n: ("mm" if isinstance(u, str) and is_length_unit(u) else u)
                                     for n, u in meta["channel_units"].items()}
    return xyz, cols, out_meta
