"""A measurement too large for the memory available is refused *before* its bulk is read, whatever
its format (core.io.memory.stated_points; issue 26): one InputError naming the file, the number of
points its header (or size) states and what helps; accepted with POINTSPRO_MEMORY_CHECK=0 and when
memory suffices."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import InputError
from pointspro.core.io import memory, read_cloud

REAL = Path(__file__).parent / "data" / "realdata"


def _csv(path: Path, n=3000):
    rng = np.random.default_rng(1)
    xyz = rng.uniform(-10, 10, (n, 3))
    np.savetxt(path, xyz, fmt="%.9f", delimiter=",", header="x,y,z", comments="")
    return n


def _npz(path: Path, n=500):
    from pointspro.core.io.npz import write_npz_cloud

    g = np.linspace(0, 1, n)
    write_npz_cloud(PointCloud.from_xyz(g, g, g), path)
    return n


def _x3p(path: Path, n=40):
    from pointspro.core.maps.grid import MapGrid

    xs = np.arange(n) * 0.1
    ys = np.arange(n - 5) * 0.1
    z = np.outer(np.ones(n - 5), xs) * 1e-4
    MapGrid(xs, ys, z, 0.1).write_x3p(path)
    return n * (n - 5)


def _las(path: Path, n=300):
    laspy = pytest.importorskip("laspy")
    h = laspy.LasHeader(point_format=3, version="1.2")
    h.scales = np.array([1e-4, 1e-4, 1e-5])
    las = laspy.LasData(h)
    rng = np.random.default_rng(2)
    las.x, las.y, las.z = rng.uniform(0, 1, n), rng.uniform(0, 1, n), rng.uniform(0, 0.1, n)
    las.write(str(path))
    return n


def _e57(path: Path, n=250):
    pye57 = pytest.importorskip("pye57")
    rng = np.random.default_rng(3)
    with pye57.E57(str(path), mode="w") as e:
        for m in (n, 50):
            e.write_scan_raw({"cartesianX": rng.random(m), "cartesianY": rng.random(m),
                              "cartesianZ": rng.random(m)})
    return n + 50


def _metropro(path: Path):
    shutil.copy(REAL / "metropro-1.dat", path)
    return 640 * 480


def _sur(path: Path):
    shutil.copy(REAL / "sur-2.sur", path)
    return None  # binary map: a lower bound from the size


MAKERS = {"c.csv": _csv, "c.npz": _npz, "m.x3p": _x3p, "s.las": _las, "s.e57": _e57, "m.dat": _metropro,
          "m.sur": _sur}


@pytest.mark.parametrize("name", sorted(MAKERS))
def test_too_large_is_refused_before_reading(tmp_path, monkeypatch, name):
    path = tmp_path / name
    n = MAKERS[name](path)
    got = memory.stated_points(path, *_sniffed(path))
    assert got is not None
    if n is not None and name.endswith(".csv"):  # text: an estimate from the first rows
        assert abs(got[0] - n) <= 0.05 * n, got
    elif n is not None:
        assert got[0] == n, got
    else:
        assert 0 < got[0] <= path.stat().st_size  # a lower bound from the size
    before = path.read_bytes()
    monkeypatch.setattr(memory, "available_bytes", lambda: 10_000)  # far below any run's need
    _forbid_bulk_reads(monkeypatch)
    with pytest.raises(InputError) as e:
        read_cloud(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: its ") and f"{got[0]:,} points" in msg and "nothing was read" in msg
    assert "decimate" in msg and "POINTSPRO_MEMORY_CHECK=0" in msg and "\n" not in msg
    assert path.read_bytes() == before
    monkeypatch.setenv("POINTSPRO_MEMORY_CHECK", "0")  # the check skipped: the reader is reached
    with pytest.raises(AssertionError, match="bulk read"):
        read_cloud(path)


@pytest.mark.parametrize("name", sorted(MAKERS))
def test_files_that_fit_are_read(tmp_path, name):
    path = tmp_path / name
    MAKERS[name](path)
    assert read_cloud(path).n > 0


def _sniffed(path):
    from pointspro.core.io.formats import _sniff

    return _sniff(path)


def _forbid_bulk_reads(monkeypatch):
    """Every reader behind read_cloud fails if called: the refusal must come first."""
    def boom(*a, **k):
        raise AssertionError("bulk read")

    from pointspro.core.io import formats, instruments, las, metropro, npz, text

    for mod, name in ((instruments, "read_x3p"), (instruments, "read_surface_topography"),
                      (npz, "read_npz"), (las, "read_las"), (metropro, "read_metropro"),
                      (formats, "_read_text_by_content"), (text, "read_text")):
        monkeypatch.setattr(mod, name, boom)
    try:
        from pointspro.core.io import e57
        monkeypatch.setattr(e57, "read_e57", boom)
    except ImportError:
        pass


@pytest.mark.parametrize("name", ["m.dat", "m.x3p"])
def test_a_header_stating_more_than_the_file_holds_is_no_memory_advice(tmp_path, monkeypatch, name):
    """A 5 KB MetroPro of random bytes was told it "needs 158 GB — decimate the map first": a header
    that states more points than the file's bytes can hold is damaged, and its reader says so."""
    path = tmp_path / name
    MAKERS[name](path)
    if name == "m.dat":
        path.write_bytes(path.read_bytes()[:5000])  # the header says 640 × 480, 5 KB are left
    else:
        import zipfile

        with zipfile.ZipFile(path) as zf:
            members = {nm: zf.read(nm) for nm in zf.namelist()}
        members["main.xml"] = members["main.xml"].replace(b"<SizeX>40</SizeX>", b"<SizeX>6400000</SizeX>")
        with zipfile.ZipFile(path, "w") as zf:
            for nm, data in members.items():
                zf.writestr(nm, data)
    assert memory.stated_points(path, *_sniffed(path)) is None
    monkeypatch.setattr(memory, "available_bytes", lambda: 10_000)
    with pytest.raises(InputError) as e:
        read_cloud(path)
    assert "decimate" not in str(e.value) and str(e.value).startswith(str(path))
