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


@pytest.mark.parametrize("text,xyz", [
    ("y;x;z\n1,2,3\n4,5,6\n", [[2, 1, 3], [5, 4, 6]]),
    ("y x z\n1,2,3\n4,5,6\n", [[2, 1, 3], [5, 4, 6]]),
    ("y,x,z\n1 2 3\n4 5 6\n", [[2, 1, 3], [5, 4, 6]]),
    ("y x z\n1\t2\t3\n4\t5\t6\n", [[2, 1, 3], [5, 4, 6]]),  # a space-separated header, tab data
    ("x [um] y [um] z [um]\n1000,2000,3\n4000,5000,6\n", [[1, 2, 0.003], [4, 5, 0.006]]),
    ("x[um] y (um) z (mm)\n1000\t2000\t3\n4000\t5000\t6\n", [[1, 2, 3], [4, 5, 6]]),
    ("Part 7, run 3\ny x z\n1\t2\t3\n4\t5\t6\n", [[2, 1, 3], [5, 4, 6]]),
])
def test_header_with_another_separator_than_the_data_is_read(tmp_path, text, xyz):
    """Ignored, such a header swapped x and y or read µm as mm."""
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, xyz) and c.xyz.dtype == np.float64
    assert c.meta["header_line"] == text.count("\n", 0, text.index("z")) + 1


@pytest.mark.parametrize("text,pattern", [
    ("x y z w\n1,2,3\n4,5,6\n", r"m.csv, line 1: the header names 4 columns \(x, y, z, w\) but line 2 "
                                r"holds 3 value"),
    ("y;x;z\n1,2,3,4\n5,6,7,8\n", r"m.csv, line 1: the header names 3 columns \(y, x, z\) but line 2 "
                                  r"holds 4 value"),
])
def test_header_with_another_separator_and_count_is_refused(tmp_path, text, pattern):
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", text))


@pytest.mark.parametrize("text,pattern", [
    ("y,x,z\n---\n4,5,6\n7,8,9\n", r"m.csv, line 2: a line that is neither numbers nor a comment "
                                   r"stands between the header \(line 1\) and the data \(line 3\)"),
    ("y,x,z\nunits: mm\n4,5,6\n7,8,9\n", r"m.csv, line 2: .* between the header \(line 1\) and "
                                         r"the data \(line 3\)"),
    ("x [um],y [um],z [um]\n-----\n1000,2000,3\n4000,5000,6\n",
     r"m.csv, line 2: .* between the header \(line 1\) and the data \(line 3\)"),
    ("# run 7\ny x z\n\n---\n# c\n1 2 3\n", r"m.csv, line 4: .* between the header \(line 2\) and the "
                                           r"data \(line 6\)"),
    # a first data row with extra text was taken for a text line, and the header dropped with it
    ("y,x,z\n1,2,3,start\n4,5,6\n7,8,9\n", r"m.csv, line 2, column 4: 'start' is not a number — a "
                                           r"line that is not all numbers stands between the header "
                                           r"\(line 1\) and the data \(line 3\)"),
    ('y,x,z\n"1,000.5",2,3\n4,5,6\n', r"m.csv, line 2: a line that is neither numbers nor a comment "
                                      r"stands between the header \(line 1\) and the data \(line 3\)"),
])
def test_a_line_between_the_header_and_the_data_is_refused(tmp_path, text, pattern):
    """Read as a title, the header was dropped: y for x, µm as mm, or a first row lost."""
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", text))


@pytest.mark.parametrize("text,xyz,header_line", [
    ("Part 7, run 3\n1,2,3\n4,5,6\n", [[1, 2, 3], [4, 5, 6]], None),
    ("Part 7, run 3\ny,x,z\n1,2,3\n4,5,6\n", [[2, 1, 3], [5, 4, 6]], 2),
    ("Part 7, run 3\nOperator: A\n1 2 3 4\n5 6 7 8\n", [[1, 2, 3], [5, 6, 7]], None),
    ("Measured by John Smith\n1,2,3,4\n5,6,7,8\n", [[1, 2, 3], [5, 6, 7]], None),
])
def test_title_lines_naming_no_axes_still_read(tmp_path, text, xyz, header_line):
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, xyz) and c.meta["header_line"] == header_line


