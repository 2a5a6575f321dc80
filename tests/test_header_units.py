"""Units in the headers of the CSV files PointsPro writes and reads (docs/formats.md, "Units in
headers"): written ``x [mm]`` …, read back bit for bit; a length unit on input (``residual [nm]``) is
converted to mm in one correctly rounded operation; CloudCompare's ``//X Y Z`` header line."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud, write_cloud
from pointspro.core.io.text import read_table
from pointspro.core.maps.grid import MapGrid
from pointspro.core.metrics.profiles import profile, psd_1d
from pointspro.core.units import channel_unit, length_to_mm

from .conftest import write


def _cloud(n=500, seed=7):
    rng = np.random.default_rng(seed)
    xyz = rng.normal(scale=[50.0, 50.0, 1e-3], size=(n, 3)) * rng.choice([1e-9, 1.0, 1e6], size=(n, 3))
    return PointCloud(xyz, {"residual": rng.normal(scale=1e-6, size=n), "omega": rng.random(n) * 1e-4,
                            "t": np.cumsum(rng.random(n)), "row": np.arange(n) % 13,
                            "fiducial": np.arange(n) % 5, "index": np.arange(n) * 3 + 1},
                      {"channel_units": {"t": "s", "row": "mm"}})


def _grid(seed=3):
    rng = np.random.default_rng(seed)
    xs = np.arange(-10, 11) * 0.7
    ys = np.arange(-8, 9) * 0.7
    X, Y = np.meshgrid(xs, ys)
    z = 1e-4 * (X**2 - 0.5 * Y**2) / 49 + rng.normal(scale=1e-7, size=X.shape)
    z[np.hypot(X, Y) > 6.5] = np.nan
    return MapGrid(xs, ys, z, 0.7)


def test_cloud_csv_states_units_and_reads_back_bit_exact(tmp_path):
    c = _cloud()
    write_cloud(c, tmp_path / "cloud.csv")
    header = (tmp_path / "cloud.csv").read_text(encoding="utf-8").split("\n", 1)[0]
    assert header.split(",") == ["x [mm]", "y [mm]", "z [mm]", "index", "residual [mm]", "omega [mm]",
                                 "t [s]", "row", "fiducial"]
    back = read_cloud(tmp_path / "cloud.csv")
    assert back.equals(c)  # every array identical, float64 bit for bit
    assert back.xyz.dtype == np.float64 and back["residual"].dtype == np.float64
    assert back.meta["channel_units"] == {"residual": "mm", "omega": "mm", "t": "s"}


def test_stated_units_of_x_y_z_are_kept_for_the_report(tmp_path):
    """x, y, z in µm are read as mm; the unit the file stated them in was lost (docs/formats.md said
    channel_units held it): now meta["xyz_units_stated"], listed in report.json's input_file."""
    from pointspro.core.report import input_description

    p = tmp_path / "u.csv"
    p.write_text("X [µm],Y [µm],Z [µm],residual [nm]\n0,0,0,1\n1000,0,1,2\n0,1000,2,3\n", encoding="utf-8")
    c = read_cloud(p)
    assert c.xyz[1, 0] == 1.0 and c.meta["channel_units"] == {"residual": "nm"}
    assert c.meta["xyz_units_stated"] == {"x": "µm", "y": "µm", "z": "µm"}
    assert input_description(c)["xyz_units_stated"] == {"x": "µm", "y": "µm", "z": "µm"}
    write_cloud(c, tmp_path / "out.csv")  # the written cloud states mm, as its numbers are
    assert (tmp_path / "out.csv").read_text(encoding="utf-8").startswith("x [mm],y [mm],z [mm]")


def test_map_csv_round_trip(tmp_path):
    g = _grid()
    g.write_csv(tmp_path / "map.csv")
    assert (tmp_path / "map.csv").read_text(encoding="utf-8").startswith("x [mm],y [mm],z [mm]\n")
    back = read_cloud(tmp_path / "map.csv")
    x, y, z = g.nodes()
    assert np.array_equal(back.xyz, np.column_stack([x, y, z]))


def test_profiles_and_psd_csv_round_trip(tmp_path):
    from pointspro.plugins.bspline_map import _write_profiles, _write_psd

    g = _grid()
    _write_profiles(tmp_path / "profiles.csv", g, (0.0, 45.0, 90.0), (0.35, 0.0))
    assert (tmp_path / "profiles.csv").read_text(encoding="utf-8").startswith(
        "angle [deg],s [mm],x [mm],y [mm],z [mm]\n")
    back = read_cloud(tmp_path / "profiles.csv")  # rows outside the map (z NaN) are dropped
    assert back.meta["channel_units"] == {"angle": "deg", "s": "mm"}
    for a in (0.0, 45.0, 90.0):
        s, z = profile(g, a, (0.35, 0.0))
        ok = np.isfinite(z)
        mine = back["angle"] == a
        assert np.array_equal(back["s"][mine], s[ok]) and np.array_equal(back.z[mine], z[ok])
        t = np.deg2rad(a)
        if a == 90.0:  # exactly the centre's x, and y the nodes' own (a review: x read 0.35 − 3.9e-14)
            assert np.all(back.x[mine] == 0.35) and np.all(back.y[mine] == s[ok])
        else:
            assert np.array_equal(back.x[mine], 0.35 + s[ok] * np.cos(t))
    _write_psd(tmp_path / "psd.csv", g)
    text = (tmp_path / "psd.csv").read_text(encoding="utf-8")
    assert text.startswith("f_x [1/mm],psd_x [mm^3],f_y [1/mm],psd_y [mm^3]\n")
    cols = np.genfromtxt(tmp_path / "psd.csv", delimiter=",", skip_header=1).T  # empty fields: NaN
    fx, px = psd_1d(g, "x")
    fy, py = psd_1d(g, "y")
    assert len(fx) != len(fy)  # a non-square map: each direction against its own frequencies
    for f, p, cf, cp in ((fx, px, cols[0], cols[1]), (fy, py, cols[2], cols[3])):
        assert np.array_equal(cf[:len(f)], f) and np.array_equal(cp[:len(p)], p)
        assert np.isnan(cf[len(f):]).all() and np.isnan(cp[len(p):]).all()


