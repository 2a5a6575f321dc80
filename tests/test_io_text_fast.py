"""Big text files go through Arrow's or pandas' C reader first: the same arrays as numpy's, the same
messages."""
from __future__ import annotations

import numpy as np
import pytest

import pointspro.core.io.text as text
from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

CASES = {
    "comma.csv": "x,y,z,w\n1.5,2.25,3.125,7\n-4,5e-3,6,8\n",
    "semicolon_decimal_comma.txt": "X [µm];Y [µm];Z [µm]\n1,5;2,5;3,25\n4;5;6\n",
    "whitespace_comments.xyz": "# CMM export\n 1 2 3\n\n4  5\t6 \n# end\n7 8 9\n",
    "tab.txt": "x\ty\tz\n1\t2\t3\n4\t5\t6\n",
    "trailing_delimiter.csv": "x,y,z,\n1,2,3,\n4,5,6,\n",
    "inline_comment_first_row.txt": "1 2 3 # first point\n4 5 6\n7 8 9\n",
    "inline_comment_first_row.csv": "1,2,3 // probe 1\n4,5,6\n7,8,9\n",
    "inline_comments_header.txt": "x y z  # mm\n1 2 3 % first\n4 5 6\n7 8 9\n",
    "decimal_comma_last_column.txt": "0 0 1,25\n1 0 1,5\n2 0 1,75\n",
    "comment_right_after_a_number.txt": "1 2 3# first\n4 5 6# second\n7 8 9\n",
}

#: what the cases above hold (x, y, z rows)
EXPECTED = {"inline_comment_first_row.txt": [[1, 2, 3], [4, 5, 6], [7, 8, 9]],
            "inline_comment_first_row.csv": [[1, 2, 3], [4, 5, 6], [7, 8, 9]],
            "inline_comments_header.txt": [[1, 2, 3], [4, 5, 6], [7, 8, 9]],
            "decimal_comma_last_column.txt": [[0, 0, 1.25], [1, 0, 1.5], [2, 0, 1.75]],
            "comment_right_after_a_number.txt": [[1, 2, 3], [4, 5, 6], [7, 8, 9]]}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_inline_comment_on_the_first_row_and_a_decimal_comma_in_the_last_column(tmp_path, name):
    """A review: the first row was dropped as a title when it ended in a comment (any later row's
    comment was cut off), and "0 0 1,25" was split at its decimal comma ("no numeric data rows")."""
    p = tmp_path / name
    p.write_text(CASES[name], encoding="utf-8")
    assert np.array_equal(read_cloud(p).xyz, np.array(EXPECTED[name], dtype=float))


#: the files Arrow's reader takes (one comma, semicolon or tab, decimal points, no comments); the
#: others go to pandas' reader
ARROW_CASES = {"comma.csv", "tab.txt", "trailing_delimiter.csv"}
#: files pandas' reader is not given (more than one comment marker, or "//"): numpy's reads them
FAST_DECLINES = {"inline_comment_first_row.csv", "inline_comments_header.txt"}