@pytest.mark.parametrize("text,xyz,channels", [
    ("//X [um] Y [um] Z [um]\n1000 2000 3\n4000 5000 6\n", [[1, 2, 0.003], [4, 5, 0.006]], []),
    ("# x[um] y[um] z[um]\n1000 2000 3\n4000 5000 6\n", [[1, 2, 0.003], [4, 5, 0.006]], []),
    ("# export\n# y x z\n\n2 1 3\n5 4 6\n", [[1, 2, 3], [4, 5, 6]], []),
    ("//X [mm] Y [mm] Z [um] Scalar field\n1 2 3 0.5\n4 5 6 0.25\n", [[1, 2, 0.003], [4, 5, 0.006]],
     ["scalar_field"]),
])
def test_comment_header_with_units_names_the_columns(tmp_path, text, xyz, channels):
    c = read_cloud(write(tmp_path / "cc.txt", text))
    assert np.array_equal(c.xyz, xyz)
    assert sorted(c.channels) == sorted(["index", *channels])


@pytest.mark.parametrize("text", ["# x y z w\n1 2 3\n4 5 6\n", "# x y\n1 2 3\n4 5 6\n",
                                  "# measured x, y and z\n1 2 3\n4 5 6\n"])
def test_other_hash_comments_stay_comments(tmp_path, text):
    c = read_cloud(write(tmp_path / "m.txt", text))
    assert np.array_equal(c.xyz, [[1, 2, 3], [4, 5, 6]]) and c.meta["header_line"] is None


@pytest.mark.parametrize("value,column", [("1e300", 4), ("9.3e18", 4), ("-1", 4), ("2.5", 4),
                                          ("9223372036854775808", 4)])
def test_index_out_of_range_or_not_whole_is_named(tmp_path, value, column):
    """Cast as read, 1e300 wrapped to -9223372036854775808 with only a RuntimeWarning."""
    p = write(tmp_path / "m.csv", f"x,y,z,index\n4,5,6,2\n1,2,3,{value}\n")
    with pytest.raises(InputError, match=rf"m.csv, line 3, column {column} \(index\): .*is not a "
                                         r"non-negative whole number"):
        read_cloud(p)


def test_integer_channels_out_of_int64_range_are_named(tmp_path):
    with pytest.raises(InputError, match=r"m.csv, line 2, column 4 \(line\): 1e\+300 is not a whole "
                                         r"number"):
        read_cloud(write(tmp_path / "m.csv", "x,y,z,line\n1,2,3,1e300\n4,5,6,2\n"))
    big = read_cloud(write(tmp_path / "ok.csv", "x,y,z,index\n1,2,3,9007199254740991\n4,5,6,0\n"))
    assert big.index.tolist() == [2**53 - 1, 0]  # the largest whole number float64 reads exactly


@pytest.mark.parametrize("value", ["9007199254740992", "9007199254740993", "4611686018427387907"])
def test_whole_numbers_float64_cannot_read_exactly_are_refused(tmp_path, value):
    """2⁵³ + 1 read as 2⁵³ and 2⁶² + 3 as 2⁶² + 4, silently (a review): a file's numbers are parsed as
    float64, so an integer column holds whole numbers below 2⁵³ (docs/formats.md)."""
    with pytest.raises(InputError, match=r"m.csv, line 3, column 4 \(index\): .* below 2⁵³ .*read as "
                                         r"float64"):
        read_cloud(write(tmp_path / "m.csv", f"x,y,z,index\n1,2,3,0\n4,5,6,{value}\n"))


@pytest.mark.parametrize("text", [
    "x,y,z\n1,2,3\n   \n4,5,6\n",
    "x\ty\tz\n1\t2\t3\n \t\n4\t5\t6\n",
    "x y z\n1 2 3\n\t\n4 5 6\n",
    "x,y,z\r\n1,2,3\r\n  \r\n4,5,6\r\n",
    "x,y,z\r1,2,3\r4,5,6\r",  # classic Mac OS: CR alone ends a line
    "x;y;z\r1;2;3\r\r4;5;6",
])
@pytest.mark.parametrize("fast", [False, True])
def test_blank_lines_and_cr_line_ends_read_as_lines(tmp_path, monkeypatch, text, fast):
    import pointspro.core.io.text as text_io

    if fast:  # pandas' reader first, as for big files
        monkeypatch.setattr(text_io, "_FAST_BYTES", 0)
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, [[1, 2, 3], [4, 5, 6]]) and np.array_equal(c.index, [0, 1])
    assert c.meta["header_line"] == 1


def test_a_bad_row_after_a_blank_line_is_still_named(tmp_path):
    with pytest.raises(InputError, match=r"m.csv, line 4, column 2: 'abc' is not a number"):
        read_cloud(write(tmp_path / "m.csv", "x,y,z\n1,2,3\n  \n4,abc,6\n"))


_UM = "x [um],y [um],z [um]\n1000,2000,3\n4000,5000,6\n"