def test_length_units_on_input_are_converted_to_mm(tmp_path):
    p = write(tmp_path / "m.csv", "X [µm],Y [um],Z [nm],residual [nm],dev (m),t [s],row [mm],w\n"
                                  "1234,-5,250,1234,0.001,0.5,3,7\n2000.5,0,0,-3,2,1.5,4,8\n")
    c = read_cloud(p)
    assert np.array_equal(c.xyz, [[1.234, -0.005, 0.00025], [2.0005, 0.0, 0.0]])
    assert np.array_equal(c["residual"], [0.001234, -0.000003])  # one division: correctly rounded
    assert np.array_equal(c["dev"], [1.0, 2000.0])
    assert np.array_equal(c["t"], [0.5, 1.5]) and np.array_equal(c["row"], [3, 4])  # not lengths
    assert np.array_equal(c["w"], [7, 8])
    assert c.meta["channel_units"] == {"residual": "nm", "dev": "m", "t": "s", "row": "mm"}
    # a written file then states mm (or the unit kept as read) and reads back the same
    write_cloud(c, tmp_path / "out.csv")
    assert (tmp_path / "out.csv").read_text(encoding="utf-8").startswith(
        "x [mm],y [mm],z [mm],index,residual [mm],dev [mm],t [s],row,w\n")
    assert read_cloud(tmp_path / "out.csv").equals(c)


def test_files_without_units_read_as_before(tmp_path):
    c = read_cloud(write(tmp_path / "m.csv", "x,y,z,residual,t\n1.5,2,3,0.25,9\n4,5,6,-0.125,10\n"))
    assert np.array_equal(c.xyz, [[1.5, 2, 3], [4, 5, 6]]) and np.array_equal(c["residual"], [0.25, -0.125])
    assert c.meta["channel_units"] == {}
    assert channel_unit("t") is None and channel_unit("residual") == "mm"


def test_parameter_tables_convert_length_columns(tmp_path):
    cols = read_table(write(tmp_path / "cal.csv", "t [s],xd [µm],ref\n0,1000,1\n0.1,2500,2\n"),
                      ("t", "xd", "ref"))
    assert np.array_equal(cols["t"], [0, 0.1]) and np.array_equal(cols["xd"], [1.0, 2.5])


def test_length_to_mm_is_one_correctly_rounded_operation():
    from fractions import Fraction

    rng = np.random.default_rng(0)
    v = np.round(rng.uniform(-1e5, 1e5, 2000), 3)
    exact = np.array([float(Fraction(x) / 1000) for x in v.tolist()])  # the float nearest v/1000
    assert np.array_equal(length_to_mm(v, "µm"), exact)
    assert not np.array_equal(v * 1e-3, exact)  # what a multiplication by 1e-3 would not give
    k = rng.integers(-10**9, 10**9, 2000).astype(np.float64)  # whole µm: same as the value in mm
    assert np.array_equal(length_to_mm(k, "um"), np.array([float(f"{int(x)}e-3") for x in k]))
    assert np.array_equal(length_to_mm(k, "nm"), np.array([float(f"{int(x)}e-6") for x in k]))
    assert length_to_mm(v, "mm") is not None and np.array_equal(length_to_mm(v, "mm"), v)
    assert np.array_equal(length_to_mm(v, "m"), v * 1e3)
    with pytest.raises(KeyError):
        length_to_mm(v, "s")


def test_unknown_unit_for_xyz_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"line 1: unknown unit \[furlong\] for x; known: .*µm"):
        read_cloud(write(tmp_path / "m.csv", "x [furlong],y,z\n1,2,3\n"))


@pytest.mark.parametrize("text,names", [
    ("//X Y Z SF\n1 2 3 0.5\n4 5 6 0.25\n", ["sf"]),
    ("//X,Y,Z,R,G,B,Scalar field\n1,2,3,255,0,10,0.5\n4,5,6,0,128,20,0.25\n",
     ["r", "g", "b", "scalar_field"]),
    ("//X Y Z Scalar field\n1 2 3 0.5\n4 5 6 0.25\n", ["scalar_field"]),
    ("// CloudCompare export\n//X;Y;Z;Nx;Ny;Nz\n1;2;3;0;0;1\n4;5;6;0;1;0\n", ["nx", "ny", "nz"]),
])
def test_cloudcompare_header_names_the_columns(tmp_path, text, names):
    c = read_cloud(write(tmp_path / "cc.txt", text))
    assert np.array_equal(c.xyz, [[1, 2, 3], [4, 5, 6]])
    assert sorted(c.channels) == sorted(["index", *names])
    assert c.meta["header_line"] == text.count("\n", 0, text.index("//X")) + 1


def test_cloudcompare_header_with_columns_in_another_order(tmp_path):
    c = read_cloud(write(tmp_path / "cc.asc", "//Z,X,Y\n3,1,2\n"))
    assert np.array_equal(c.xyz, [[1, 2, 3]])


def test_other_double_slash_comments_stay_comments(tmp_path):
    c = read_cloud(write(tmp_path / "m.txt", "// operator: A\n// x y\n1 2 3 4\n"))
    assert np.array_equal(c.xyz, [[1, 2, 3]]) and set(c.channels) == {"index", "col4"}
