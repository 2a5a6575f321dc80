"""`pointspro info FILE`: what a measurement file holds, before any recipe (like `pdal info`).

The reader chosen, the number of points, the channels with their units, the extents (mm), the grid
of a map (rows × columns, pixel) or the mean nearest-neighbour spacing of a scattered cloud, and a
quick look at the heights: RMS (over the area) and PV of z after removing the least-squares plane
(piston and tilt, about the bounding-box centre as in the summary, docs/conventions.md "Summary
figures"). Nothing is written; the file is read exactly as `--batch` reads it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

#: channels whose unit the project fixes (docs/conventions.md, Units); others: the file's header
_KNOWN_UNITS = {"residual": "mm", "probe_residual": "mm", "nx": "1", "ny": "1", "nz": "1"}
_DELIMITERS = {",": "comma", ";": "semicolon", "\t": "tab", " ": "space", "|": "bar"}
#: points queried for the nearest-neighbour spacing (a fixed-seed subsample of larger clouds)
SPACING_SAMPLE = 10_000


def describe(path, options: dict | None = None) -> dict:
    """The facts above as a JSON-able dict (lengths in mm, keys ending ``_mm``). InputError for a
    file no reader takes, as `--batch` would say it."""
    from .io import read_cloud
    from .pipeline import remove_piston_tilt
    from .units import format_length

    path = Path(path)
    cloud = read_cloud(path, **(options or {}))
    meta = dict(cloud.meta)
    units = dict(meta.get("channel_units") or {})
    channels = [{"name": n, "unit": "mm"} for n in ("x", "y", "z")]
    channels += [{"name": n, "unit": units.get(n) or _KNOWN_UNITS.get(n)}
                 for n in cloud.column_names[3:]]
    d: dict = {"file": str(path), "format": meta.get("instrument_format") or meta.get("format"),
               "reader": meta.get("instrument_reader"), "points": cloud.n, "channels": channels,
               "invalid_dropped": meta.get("invalid_dropped", 0)}
    if meta.get("format") == "text" and meta.get("delimiter"):
        delim = _DELIMITERS.get(meta["delimiter"], meta["delimiter"])
        d["reader"] = (f"x y z columns, {delim}-delimited"
                       + (", decimal comma" if meta.get("decimal_comma") else "")
                       + (f", header on line {meta['header_line']}" if meta.get("header_line") else ""))
    d["extent_mm"] = {a: [float(v.min()), float(v.max())] if cloud.n else None
                      for a, v in (("x", cloud.x), ("y", cloud.y), ("z", cloud.z))}
    grid, pixel = meta.get("grid"), meta.get("pixel_mm")
    if grid:
        d["grid"] = {"rows": int(grid[1]), "cols": int(grid[0]),
                     "pixel_mm": [float(p) for p in pixel] if pixel else None}
        d["spacing_mm"] = None
    else:
        d["grid"] = None
        # lateral (x, y), as the steps see the sampling (knn_denoise's window, a map's pitch): in 3-D
        # a steep or tall z made it the heights' steps (a review: 40.6 mm for a 1 µm pitch)
        d["spacing_mm"] = mean_spacing(cloud.xyz[:, :2])
    d["z_plane_removed"] = None
    if cloud.n >= 3:
        from .metrics.area_weights import weighted_rms
        from .pipeline import area_weights_of

        r = remove_piston_tilt(cloud.x, cloud.y, cloud.z)
        # RMS over the area, as the summary (docs/conventions.md, Summary figures): a star scan's points
        # crowd its centre; a map, an even sampling and stylus profiles: the points' plain RMS
        w = None if grid else area_weights_of(cloud)
        rms, pv = weighted_rms(r, w), float(np.ptp(r))
        d["z_plane_removed"] = {"rms_mm": rms, "pv_mm": pv, "rms": format_length(rms),
                                "pv": format_length(pv)}
    return d


def mean_spacing(xyz: np.ndarray, sample: int = SPACING_SAMPLE, seed: int = 0) -> float | None:
    """Mean distance (mm) from a point to its nearest neighbour (in the coordinates given: info passes
    x, y), over a fixed-seed subsample of at
    most ``sample`` points queried against the whole cloud (so the estimate is not inflated by the
    subsampling). None below two points."""
    from scipy.spatial import cKDTree

    n = len(xyz)
    if n < 2:
        return None
    tree = cKDTree(xyz)
    q = xyz if n <= sample else xyz[np.random.default_rng(seed).choice(n, sample, replace=False)]
    dist, _ = tree.query(q, k=2)
    return float(np.mean(dist[:, 1]))


def format_text(d: dict) -> str:
    """The description as a few aligned lines for the terminal."""
    from .units import format_length

    fmt = d["format"] + (f" ({d['reader']})" if d.get("reader") else "")
    chans = ", ".join(c["name"] + (f" [{c['unit']}]" if c.get("unit") else "") for c in d["channels"])
    lines = [f"file       {d['file']}", f"format     {fmt}",
             f"points     {d['points']}" + (f" ({d['invalid_dropped']} invalid dropped)"
                                            if d.get("invalid_dropped") else ""),
             f"channels   {chans}"]
    for a in ("x", "y", "z"):
        e = d["extent_mm"][a]
        if e is not None:
            lines.append(f"{a}          {e[0]:.6g} … {e[1]:.6g} mm (span {format_length(e[1] - e[0])})")
    g = d.get("grid")
    if g:
        pix = g.get("pixel_mm")
        pix_text = (f", pixel {format_length(pix[0])} × {format_length(pix[1])}" if pix else "")
        lines.append(f"grid       {g['rows']} rows × {g['cols']} cols{pix_text}")
    elif d.get("spacing_mm") is not None and np.isfinite(d["spacing_mm"]):
        lines.append(f"scattered  mean nearest-neighbour spacing {format_length(d['spacing_mm'])} (in x, y)")
    elif d.get("spacing_mm") is not None:  # distances of ~1e300 mm overflow
        lines.append("scattered  nearest-neighbour spacing not computable: the coordinates are too "
                     "large for float64 distances (check the file's unit and columns)")
    z = d.get("z_plane_removed")
    if z:
        lines.append(f"z          RMS {z['rms']}, PV {z['pv']} after piston and tilt removal")
    return "\n".join(lines)
