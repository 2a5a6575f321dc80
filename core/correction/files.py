"""Writers of the correction's files: grid CSVs with a stated sign convention, the radial table.

Grid CSVs have ``#`` comment lines first (the sign convention, the process, the filter), then the
header with units, then one row per valid node, y-major (row by row from the lowest y) — the same
order as map.csv. x and y are written in fixed point with 12 decimals (formatted once per column
and row): a node k × spacing from a decimal origin reads as its decimal (-2.8, not Python's
-2.8000000000000003 — a review: 41,524 of 114,418 coordinates so, which fixed-width and G-code
post-processors choke on); the value in fixed point with ``decimals`` places (12 in mm: 1 fm, far
below anything a machine or a measurement resolves), trailing zeros dropped. The radial table
(correction_radial.csv) writes both r and dz that way. The rows are assembled
as one byte matrix in numpy, so a 1001 × 1001 grid is written in a fraction of a second.
"""
from __future__ import annotations

import numpy as np


def _comment(lines) -> str:
    return "".join(f"# {ln}\n" for ln in lines)


#: the 1000 three-digit groups "000" … "999" as ASCII digits
_TRIPLES = np.array([[48 + i // 100, 48 + (i // 10) % 10, 48 + i % 10] for i in range(1000)], np.uint8)


def _digits(n: np.ndarray, width: int) -> np.ndarray:
    """(N, width) ASCII decimal digits of non-negative integers, most significant first: three
    digits at a time from a table (a few scalar divisions instead of one per digit)."""
    groups = -(-width // 3)
    out = np.empty((n.size, 3 * groups), np.uint8)
    m = n.copy()
    for k in range(groups - 1, -1, -1):
        m, g = np.divmod(m, 1000)
        out[:, 3 * k:3 * k + 3] = _TRIPLES[g]
    return out[:, 3 * groups - width:]


def fixed_point_bytes(v, decimals: int) -> np.ndarray:
    """(N, width) uint8 of each value in fixed point (``-12.345``), zero bytes where a shorter number
    leaves room (removed when the rows are joined); trailing zeros of the fraction dropped."""
    v = np.asarray(v, dtype=np.float64)
    scale = 10 ** decimals
    if v.size and np.max(np.abs(v)) * scale >= 9e18:
        raise ValueError("value too large for fixed-point output")
    n = np.rint(np.abs(v) * scale).astype(np.int64)
    neg = (v < 0) & (n > 0)
    ip, fp = np.divmod(n, scale)
    wi = max(1, int(np.max(ip, initial=0)).bit_length() // 3 + 2)
    idig = _digits(ip, wi)
    nd = np.ones(ip.shape, np.int64)  # digits of the integer part (at least the units)
    for k in range(1, wi):
        nd += ip >= 10 ** k
    lead = np.arange(wi)[None, :] < (wi - nd)[:, None]
    ib = np.where(lead, np.uint8(0), idig)
    fdig = _digits(fp, decimals)
    # trailing zeros of the fraction dropped, one decimal kept: the digits after the last non-zero
    # one (read from the digit bytes, not by `decimals` integer remainders over the whole column)
    keep = np.maximum(decimals - np.argmax(fdig[:, ::-1] != ord("0"), axis=1), 1)
    keep[fp == 0] = 1
    trail = np.arange(decimals)[None, :] >= keep[:, None]
    fb = np.where(trail, np.uint8(0), fdig)
    sign = np.where(neg, ord("-"), 0).astype(np.uint8)[:, None]
    dot = np.full((v.size, 1), ord("."), np.uint8)
    return np.concatenate([sign, ib, dot, fb], axis=1)


def write_grid_csv(path, xs, ys, Z, header: str, comments=(), scale: float = 1.0,
                   decimals: int = 12) -> None:
    """x, y and Z·scale (fixed point, ``decimals`` places) of the finite nodes of Z
    ((len(ys), len(xs))), y-major."""
    ok = np.isfinite(Z)
    iy, ix = np.nonzero(ok)
    comma = np.full((iy.size, 1), ord(","), np.uint8)
    nl = np.full((iy.size, 1), ord("\n"), np.uint8)
    M = np.concatenate([fixed_point_bytes(xs, 12)[ix], comma, fixed_point_bytes(ys, 12)[iy], comma,
                        fixed_point_bytes(Z[ok] * scale, decimals), nl], axis=1)
    with open(path, "wb") as f:
        f.write((_comment(comments) + header).encode("utf-8"))
        f.write(M[M != 0].tobytes())


def write_radial_csv(path, r, dz, comments=()) -> None:
    """r and dz (mm) in fixed point, 12 decimals, as the grid files' values: r = k × spacing is
    written as its decimal (1.2, not 1.2000000000000002 — exact for a decimal spacing)."""
    r = np.asarray(r, dtype=np.float64)
    comma = np.full((r.size, 1), ord(","), np.uint8)
    nl = np.full((r.size, 1), ord("\n"), np.uint8)
    M = np.concatenate([fixed_point_bytes(r, 12), comma, fixed_point_bytes(dz, 12), nl], axis=1)
    with open(path, "wb") as f:
        f.write((_comment(comments) + "r [mm],dz [mm]\n").encode("utf-8"))
        f.write(M[M != 0].tobytes())


def read_comment_csv(path):
    """(comment lines, header, (N, k) array) of a file written here (tests, the window's preview)."""
    comments, rows, header = [], [], None
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("#"):
                comments.append(line[1:].strip())
            elif header is None:
                header = line.strip()
            else:
                rows.append(line)
    data = np.loadtxt(rows, delimiter=",", ndmin=2) if rows else np.zeros((0, 0))
    return comments, header, data
