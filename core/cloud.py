"""The point cloud: float64 xyz (mm) plus named per-point channels, metadata and provenance.

The data model: clouds are never mutated in place. Every array a cloud holds is made
read-only, so a step that tries to write into its input fails loudly instead of corrupting it;
a step returns a new cloud (sharing unchanged arrays is fine and cheap).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np

_CHANNEL_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
# Channels that hold integers (labels, ids, rows); everything else is float64.
INTEGER_CHANNELS = frozenset({"index", "line", "fiducial", "sensor"})
#: float64 holds every whole number below 2⁵³ exactly (2⁵³ itself is also what 2⁵³ + 1 reads as): an
#: integer channel parsed from text as float64 must lie below it (docs/formats.md)
EXACT_WHOLE = 2**53


def first_repeat(index) -> tuple | None:
    """(the first repeated value in row order, how often it occurs, how many repeats in all) when
    ``index`` repeats a value, else None; an increasing index, the usual case, is told without sorting."""
    idx = np.asarray(index)
    if idx.size < 2 or bool(np.all(idx[1:] > idx[:-1])):
        return None
    uniq, counts = np.unique(idx, return_counts=True)
    if uniq.size == idx.size:
        return None
    first = idx[np.isin(idx, uniq[counts > 1])][0].item()
    first = int(first) if isinstance(first, float) and first.is_integer() else first
    return first, int(counts[np.searchsorted(uniq, first)]), int(idx.size - uniq.size)


def repeated_index_message(index) -> str | None:
    """A reader's words for a repeated index (it numbers the input's rows: manual_edit removes by it):
    "the index column has repeated values (the first: 3, 2 times)"; None when none repeats."""
    rep = first_repeat(index)
    return None if rep is None else f"the index column has repeated values (the first: {rep[0]}, {rep[1]} times)"


FRAMES = ("measuring", "part")


def _frozen(a: np.ndarray) -> np.ndarray:
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


def _unique_index(index, where: str) -> None:
    """An ``index`` given by the caller must name each input row once: manual_edit removes rows by it,
    and pd.concat of two to_pandas() frames repeats it (remove: [3] removed 468 points of 4680,
    silently — a review)."""
    if index is None:
        return
    from .errors import InputError

    rep = first_repeat(index)
    if rep is not None:
        first, times, repeats = rep
        raise InputError(f"{where}: the index column must name each input row once; {repeats} "
                         f"repeat(s) (first: {first!r}, {times} times) — "
                         "renumber it (df['index'] = range(len(df))) or drop it")


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points of a measured surface.

    xyz:        (N, 3) float64, mm.
    channels:   name -> (N,) array; ``index`` (int64 row of the original input) is always present.
    meta:       units ("mm"), frame ("measuring" or "part"), source (file), anything JSON-able.
    provenance: the steps applied so far, oldest first (each a small dict: id, params).
    """

    xyz: np.ndarray
    channels: Mapping[str, np.ndarray] = field(default_factory=dict)
    meta: Mapping[str, Any] = field(default_factory=dict)
    provenance: tuple = ()

    def __post_init__(self):
        xyz = np.asarray(self.xyz)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise ValueError(f"xyz must have shape (N, 3), got {xyz.shape}")
        xyz = _frozen(np.ascontiguousarray(xyz, dtype=np.float64))
        n = xyz.shape[0]
        chans = {}
        for name, arr in dict(self.channels).items():
            if not _CHANNEL_NAME.match(name):
                raise ValueError(f"channel name {name!r} is not an identifier")
            if name in ("x", "y", "z"):
                raise ValueError("x, y, z live in xyz, not in channels")
            a = np.asarray(arr)
            if a.shape != (n,):
                raise ValueError(f"channel {name!r} has shape {a.shape}, expected ({n},)")
            # int64 holds every integer channel: a uint64 of 2⁶³ or more (or a float beyond ±2⁶³)
            # wrapped to a negative number with no word (a review)
            if a.dtype.kind == "u" and a.size and int(a.max()) >= 2**63:
                raise ValueError(f"channel {name!r} holds {int(a.max())}, beyond the 64-bit signed "
                                 "integers (2⁶³ − 1) it is kept in")
            if name in INTEGER_CHANNELS:
                if a.dtype.kind == "f":
                    if not np.all(np.isfinite(a)) or np.any(a != np.round(a)):
                        raise ValueError(f"channel {name!r} must hold integers")
                    if a.size and not np.all((a >= -(2.0**63)) & (a < 2.0**63)):
                        raise ValueError(f"channel {name!r} holds {float(np.max(np.abs(a)))!r}, beyond the "
                                         "64-bit signed integers it is kept in")
                a = a.astype(np.int64, copy=False)
            elif a.dtype.kind in "iub":
                a = a.astype(np.float64) if a.dtype.kind == "b" else a.astype(np.int64, copy=False)
            else:
                a = a.astype(np.float64, copy=False)
            chans[name] = _frozen(a)
        if "index" not in chans:
            chans["index"] = _frozen(np.arange(n, dtype=np.int64))
        meta = {"units": "mm", "frame": "measuring"}
        meta.update(dict(self.meta))
        if meta["frame"] not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, got {meta['frame']!r}")
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "channels", chans)
        object.__setattr__(self, "meta", meta)
        object.__setattr__(self, "provenance", tuple(self.provenance))

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_xyz(cls, x, y, z, **channels) -> "PointCloud":
        """A cloud from three coordinate arrays (mm) and channels as keyword arrays."""
        _unique_index(channels.get("index"), "from_xyz")
        return cls(np.column_stack([np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)]),
                   channels)

    @classmethod
    def from_numpy(cls, xyz, *, meta: Mapping[str, Any] | None = None, **channels) -> "PointCloud":
        """A cloud from an (N, 3) array of x, y, z in mm (convert first: ``xyz_um * 1e-3``) and
        channels as keyword arrays of length N (``residual=r_mm``); float64 copies are made where
        the dtype differs. ``meta`` e.g. ``{"frame": "part"}`` for points already in the part frame."""
        from .errors import InputError

        xyz = np.asarray(xyz)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"from_numpy: xyz must have shape (N, 3), got {xyz.shape}")
        _unique_index(channels.get("index"), "from_numpy")
        try:
            return cls(xyz, channels, dict(meta or {}))
        except ValueError as e:
            raise InputError(f"from_numpy: {e}") from None

    @classmethod
    def from_pandas(cls, df, *, meta: Mapping[str, Any] | None = None) -> "PointCloud":
        """A cloud from a DataFrame with columns x, y, z (mm) and any numeric columns as channels
        (``index``, when present, is the input row kept through the steps). ``df.attrs`` (as
        ``to_pandas`` writes them: units, frame, source) become the cloud's metadata."""
        from .errors import InputError

        cols = [str(c) for c in df.columns]
        missing = [c for c in "xyz" if c not in cols]
        if missing:
            raise InputError(f"from_pandas: column(s) {', '.join(missing)} missing (have "
                             f"{', '.join(cols[:12])}); x, y, z in mm are required")
        chans = {}
        for c in cols:
            if c in ("x", "y", "z"):
                continue
            s = df[c]
            if s.dtype.kind not in "fiub":
                raise InputError(f"from_pandas: column {c!r} is not numeric ({s.dtype}); drop it or "
                                 "convert it")
            chans[c] = s.to_numpy()
        m = {k: v for k, v in dict(getattr(df, "attrs", {}) or {}).items() if isinstance(k, str)}
        m.update(meta or {})
        xyz = np.column_stack([df[c].to_numpy(dtype=np.float64) for c in "xyz"])
        _unique_index(chans.get("index"), "from_pandas")
        try:
            return cls(xyz, chans, m)
        except ValueError as e:
            raise InputError(f"from_pandas: {e}") from None

    # -- export ---------------------------------------------------------------------------------
    def to_numpy(self) -> np.ndarray:
        """A writable (N, 3) float64 copy of x, y, z (mm)."""
        return np.array(self.xyz)

    def to_pandas(self):
        """A DataFrame (writable copies): x, y, z (mm), index, then every channel; ``df.attrs``
        holds the metadata (units, frame, source, the reader's description)."""
        import pandas as pd

        data = {"x": self.x, "y": self.y, "z": self.z}
        data.update({name: self[name] for name in self.column_names[3:]})
        df = pd.DataFrame({k: np.array(v) for k, v in data.items()})
        df.attrs.update({k: v for k, v in self.meta.items()})
        return df

    def to_pyvista(self):
        """A pyvista PolyData of the points (float64, one vertex cell each) with every channel as a
        point array and the metadata's units and frame as field arrays."""
        import pyvista as pv

        poly = pv.PolyData(np.array(self.xyz))
        for name in self.column_names[3:]:
            poly.point_data[name] = np.array(self[name])
        poly.field_data["units"] = [str(self.meta.get("units", "mm"))]
        poly.field_data["frame"] = [self.frame]
        return poly

    def _repr_html_(self) -> str:
        from .notebook import cloud_html

        return cloud_html(self)

    # -- access ---------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.xyz.shape[0]

    @property
    def n(self) -> int:
        return self.xyz.shape[0]

    @property
    def x(self) -> np.ndarray:
        return self.xyz[:, 0]

    @property
    def y(self) -> np.ndarray:
        return self.xyz[:, 1]

    @property
    def z(self) -> np.ndarray:
        return self.xyz[:, 2]

    @property
    def index(self) -> np.ndarray:
        return self.channels["index"]

    @property
    def frame(self) -> str:
        return self.meta["frame"]

    def __getitem__(self, name: str) -> np.ndarray:
        if name in ("x", "y", "z"):
            return self.xyz[:, "xyz".index(name)]
        return self.channels[name]

    def __contains__(self, name: str) -> bool:
        return name in ("x", "y", "z") or name in self.channels

    @property
    def column_names(self) -> list[str]:
        """x, y, z then the channels, ``index`` first."""
        rest = [c for c in self.channels if c != "index"]
        return ["x", "y", "z", "index", *rest]

    # -- derivation (never in place) ------------------------------------------------------------
    def replace(self, *, xyz=None, channels=None, meta=None, drop: Iterable[str] = ()) -> "PointCloud":
        """A new cloud with some parts replaced; channels/meta given here are merged over the old."""
        ch = dict(self.channels)
        for d in drop:
            ch.pop(d, None)
        if channels:
            ch.update(channels)
        m = dict(self.meta)
        if meta:
            m.update(meta)
        return PointCloud(self.xyz if xyz is None else xyz, ch, m, self.provenance)

    def select(self, keep) -> "PointCloud":
        """Rows kept by a boolean mask or integer positions (order of the input is preserved)."""
        keep = np.asarray(keep)
        if keep.dtype == bool:
            if keep.shape != (self.n,):
                raise ValueError("mask length does not match the cloud")
        else:
            keep = np.sort(keep.astype(np.int64))
        return PointCloud(self.xyz[keep], {k: v[keep] for k, v in self.channels.items()},
                          self.meta, self.provenance)

    def with_provenance(self, entry: Mapping[str, Any]) -> "PointCloud":
        return PointCloud(self.xyz, self.channels, self.meta, self.provenance + (dict(entry),))

    def equals(self, other: "PointCloud") -> bool:
        """Bit-for-bit equality of coordinates and channels (NaN equal to NaN)."""
        if set(self.channels) != set(other.channels) or self.n != other.n:
            return False
        if not np.array_equal(self.xyz, other.xyz, equal_nan=True):
            return False
        return all(np.array_equal(v, other.channels[k], equal_nan=v.dtype.kind == "f")
                   for k, v in self.channels.items())

    def __repr__(self) -> str:
        return (f"PointCloud(n={self.n}, channels={sorted(self.channels)}, frame={self.frame!r}, "
                f"steps={[p.get('id') for p in self.provenance]})")
