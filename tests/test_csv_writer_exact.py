"""cloud.csv's numbers (core.io.formats.write_csv, Arrow's shortest-decimal writer): every float64
reads back bit for bit — specials, subnormals, huge and integral values included — through
read_cloud, pandas and Python's float(); integer channels stay integers; the header keeps units."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.io import read_cloud, write_csv

SPECIAL = [0.0, -0.0, 1e-5, 1e-7, 0.1, 123.0, 1e16, 1e17, 1e21, 1e22, 5e-324, 2.2250738585072014e-308,
           1.7976931348623157e308, -2.5, 123456789012345678.0, 0.30000000000000004, 1 / 3]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_value_reads_back_bit_for_bit(tmp_path, seed):
    rng = np.random.default_rng(seed)
    n = 20_000
    x = rng.uniform(-700, 700, n)
    y = np.round(rng.uniform(-50, 50, n), 3)  # a scanner's 1 µm grid: integral-looking decimals
    z = x * x / 6000 + rng.normal(0, 3e-4, n)
    r = rng.normal(0, 1, n) * 10.0 ** rng.integers(-12, 5, n)  # every magnitude
    r[:len(SPECIAL)] = SPECIAL
    ang = rng.choice([0.0, 90.0, 180.0], n)  # integral floats: written "90", read back as float64
    c = PointCloud.from_xyz(x, y, z, residual=r, angle=ang)
    write_csv(c, tmp_path / "c.csv")
    back = read_cloud(tmp_path / "c.csv")
    for k in ("x", "y", "z", "residual", "angle"):
        a, b = np.asarray(c[k]), np.asarray(back[k])
        assert b.dtype == np.float64
        assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), k  # -0.0 too
    assert np.array_equal(back["index"], c["index"]) and back["index"].dtype.kind == "i"
    lines = (tmp_path / "c.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "x [mm],y [mm],z [mm],index,residual [mm],angle"
    assert len(lines) == n + 1
    # any reader: Python's float() of each field is the same float64
    for line, i in zip(lines[1:200], range(199)):
        f = line.split(",")
        assert float(f[4]) == r[i] and str(f[4]).startswith("-") == bool(np.signbit(r[i]))
        assert int(f[3]) == i


def test_non_finite_values_are_written_as_python_reads_them(tmp_path):
    c = PointCloud.from_xyz(np.arange(3.0), np.zeros(3), np.zeros(3),
                            residual=np.array([np.nan, np.inf, -np.inf]))
    write_csv(c, tmp_path / "c.csv")
    fields = [ln.split(",")[4] for ln in (tmp_path / "c.csv").read_text(encoding="utf-8").splitlines()[1:]]
    assert fields == ["nan", "inf", "-inf"]


def test_the_shortest_decimal_is_written(tmp_path):
    """No padding digits: each value has as few digits as repr's (the file is not 17 digits a value)."""
    rng = np.random.default_rng(5)
    v = rng.normal(0, 1, 2_000) * 10.0 ** rng.integers(-6, 4, 2_000)
    c = PointCloud.from_xyz(v, v, v)
    write_csv(c, tmp_path / "c.csv")
    got = [ln.split(",")[0] for ln in (tmp_path / "c.csv").read_text(encoding="utf-8").splitlines()[1:]]

    def digits(s):
        m = s.lstrip("-").split("e")[0].replace(".", "").lstrip("0")
        return len(m.rstrip("0")) if "e" in s or "." in s else len(m.rstrip("0"))
    assert [digits(g) for g in got] == [digits(repr(float(x))) for x in v]


def test_float32_and_small_integer_channels_keep_their_values(tmp_path):
    """A float32 channel is written as the float64 it widens to; int32/uint8 as integers."""
    rng = np.random.default_rng(9)
    f32 = rng.normal(0, 1e-3, 500).astype(np.float32)
    c = PointCloud.from_xyz(np.arange(500.0), np.zeros(500), np.zeros(500), u=f32,
                            row=np.arange(500, dtype=np.int32), flag=(np.arange(500) % 3).astype(np.uint8))
    write_csv(c, tmp_path / "c.csv")
    back = read_cloud(tmp_path / "c.csv")
    assert np.array_equal(back["u"], f32.astype(np.float64))
    assert np.array_equal(back["row"], np.arange(500)) and np.array_equal(back["flag"], np.arange(500) % 3)


def test_map_csv_reads_back_bit_for_bit(tmp_path):
    from pointspro.core.maps.grid import MapGrid

    rng = np.random.default_rng(4)
    xs, ys = 0.37 * np.arange(31) - 5.0, 0.37 * np.arange(23) + 1.1
    z = rng.normal(0, 1e-4, (23, 31))
    z[rng.random(z.shape) < 0.1] = np.nan  # unmapped nodes are not written
    g = MapGrid(xs, ys, z, 0.37)
    g.write_csv(tmp_path / "map.csv")
    back = read_cloud(tmp_path / "map.csv")
    x, y, zz = g.nodes()
    assert np.array_equal(back.x, x) and np.array_equal(back.y, y) and np.array_equal(back.z, zz)
    assert (tmp_path / "map.csv").read_text(encoding="utf-8").startswith("x [mm],y [mm],z [mm]\n")