@pytest.mark.parametrize("lines", [60, 500, 998])
@pytest.mark.parametrize("fast", [False, True])
def test_a_long_preamble_is_skipped(tmp_path, monkeypatch, lines, fast):
    """Instrument exports carry 100+ metadata lines; the data was looked for in the first 50."""
    import pointspro.core.io.text as text_io

    if fast:
        monkeypatch.setattr(text_io, "_FAST_BYTES", 0)
    text = "".join(f"Info{i}: value\n" for i in range(lines)) + _UM
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, [[1, 2, 0.003], [4, 5, 0.006]]) and c.meta["header_line"] == lines + 1


@pytest.mark.parametrize("text,pattern", [
    ("".join(f"Info{i}: value\n" for i in range(1000)) + _UM,
     r"m.csv: no numeric data rows in the first 1000 lines \(first line 1: 'Info0: value'\)"),
    ("".join(f"# note {i}\n" for i in range(1200)) + "1,2,3\n",
     r"m.csv: no numeric data rows in the first 1000 lines \(comments and blank lines only\)"),
])
def test_no_data_in_the_head_says_how_far_it_looked(tmp_path, text, pattern):
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", text))


@pytest.mark.parametrize("text,xyz,decimal_comma", [
    # a decimal comma in a later row, not the first: read as one
    ("x;y;z\n1;2;3\n4,5;5;6\n", [[1, 2, 3], [4.5, 5, 6]], True),
    ("x\ty\tz\n1\t2\t3\n4,5\t5\t6\n", [[1, 2, 3], [4.5, 5, 6]], True),
    ("x;y;z\n1;2;3\n# v1.2, test\n4;5;6,25 # rev 2.1\n", [[1, 2, 3], [4, 5, 6.25]], True),
    # decimal points with ';' or tab, and any ',' file, read as before
    ("x;y;z\n1.5;2;3\n4.25;5;6\n", [[1.5, 2, 3], [4.25, 5, 6]], False),
    ("x\ty\tz\n1.5\t2\t3\n4.25\t5\t6\n", [[1.5, 2, 3], [4.25, 5, 6]], False),
    ("x,y,z\n1.5,2,3\n4,5,6\n", [[1.5, 2, 3], [4, 5, 6]], False),
])
@pytest.mark.parametrize("fast", [False, True])
def test_decimal_comma_in_any_row_of_the_head(tmp_path, monkeypatch, text, xyz, decimal_comma, fast):
    import pointspro.core.io.text as text_io

    if fast:
        monkeypatch.setattr(text_io, "_FAST_BYTES", 0)
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, xyz) and c.meta["decimal_comma"] is decimal_comma


@pytest.mark.parametrize("text,pattern", [
    ("x;y;z\n1;2;3\n4,5;5;6\n7.5;8;9\n", r"m.csv, line 4, column 1: '7.5' has a decimal point but "
                                        r"line 3 a decimal comma"),
    ("x;y;z\n1.5;2;3\n4,5;5;6\n", r"m.csv, line 2, column 1: '1.5' has a decimal point but line 3 a "
                                  r"decimal comma"),
    ("x\ty\tz\n1\t2,5\t3\n4\t5.5\t6\n", r"m.csv, line 3, column 2: '5.5' has a decimal point"),
    ("1,5 2,5 3,5\n4.0 5.0 6.0\n", r"m.csv, line 2, column 1: '4.0' has a decimal point but line 1"),
    ("x;y;z\n1;2;3\n1.000,5;5;6\n", r"m.csv, line 3, column 1: '1.000,5' is not a number"),
    ("x;y;z\n1.5;2;3\n4.5;5;6\nEnd, 2 points\n", r"m.csv, line 4: 1 column\(s\), expected 3"),
    ("x\ty\tz\n" + "1\t2\t3\n" * 1200 + "4,5\t5\t6\n",
     r"m.csv, line 1202, column 1: '4,5' is not a number \(a decimal comma where the rows above "
     r"have none"),
])
@pytest.mark.parametrize("fast", [False, True])
def test_decimal_commas_and_points_mixed_are_refused(tmp_path, monkeypatch, text, pattern, fast):
    """Read with the commas made points, "4.5" among "4,5" passed unseen (or "1.000,5" as 1.0005)."""
    import pointspro.core.io.text as text_io

    if fast:
        monkeypatch.setattr(text_io, "_FAST_BYTES", 0)
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", text))


