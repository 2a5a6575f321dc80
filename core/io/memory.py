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
#: few more columns (tracemalloc peak above the input: knn_denoise 75 B/point, misalignment 41 —
#: 33 of them its output — since its Jacobian is accumulated by blocks; bspline_map a fixed ~200 MB)
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
    if file_short:  # too many to process, and more than the file holds: the count is the fault
        raise InputError(f"{path}: its {where} states {npoints:,} points, more than the file holds — "
                         "the header is damaged or the file truncated; nothing was read")
    fit = max(int((avail - BASE_BYTES) / BYTES_PER_POINT), 0)
    short = ""
    raise InputError(
        f"{path}: its {where} states {npoints:,} points{short}; processing them needs about "
        f"{_gb(need)} ({BYTES_PER_POINT} bytes a point + {_gb(BASE_BYTES)}) and {_gb(avail)} is "
        f"available — nothing was read. About {fit:,} points fit: decimate the map first (every "
        f"k-th pixel, k ≥ {max(math.ceil(math.sqrt(npoints / max(fit, 1))), 2)} along each axis), "
        "crop it to the aperture of interest, or run on a machine with more memory; "
        "--cloud-format ply (or npz) avoids cloud.csv's text. POINTSPRO_MEMORY_CHECK=0 skips this check")


# -- the number of points a file holds, from its header (or its size), before reading it ----------------
def stated_points(path, head: bytes, is_text: bool) -> tuple[int, str] | None:
    """(points, where that number comes from) for the formats read_cloud knows, from what can be
    had without reading the bulk: a header's counts (LAS/LAZ, E57, X3P's MatrixDimension, MetroPro's
    phase-map size, an NPZ member's array header) or, for text and other binary maps, the file's
    size (an estimate for text: bytes per row of the first rows; a lower bound for binary maps: at
    most 16 bytes a pixel). None: unknown (nothing is refused). PLY checks its own header
    (core.io.ply)."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if head.startswith(b"ply"):
            return None
        if head.startswith(b"LASF"):
            return _las_points(head, p), "LAS header"
        if head.startswith(b"ASTM-E57"):
            n = _e57_points(p)
            return (n, "E57 scan headers") if n is not None else None
        if head.startswith(b"PK\x03\x04"):
            return _zip_points(p)
        if head[:4] in (b"\x88\x1b\x03\x6f", b"\x88\x1b\x03\x70", b"\x88\x1b\x03\x71"):  # MetroPro
            w = int.from_bytes(head[68:70], "big")
            h = int.from_bytes(head[70:72], "big")
            if not (w and h) or 4 * w * h > size:  # 4 bytes a phase pixel: more than the file holds
                return None  # is a damaged header, which the reader names (not a memory advice)
            return w * h, "MetroPro header (phase-map size)"
        if is_text:
            lines = head.splitlines()[1:-1]  # the first (a header?) and the cut last one left out
            rows = [ln for ln in lines if ln.strip() and not ln.lstrip()[:1] in (b"#", b"/", b";")]
            if len(rows) < 5 or len(head) < 4096:
                return None  # a small file: nothing to fear
            per_row = sum(len(r) + 1 for r in rows) / len(rows)
            return int(size / per_row), "size (at the first rows' bytes per row: an estimate)"
        return size // 16, "size (at most 16 bytes a pixel: a lower bound)"
    except Exception:  # a damaged header (bad zip, bad XML …): unknown here; its reader says what is wrong
        return None


def _las_points(head: bytes, path: Path) -> int:
    legacy = int.from_bytes(head[107:111], "little")
    major, minor = head[24], head[25]
    if (major, minor) >= (1, 4) and len(head) >= 255:
        return int.from_bytes(head[247:255], "little") or legacy
    return legacy


def _e57_points(path: Path) -> int | None:
    try:
        import pye57
    except ImportError:
        return None  # read_e57 names the missing extra
    try:
        e = pye57.E57(str(path))
        return sum(int(e.get_header(i).point_count) for i in range(e.scan_count))
    except Exception:  # a damaged file: its reader says what is wrong
        return None


def _zip_points(path: Path) -> tuple[int, str] | None:
    import xml.etree.ElementTree as ET
    import zipfile

    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        if "main.xml" in names:  # X3P: Record3/MatrixDimension
            root = ET.fromstring(zf.read("main.xml"))
            dims = next((el for el in root.iter() if el.tag.split("}")[-1] == "MatrixDimension"), None)
            if dims is None:
                return None
            vals = {c.tag.split("}")[-1]: int(c.text or 1) for c in dims}
            n = vals.get("SizeX", 1) * vals.get("SizeY", 1) * vals.get("SizeZ", 1)
            data = max((zf.getinfo(nm).file_size for nm in names if nm.startswith("bindata/")), default=0)
            if 2 * n > data:  # 2 bytes a point at least (int16): a damaged header, which the reader names
                return None
            return n, "X3P MatrixDimension"
        npy = next((nm for nm in names if nm in ("x.npy", "xyz.npy")), None)
        if npy is None:
            return None
        import numpy as np

        with zf.open(npy) as f:
            version = np.lib.format.read_magic(f)
            read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                    else np.lib.format.read_array_header_2_0)
            shape, _, _ = read(f)
        return int(shape[0]) if shape else 0, "NPZ array header"


def check_stated(path, head: bytes, is_text: bool, *, available: int | None = None) -> None:
    """check_fits with the number of points the file states (``stated_points``), when it states one."""
    got = stated_points(path, head, is_text)
    if got is not None:
        check_fits(path, got[0], where=got[1], available=available)