@pytest.mark.parametrize("reader", ["_arrow_parse", "_fast_parse"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_fast_path_reads_what_numpy_reads(tmp_path, monkeypatch, name, reader):
    """Each fast reader, where it is taken, reads what numpy's reads (pandas' with Arrow's left out)."""
    p = tmp_path / name
    p.write_text(CASES[name], encoding="utf-8")
    slow = read_cloud(p)
    monkeypatch.setattr(text, "_FAST_BYTES", 0)
    if reader == "_fast_parse":
        monkeypatch.setattr(text, "_arrow_parse", lambda *a: None)
    calls = []
    real = getattr(text, reader)
    monkeypatch.setattr(text, reader, lambda *a: calls.append(real(*a) is not None) or real(*a))
    fast = read_cloud(p)
    taken = (reader == "_fast_parse" and name not in FAST_DECLINES) or name in ARROW_CASES
    assert calls == [taken]
    assert fast.equals(slow)
    assert np.array_equal(fast.xyz, slow.xyz)


def test_fast_path_round_trips_full_precision(tmp_path, monkeypatch):
    from pointspro.core import PointCloud
    from pointspro.core.io import write_csv

    rng = np.random.default_rng(3)
    c = PointCloud.from_xyz(*rng.normal(0, 300, (3, 20000)), residual=rng.normal(0, 1e-3, 20000))
    write_csv(c, tmp_path / "c.csv")
    monkeypatch.setattr(text, "_FAST_BYTES", 0)
    back = read_cloud(tmp_path / "c.csv")
    assert np.array_equal(back.xyz, c.xyz) and np.array_equal(back["residual"], c["residual"])


@pytest.mark.parametrize("body, where", [("1,2,3\n4,,6\n", "line 3, column 2"),
                                         ("1,2,3\n4,5,6,7\n", "line 3"),
                                         ("1,2,3\n4,abc,6\n", "line 3, column 2")])
def test_bad_rows_in_big_files_are_still_named(tmp_path, monkeypatch, body, where):
    monkeypatch.setattr(text, "_FAST_BYTES", 0)
    p = tmp_path / "bad.csv"
    p.write_text("x,y,z\n" + body, encoding="utf-8")
    with pytest.raises(InputError, match=where):
        read_cloud(p)


def test_quotes_in_a_preamble_do_not_make_pandas_skip_a_data_row(tmp_path, monkeypatch):
    """pandas counts the lines it skips as CSV rows, a quote joining lines: two '"q' lines before the
    data made it skip the first data row without a word (a review). With a blank line of spaces in
    the data (Arrow declines) the file now goes to numpy's reader: both rows."""
    p = tmp_path / "q.csv"
    p.write_bytes(b'"q\n"q\n1,2,3\n \n4,5,6\n')
    monkeypatch.setattr(text, "_FAST_BYTES", 0)
    assert read_cloud(p).xyz.tolist() == [[1, 2, 3], [4, 5, 6]]


@pytest.mark.parametrize("body, where", [('x,y,z\n "1",2,3\n4,5,6\n', "line 2, column 1"),
                                         ('x;y;z\n1;2;3\n4; "5";6\n', "line 3, column 2")])
def test_a_space_before_an_opening_quote_is_named(tmp_path, body, where):
    """numpy's reader takes a quote only at the start of a field: ' "1"' failed with "could not parse
    the numeric data", naming no line (a review)."""
    p = tmp_path / "q.csv"
    p.write_text(body, encoding="utf-8")
    with pytest.raises(InputError, match=where + r": ' \"\d\"' has a space before its opening quote"):
        read_cloud(p)


@pytest.mark.parametrize("text, channel", [("Pt# X Y Z\n1 0.0 0.0 1.0\n2 1.0 0.0 1.5\n3 0.0 1.0 2.0\n", "pt"),
                                           ("Pt#,X,Y,Z\n1,0.0,0.0,1.0\n2,1.0,0.0,1.5\n3,0.0,1.0,2.0\n", "pt"),
                                           ("X Y Z Refl[%]\n0.0 0.0 1.0 50\n1.0 0.0 1.5 60\n0.0 1.0 2.0 70\n",
                                            "refl")])
def test_a_comment_marker_inside_a_column_name_is_part_of_it(tmp_path, text, channel):
    """A review of the inline-comment fix: cut at any marker, "Pt# X Y Z" became "Pt" — a title — and
    the point numbers became x, silently; "Refl[%]" was refused. A marker starts a comment only at the
    start of a field."""
    p = tmp_path / "h.txt"
    p.write_text(text, encoding="utf-8")
    c = read_cloud(p)
    assert np.array_equal(c.xyz, [[0.0, 0.0, 1.0], [1.0, 0.0, 1.5], [0.0, 1.0, 2.0]]) and channel in c.channels