_UTF16_TEXT = "x [µm],y [µm],z [µm]\r\n1000,2000,3\r\n4000,5000,6\r\n"


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be"])
@pytest.mark.parametrize("fast", [False, True])
def test_utf16_text_is_read(tmp_path, monkeypatch, encoding, fast):
    """Latin-1 was the fallback: every other byte a NUL, and a message about something else."""
    import pointspro.core.io.text as text_io

    if fast:  # pandas reads the raw bytes: not taken for UTF-16
        monkeypatch.setattr(text_io, "_FAST_BYTES", 0)
        monkeypatch.setattr(text_io, "_fast_parse", lambda *a: pytest.fail("fast path on UTF-16"))
    p = tmp_path / "m.csv"
    p.write_bytes(_UTF16_TEXT.encode(encoding))  # "utf-16" with its BOM, the others without
    xyz, _, meta = text_io.read_text(p)
    assert np.array_equal(xyz, [[1, 2, 0.003], [4, 5, 0.006]]) and meta["header_line"] == 1
    (tmp_path / "cut.csv").write_bytes(p.read_bytes()[:-1])  # an odd byte count
    with pytest.raises(InputError, match=r"cut.csv: UTF-16 text that does not decode at byte \d+ — "
                                         r"save it as UTF-8"):
        text_io.read_text(tmp_path / "cut.csv")


def test_utf16_text_is_read_by_read_cloud(tmp_path):
    p = tmp_path / "m.csv"
    p.write_bytes(_UTF16_TEXT.encode("utf-16"))
    assert np.array_equal(read_cloud(p).xyz, [[1, 2, 0.003], [4, 5, 0.006]])


@pytest.mark.parametrize("text,xyz", [
    ('x,y,z\n"1","2","3"\n"4","5","6"\n', [[1, 2, 3], [4, 5, 6]]),
    ('"x","y","z"\n"1.5",2,"3"\n4,"5",6\n', [[1.5, 2, 3], [4, 5, 6]]),
    ('"x";"y";"z"\n"1,5";"2";"3"\n"4";"5";"6"\n', [[1.5, 2, 3], [4, 5, 6]]),
    ('"1" "2" "3"\n"4" "5" "6"\n', [[1, 2, 3], [4, 5, 6]]),
])
@pytest.mark.parametrize("fast", [False, True])
def test_numbers_in_double_quotes_are_read(tmp_path, monkeypatch, text, xyz, fast):
    import pointspro.core.io.text as text_io

    if fast:  # pandas takes the quotes off itself
        monkeypatch.setattr(text_io, "_FAST_BYTES", 0)
    c = read_cloud(write(tmp_path / "m.csv", text))
    assert np.array_equal(c.xyz, xyz) and c.xyz.dtype == np.float64


@pytest.mark.parametrize("text,pattern", [
    ('x,y,z\n"1","2","3"\n"4","a","6"\n', r"m.csv, line 3, column 2: '\"a\"' is not a number"),
    ('x,y,z\n"1","2","3"\n"4,5","5","6"\n', r"m.csv, line 3: 4 column\(s\), expected 3 as on line 2"),
])
def test_bad_quoted_fields_are_named(tmp_path, text, pattern):
    with pytest.raises(InputError, match=pattern):
        read_cloud(write(tmp_path / "m.csv", text))


@pytest.mark.parametrize("kind", ["ply", "pcd"])
def test_ascii_ply_and_pcd_refuse_integer_channels_float64_cannot_hold(tmp_path, kind):
    """An index written as a floating property of an ASCII PLY (or TYPE F of an ASCII PCD) is parsed as
    float64: 9007199254740993 and …992 read as two equal indices, silently (a review). Refused now;
    a PCD's TYPE I / U SIZE 8 field is read exactly."""
    if kind == "ply":
        p = write(tmp_path / "m.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\n"
                  "property double y\nproperty double z\nproperty double index\nend_header\n"
                  "0 0 0 9007199254740993\n1 1 1 5\n")
        with pytest.raises(InputError, match=r"m.ply: vertex 0, property 'index': .* below 2⁵³"):
            read_cloud(p)
        return
    head = ("VERSION .7\nFIELDS x y z index\nSIZE 8 8 8 8\nTYPE F F F {t}\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n0 0 0 9007199254740993\n1 1 1 9007199254740992\n")
    with pytest.raises(InputError, match=r"m.pcd, line 11: field 'index' is TYPE F .* below 2⁵³"):
        read_cloud(write(tmp_path / "m.pcd", head.format(t="F")))
    exact = read_cloud(write(tmp_path / "u.pcd", head.format(t="U")))
    assert exact.index.tolist() == [2**53 + 1, 2**53]


def test_a_repeated_index_is_refused_by_every_reader(tmp_path):
    """The index numbers the input's rows (manual_edit removes by it): the text reader refused a repeated
    one, an ASCII PLY's `3, 3` was read as is (a review)."""
    p = write(tmp_path / "m.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\n"
              "property double y\nproperty double z\nproperty double index\nend_header\n0 0 0 3\n1 1 1 3\n")
    with pytest.raises(InputError, match=r"m.ply: the index column has repeated values \(the first: 3, 2 times\)"):
        read_cloud(p)
