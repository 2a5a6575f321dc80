"""Refuse a measurement that cannot fit in memory *before* reading it (issue 26).

A reader that knows the number of points from the file's header (PLY's ``element vertex N``)
calls ``check_fits`` with it. The model is linear: a run holds about ``BYTES_PER_POINT`` bytes per
point at its peak — the cloud (x, y, z), the input kept for the summary, the residual and a few
full-length columns of the steps (measured with benchmarks/bench_large_map.py: zernike 36 terms +
bspline_map on 1M … 16M points, see benchmarks/README.md) — plus ``BASE_BYTES`` for the interpreter
and libraries. It is compared with the memory available now: /proc/meminfo's MemAvailable (the
kernel's estimate of what can be allocated without swapping), lowered by a cgroup's limit
(memory.max) when the process runs in one (a container, a batch slot), else
os.sysconf's free physical pages. When that cannot be read, nothing is refused.

``POINTSPRO_MEMORY_CHECK=0`` skips the check (a machine whose swap or overcommit the user trusts).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

from ..errors import InputError

#: peak bytes a run holds per point of the input (see module doc). Measured (peak RSS, interpreter
#: included): 96 B/point for zernike 36 + bspline_map at 12.6M points with cloud.x3p, 188 B/point
#: with cloud.csv before the spline's evaluation was chunked; 200 leaves room for steps that hold a
#: few more columns (misalignment's Jacobian, knn_denoise's neighbour tree)
BYTES_PER_POINT = 200
#: the interpreter, numpy/scipy/matplotlib and the steps' fixed working sets (the 150² spline system)
BASE_BYTES = 400 * 2**20


def available_bytes() -> int | None:
    """Bytes that can be allocated now without swapping, or None when unknown."""
    avail = None
    try:
        with open("/proc/meminfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        avail = None
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = None
    limit = _cgroup_room()
    if limit is not None:
        avail = limit if avail is None else min(avail, limit)
    return avail


def _cgroup_room() -> int | None:
    """memory.max − memory.current of this process's cgroup (v2), when it has a limit."""
    try:
        with open("/proc/self/cgroup", encoding="utf-8") as f:
            rel = next((ln.split(":", 2)[2].strip() for ln in f if ln.startswith("0::")), None)
        if rel is None:
            return None
        base = Path("/sys/fs/cgroup") / rel.lstrip("/")
        mx = (base / "memory.max").read_text(encoding="utf-8").strip()
        if mx == "max":
            return None
        cur = int((base / "memory.current").read_text(encoding="utf-8").strip())
        return max(int(mx) - cur, 0)
    except (OSError, ValueError, StopIteration):
        return None


def needed_bytes(npoints: int) -> int:
    return BASE_BYTES + BYTES_PER_POINT * int(npoints)


def _gb(b: float) -> str:
    return f"{b / 1e9:.3g} GB"


def check_fits(path, npoints: int, *, where: str = "header", file_short: bool = False,
               available: int | None = None) -> None:
    """InputError when ``npoints`` (as the file's ``where`` states) cannot be processed in the
    memory available (``available`` bytes, default ``available_bytes()``), naming what helps."""
    if os.environ.get("POINTSPRO_MEMORY_CHECK", "1").strip() == "0":
        return
    avail = available_bytes() if available is None else available
    if avail is None:
        return
    need = needed_bytes(npoints)
    if need <= avail:
        return
    fit = max(int((avail - BASE_BYTES) / BYTES_PER_POINT), 0)
    short = (" (and the file is shorter than that: the header may be damaged)" if file_short else "")
    raise InputError(
        f"{path}: its {where} states {npoints:,} points{short}; processing them needs about "
        f"{_gb(need)} ({BYTES_PER_POINT} bytes a point + {_gb(BASE_BYTES)}) and {_gb(avail)} is "
        f"available — nothing was read. About {fit:,} points fit: decimate the map first (every "
        f"k-th pixel, k ≥ {max(math.ceil(math.sqrt(npoints / max(fit, 1))), 2)} along each axis), "
        "crop it to the aperture of interest, or run on a machine with more memory; "
        "--cloud-format ply (or npz) avoids cloud.csv's text. POINTSPRO_MEMORY_CHECK=0 skips this check")
