"""Reading CMM/profiler exports and writing clouds; every bad input names file, line and column."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pointspro.core import PointCloud
from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud, write_cloud

from .conftest import write


@pytest.mark.parametrize("text,delim", [
    ("x,y,z\n1,2,3\n4,5,6\n", ","),
    ("X;Y;Z\n1;2;3\n4;5;6\n", ";"),
    ("x\ty\tz\n1\t2\t3\n4\t5\t6\n", "\t"),
    ("1 2 3\n4   5 6\n", "whitespace"),
    ("# exported by CMM\n// operator: A\n1, 2, 3\n% mid comment\n4, 5, 6\n", ","),
])
def test_delimiters_headers_comments(tmp_path, text, delim):
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, [[1, 2, 3], [4, 5, 6]])
    assert c.xyz.dtype == np.float64 and c.meta["delimiter"] == delim
    assert np.array_equal(c.index, [0, 1]) and c.meta["frame"] == "measuring"


def test_decimal_comma_preamble_units_and_extra_columns(tmp_path):
    text = ("Instrument: Leitz PMM\nDate: 2020-01-01\nPoint;X [µm];Y [µm];Z [µm];Temp\n"
            "1;1000,5;2000;-3,25;20,1\n2;0;0;0;20,2\n")
    c = read_cloud(write(tmp_path / "m.txt", text))
    assert np.allclose(c.xyz, [[1.0005, 2.0, -0.00325], [0, 0, 0]])
    assert np.array_equal(c["point"], [1, 2]) and np.allclose(c["temp"], [20.1, 20.2])
    assert c.meta["channel_units"] == {}
    # decimal comma with spaces
    c2 = read_cloud(write(tmp_path / "m2.xyz", "1,5 2,5 3,5\n4,0 5,0 6,0\n"))
    assert np.allclose(c2.xyz, [[1.5, 2.5, 3.5], [4, 5, 6]])


def test_headerless_extra_columns_and_index_column(tmp_path):
    c = read_cloud(write(tmp_path / "m.dat", "1 2 3 7 8\n4 5 6 9 10\n"))
    assert set(c.channels) == {"index", "col4", "col5"}
    c2 = read_cloud(write(tmp_path / "m.csv", "x,y,z,index,residual\n1,2,3,17,0.5\n4,5,6,3,0.25\n"))
    assert np.array_equal(c2.index, [17, 3]) and c2.index.dtype == np.int64


@pytest.mark.parametrize("text,pattern", [
    ("", r"m.csv: empty file — no data rows"),
    ("# only a comment\n\n", r"m.csv: empty file — no data rows"),
    ("x,y,z\n", r"m.csv: no numeric data rows found \(first line 1"),
    ("x,y,z\n1,2,3\n4,abc,6\n", r"m.csv, line 3, column 2: 'abc' is not a number"),
    ("x,y,z\n1,2,3\n4,5\n", r"m.csv, line 3: 2 column\(s\), expected 3 as on line 2"),
    ("x,y,z\n1,2,3\n4,nan,6\n", r"m.csv, line 3, column 2 \(y\): nan is not a finite number"),
    ("x,y,z\n1,2,3\n# c\n4,5,inf\n", r"m.csv, line 4, column 3 \(z\): inf is not a finite number"),
    ("a,b,c\n1,2,3\n", r"m.csv, line 1: no x/y/z column in the header \(columns: a, b, c\)"),
    ("x,y,q\n1,2,3\n", r"m.csv, line 1: no z column"),
    ("1,2\n1,4\n", r"m.csv, line 2: x = 1 mm repeats line 1's — a profile holds one height"),  # x, z
    ("x,z\n1,2\n", r"m.csv: a profile of 1 point"),
    ("7\n8\n", r"m.csv, line 1: 1 column\(s\); need at least x, y, z"),
    ("x [furlong],y,z\n1,2,3\n", r"unknown unit \[furlong\] for x"),
    ("x,y,z,x\n1,2,3,4\n", r"duplicate column name"),
    # a header naming the axes over a different number of values: never read without it
    ("x,y,z\n1,2\n", r"m.csv, line 1: the header names 3 columns \(x, y, z\) but line 2 holds 2 value"),
    ("y,x,z\n1,2,3,4\n5,6,7,8\n", r"line 1: the header names 3 columns \(y, x, z\) but line 2 holds 4"),
    ("# run 7\nX;Y;Z;I\n1;2;3\n", r"line 2: the header names 4 columns \(X, Y, Z, I\) but line 3 holds 3"),
])
def test_bad_text_inputs_name_the_place(tmp_path, text, pattern):
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", text), invalid="error")


def test_nan_rows_dropped_and_counted_by_default(tmp_path):
    p = write(tmp_path / "m.csv", "x,y,z,t\n1,2,3,0.5\n4,nan,6,0.5\n# c\n7,8,inf,0.5\n9,9,9,nan\n"
              "10,11,12,0.25\n")
    c = read_cloud(p)
    assert np.array_equal(c.xyz, [[1, 2, 3], [10, 11, 12]]) and np.allclose(c["t"], [0.5, 0.25])
    assert c.meta["invalid_dropped"] == 3
    assert np.array_equal(c.index, [0, 4])  # the data row of the input, gaps where rows were dropped
    assert read_cloud(write(tmp_path / "ok.csv", "1 2 3\n4 5 6\n")).meta["invalid_dropped"] == 0
    with pytest.raises(InputError, match=r"m.csv, line 3, column 2 \(y\): nan is not a finite"):
        read_cloud(p, invalid="error")
    with pytest.raises(InputError, match=r"all.csv, line 1, column 1 \(x\): every data row holds a "
                                         r"NaN/inf value"):
        read_cloud(write(tmp_path / "all.csv", "nan 1 2\n3 inf 4\n"))


@pytest.mark.parametrize("options,pattern", [
    ({"invalid": "skip"}, r"m.csv: key 'invalid': drop or error \(got 'skip'\)"),
    ({"pixel_size": 1}, r"m.csv: unknown reader option 'pixel_size' \(options: pixel_size_um, "),
    ({"pixel_size_um": -1}, r"m.csv: key 'pixel_size_um': a positive number"),
    ({"pixel_size_um": [1, 2, 3]}, r"key 'pixel_size_um'"),
    ({"wavelength_nm": "red"}, r"key 'wavelength_nm': a positive number"),
    ({"height_unit": "furlong"}, r"key 'height_unit': one of nm, µm, mm, m"),
])
def test_reader_options_are_validated_by_name(tmp_path, options, pattern):
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", "1 2 3\n"), **options)


def test_missing_folder_and_unknown_type(tmp_path):
    with pytest.raises(InputError, match="nope.csv: file not found"):
        read_cloud(tmp_path / "nope.csv")
    with pytest.raises(InputError, match="is a folder"):
        read_cloud(tmp_path)
    # the content decides, not the name: x y z text is read whatever its extension
    assert read_cloud(write(tmp_path / "m.stp", "1 2 3\n")).n == 1
    with pytest.raises(InputError, match=r"part.stp: a STEP CAD file, not a measurement file"):
        read_cloud(write(tmp_path / "part.stp", "ISO-10303-21;\nHEADER;\nENDSEC;\n"))
    (tmp_path / "blob.xyz2").write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match=r"blob.xyz2: unknown file type '.xyz2' — no reader "
                                         r"recognises its content"):
        read_cloud(tmp_path / "blob.xyz2")


def _cloud(n=50, seed=0):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-650, 650, (n, 3)) + rng.normal(0, 1e-7, (n, 3))
    return PointCloud(xyz, {"residual": rng.normal(0, 1e-3, n), "line": rng.integers(0, 9, n),
                            "index": np.arange(n) * 2 + 5})


@pytest.mark.parametrize("suffix", [".csv", ".ply"])
def test_write_read_round_trip_is_bit_exact(tmp_path, suffix):
    c = _cloud()
    p = tmp_path / f"c{suffix}"
    write_cloud(c, p)
    back = read_cloud(p)
    assert back.equals(c)
    assert not list(tmp_path.glob("*.partial"))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)] * 3),
                min_size=1, max_size=30))
def test_csv_round_trip_property(tmp_path_factory, rows):
    c = PointCloud(np.array(rows, dtype=np.float64))
    p = tmp_path_factory.mktemp("rt") / "c.csv"
    write_cloud(c, p)
    assert read_cloud(p).equals(c)


def test_open3d_formats(tmp_path):
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array([[1.0, 2, 3], [4, 5, 6]])))
    pc.normals = o3d.utility.Vector3dVector(np.array([[0.0, 0, 1], [0, 0, 1]]))
    p = tmp_path / "c.pcd"
    assert o3d.io.write_point_cloud(str(p), pc)
    c = read_cloud(p)
    assert np.allclose(c.xyz, [[1, 2, 3], [4, 5, 6]]) and np.allclose(c["nz"], 1)
    pts = write(tmp_path / "c.pts", "2\n1 2 3\n4 5 6\n")
    assert np.allclose(read_cloud(pts).xyz, [[1, 2, 3], [4, 5, 6]])
    bad = write(tmp_path / "bad.pcd", "garbage\n")
    with pytest.raises(InputError, match="bad.pcd: no points read"):
        read_cloud(bad)


def test_ply_ascii_and_truncated(tmp_path):
    p = write(tmp_path / "a.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\n"
              "property double y\nproperty double z\nproperty float quality\nend_header\n"
              "1 2 3 0.5\n4 5 6 0.25\n")
    c = read_cloud(p)
    assert np.allclose(c.xyz, [[1, 2, 3], [4, 5, 6]]) and np.allclose(c["quality"], [0.5, 0.25])
    good = tmp_path / "b.ply"
    write_cloud(_cloud(), good)
    data = good.read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-10])
    with pytest.raises(InputError, match="truncated"):
        read_cloud(tmp_path / "t.ply")


def test_cloud_is_immutable_and_index_survives_selection():
    c = _cloud(10)
    with pytest.raises(ValueError):
        c.xyz[0, 0] = 1.0
    with pytest.raises(ValueError):
        c["residual"][0] = 1.0
    s = c.select(np.array([True, False] * 5))
    assert np.array_equal(s.index, c.index[::2])
    with pytest.raises(ValueError, match="shape"):
        PointCloud(np.zeros((3, 3)), {"residual": np.zeros(2)})


def test_damaged_first_data_line_is_not_taken_for_a_header(tmp_path):
    with pytest.raises(InputError, match=r"m.csv, line 2, column 2: '2x' is not a number"):
        read_cloud(write(tmp_path / "m.csv", "# export\n1,2x,3\n4,5,6\n7,8,9\n"))


def test_a_title_line_is_not_taken_for_a_short_header(tmp_path):
    """A title with commas above headerless data names no axes: the data read as x, y, z."""
    c = read_cloud(write(tmp_path / "t.csv", "Part 7, run 3\n1,2,3\n4,5,6\n"))
    assert np.array_equal(c.xyz, [[1, 2, 3], [4, 5, 6]])
