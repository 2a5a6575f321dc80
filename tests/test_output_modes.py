"""Files and folders PointsPro writes get the modes of any other tool's output (0o666 / 0o777 less the
umask), not the private 0600 / 0700 of a temporary file (core/io/atomic.py)."""
from __future__ import annotations

import os
import stat
import sys

import pytest

from pointspro.core import PointCloud
from pointspro.core.io import atomic_dir, atomic_path, write_cloud

from .conftest import write

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX modes")


@pytest.fixture
def umask():
    """Set the process umask for one test and restore the old one."""
    old = os.umask(0o022)

    def set_(mask: int) -> None:
        os.umask(mask)

    yield set_
    os.umask(old)


def _mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o002], ids=oct)
def test_atomic_file_and_folder_follow_the_umask(tmp_path, umask, mask):
    umask(mask)
    with atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("1\n", encoding="utf-8")
    assert _mode(tmp_path / "a.txt") == 0o666 & ~mask
    with atomic_dir(tmp_path / "d") as tmp:
        (tmp / "f.txt").write_text("1\n", encoding="utf-8")
    assert _mode(tmp_path / "d") == 0o777 & ~mask
    # replacing an existing folder keeps the modes too
    with atomic_dir(tmp_path / "d") as tmp:
        (tmp / "g.txt").write_text("2\n", encoding="utf-8")
    assert _mode(tmp_path / "d") == 0o777 & ~mask
    assert [p.name for p in (tmp_path / "d").iterdir()] == ["g.txt"]
    assert not list(tmp_path.glob(".*"))


def test_written_cloud_is_0644_under_umask_022(tmp_path, umask):
    c = PointCloud.from_xyz([0.0, 1.0], [0.0, 2.0], [0.5, 0.25])
    for name in ("c.csv", "c.ply"):
        write_cloud(c, tmp_path / name)
        assert _mode(tmp_path / name) == 0o644, name


def test_batch_output_folder_is_0755_and_its_files_0644(run_cli, tmp_path, umask):
    data = write(tmp_path / "part.csv", "x,y,z\n" + "".join(
        f"{i % 7},{i // 7},{0.001 * ((i * 37) % 11)}\n" for i in range(49)))
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - manual_edit: {remove: [1]}\n")
    code, out, err = run_cli("--batch", recipe, data, "--out", tmp_path / "o")
    assert code == 0, err
    folder = tmp_path / "o" / "part"
    assert (folder / "cloud.csv").is_file()
    found = [tmp_path / "o", *(tmp_path / "o").rglob("*")]
    assert len(found) > 3
    for p in found:
        want = 0o755 if p.is_dir() else 0o644
        assert _mode(p) == want, f"{p.relative_to(tmp_path)}: {oct(_mode(p))}"
