"""Height matrices in text that PointsPro's Gwyddion/SPIP/Nova header test did not recognise were read
as x y z point rows (a review: SurfaceTopography's matrix-2.txt, 650 × 650 heights, became 650 points
in mm with channels col4 … col650; the 10 × 10 matrix-5.txt, without a header, 10 points). Checked
here: the `h= w=` / `pixel size=` / `height conversion factor (-> m)=` header against
SurfaceTopography's own reader, a headerless matrix refused saying what is missing (and read with
the reader options), and the width from which headerless rows stop being points (core.io.text)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

DATA = Path(__file__).parent / "data" / "realdata"


def st_topography(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from SurfaceTopography.IO import open_topography

        return open_topography(str(path), format="asc").topography(**kw)


def st_rms(t):
    """SurfaceTopography's RMS height (Sq) of ``t``, its deprecation warning silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return t.rms_height_from_area()


# --- matrix-4.txt: `h=305 w=75`, `pixel size=3.69862e-007 m`, `height conversion factor (-> m)` ---
def test_matrix_4_matches_surfacetopography():
    c = read_cloud(DATA / "matrix-4.txt")
    t = st_topography(DATA / "matrix-4.txt")
    assert t.nb_grid_pts == (75, 305) and t.unit == "m"
    assert c.meta["format"] == "matrix" and c.meta["instrument_unit"] == "m"
    assert c.meta["grid"] == [75, 305] and c.n == 75 * 305 and c.meta["invalid_dropped"] == 0
    # pixel size: SurfaceTopography's, and the header's 3.69862e-007 m on both axes
    px = [s / n * 1e3 for s, n in zip(t.physical_sizes, t.nb_grid_pts)]
    assert np.allclose(c.meta["pixel_mm"], px, rtol=1e-12, atol=0)
    assert np.allclose(c.meta["pixel_mm"], [3.69862e-4, 3.69862e-4], rtol=1e-12, atol=0)
    assert np.allclose(c.x, c["col"] * px[0], rtol=1e-12) and np.allclose(c.y, c["row"] * px[1], rtol=1e-12)
    # heights: the same pixels, m → mm; RMS height 117.46 nm (SurfaceTopography's rms_height)
    h = np.asarray(t.heights(), dtype=np.float64) * 1e3
    assert np.array_equal(c.z, h[c["col"], c["row"]])
    assert np.isclose(c.z.std(), st_rms(t) * 1e3, rtol=1e-12)
    assert np.isclose(c.z.std() * 1e6, 117.4589, rtol=1e-6)
    # and without SurfaceTopography: the file's numbers × the factor, row j of the file is y = j·Δy
    raw = np.loadtxt(DATA / "matrix-4.txt", skiprows=4)
    assert raw.shape == (305, 75)
    assert np.allclose(c.z, raw[c["row"], c["col"]] * 2.91818e-8 * 1e3, rtol=1e-15, atol=0)


def test_matrix_2_header_reads_as_a_matrix(tmp_path):
    """matrix-2.txt's header (650 × 650, 240.4 µm, RMS 277 nm) over a 4 × 5 cut of matrix-4's
    numbers: a matrix in m, not 5 points with channels col4 …"""
    rows = (DATA / "matrix-4.txt").read_text(encoding="utf-8").splitlines()[4:9]
    rows = [" ".join(r.split()[:4]) for r in rows]
    p = tmp_path / "m2.txt"
    head = ("h=5 w=4\npixel size=3.69862e-007 m\ndata unit=rad\n"
            "height conversion factor (-> m)=6.30079e-008\n")
    p.write_text(head + "\n".join(rows) + "\n", encoding="utf-8")
    c = read_cloud(p)
    t = st_topography(p)
    assert c.meta["format"] == "matrix" and c.meta["grid"] == [4, 5] == list(t.nb_grid_pts)
    assert "col4" not in c.channels
    assert np.array_equal(c.z, np.asarray(t.heights())[c["col"], c["row"]] * 1e3)
    assert np.allclose(c.meta["pixel_mm"], [3.69862e-4] * 2, rtol=1e-12)


@pytest.mark.parametrize("head,pattern", [
    ("h=6 w=4\npixel size=1 µm\nheight conversion factor (-> m)=1e-9\n",
     r"m.txt, line 1: the header's h=6 but the matrix has 5 rows"),
    ("h=5 w=3\npixel size=1 µm\nheight conversion factor (-> m)=1e-9\n",
     r"m.txt, line 1: the header's w=3 but the matrix has 4 values a row"),
    ("h=5 w=4\npixel size=0.37\nheight conversion factor (-> m)=1e-9\n",
     r"m.txt, line 2: the pixel size has no unit \('pixel size=0.37'\); write e.g. 'pixel "
     r"size=0.37 µm' or give the reader option pixel_size_um"),
    ("h=5 w=4\npixel size=0 m\nheight conversion factor (-> m)=1e-9\n",
     r"m.txt, line 2: the header's pixel size is 0 — x and y positions cannot be scaled"),
    ("h=5 w=4\npixel size=1 px\nheight conversion factor (-> m)=1e-9\n",
     r"m.txt, line 2: the pixel size's unit 'px' is no length unit"),
    ("h=5 w=4\npixel size=1 µm\nheight conversion factor (-> rad)=1e-9\n",
     r"m.txt, line 3: the height conversion factor converts to 'rad', which is no length unit"),
    ("h=5 w=4\npixel size=1 µm\nheight conversion factor (-> m)=nan\n",
     r"m.txt, line 3: the header's height conversion factor is not a number"),
    ("h=5 w=4\npixel size=1 µm\ndata unit=rad\n",
     r"m.txt, line 3: the values are in 'rad' \(data unit\), not a length, and the header gives no "
     r"'height conversion factor \(-> m\)=…'"),
    ("h=5 w=4\nx pixel size=1 µm\ny pixel size=2 µm\nheight conversion factor (-> m)=1e-9\n",
     r"m.txt, line 3: a second pixel size \(line 2 has one\)"),
    ("# Width: 4 µm\n# Height: 5 µm\npixel size=1 µm\n# Value units: m\n",
     r"m.txt, line 3: the header gives both a pixel size \(line 3\) and the map's size \(# Width, "
     r"line 1\); keep one of them"),
    ("h=5 w=4\npixel size=1 µm\n",
     r"m.txt: the Plain text file gives no length unit for its heights; give the reader option "
     r"height_unit"),
])
def test_st_matrix_header_refused_naming_the_line(tmp_path, head, pattern):
    p = tmp_path / "m.txt"
    p.write_text(head + "".join(f"{j} {j + 1} {j + 2} {j + 3}\n" for j in range(5)), encoding="utf-8")
    with pytest.raises(InputError, match=pattern) as e:
        read_cloud(p)
    assert "\n" not in str(e.value)


def test_st_matrix_header_with_the_options(tmp_path):
    """A pixel size without unit is replaced by pixel_size_um; a pixel size in µm with heights of no
    stated unit takes height_unit for the heights only (SurfaceTopography would read the µm as nm)."""
    body = "".join(f"{j} {j + 1} {j + 2} {j + 3}\n" for j in range(5))
    p = tmp_path / "a.txt"
    p.write_text("h=5 w=4\npixel size=0.37\nheight conversion factor (-> m)=1e-9\n" + body, encoding="utf-8")
    c = read_cloud(p, pixel_size_um=2.0)
    assert np.allclose(c.meta["pixel_mm"], [2e-3, 2e-3], rtol=1e-12)
    assert np.isclose(c.z.max(), 7e-6, rtol=1e-12)  # 7 × 1e-9 m
    p = tmp_path / "b.txt"
    p.write_text("h=5 w=4\npixel size=0.5 µm\n" + body, encoding="utf-8")
    c = read_cloud(p, height_unit="nm")
    assert np.allclose(c.meta["pixel_mm"], [5e-4, 5e-4], rtol=1e-12)
    assert np.isclose(c.z.max(), 7e-6, rtol=1e-12)


# --- matrix-5.txt: 10 × 10 numbers, no header -------------------------------------------------------
def test_headerless_matrix_5_is_refused_saying_what_is_missing():
    with pytest.raises(InputError) as e:
        read_cloud(DATA / "matrix-5.txt")
    msg = str(e.value)
    assert msg.startswith(f"{DATA / 'matrix-5.txt'}, line 1: 10 rows of 10 numbers and no header "
                          "naming the columns — a height matrix, not x y z points, and it states no "
                          "pixel size and no height unit: give the reader options pixel_size_um (µm) "
                          "and height_unit (nm, µm, mm or m), e.g. `input: {pixel_size_um: 1.1, "
                          "height_unit: nm}` in the recipe")
    assert "\n" not in msg
    with pytest.raises(InputError, match=r"it states no height unit: give the reader option "
                                         r"height_unit \(nm, µm, mm or m\), e\.g\. `input: "
                                         r"\{height_unit: nm\}`"):
        read_cloud(DATA / "matrix-5.txt", pixel_size_um=1.0)
    with pytest.raises(InputError, match=r"it states no pixel size: give the reader option "
                                         r"pixel_size_um \(µm\)"):
        read_cloud(DATA / "matrix-5.txt", height_unit="nm")


def test_headerless_matrix_5_with_the_options_matches_surfacetopography():
    c = read_cloud(DATA / "matrix-5.txt", pixel_size_um=[2.0, 3.0], height_unit="µm")
    t = st_topography(DATA / "matrix-5.txt", physical_sizes=(20.0, 30.0), unit="µm")
    assert t.nb_grid_pts == (10, 10)
    assert c.meta["format"] == "matrix" and c.meta["grid"] == [10, 10] and c.n == 100
    assert np.allclose(c.meta["pixel_mm"], [2e-3, 3e-3], rtol=1e-12)
    assert np.array_equal(c.z, np.asarray(t.heights())[c["col"], c["row"]] * 1e-3)
    assert np.isclose(c.z.std(), st_rms(t) * 1e-3, rtol=1e-12)
    assert np.array_equal(c.z[c["row"] < 5], np.full(50, 2e-3))  # the first five lines are 2 µm
    assert np.isclose(np.ptp(c.y), 9 * 3e-3) and np.isclose(np.ptp(c.x), 9 * 2e-3)


def test_headerless_matrix_refusal_is_one_line_from_the_cli(run_cli):
    code, out, err = run_cli("info", DATA / "matrix-5.txt")
    assert code == 2 and "Traceback" not in err and err.strip().count("\n") == 0
    assert "a height matrix, not x y z points" in err and "pixel_size_um" in err


# --- how wide headerless rows may be and still be points --------------------------------------------
def _rows(n, m, sep=" "):
    rng = np.random.default_rng(n * 100 + m)
    return "".join(sep.join(repr(float(v)) for v in row) + "\n" for row in rng.normal(size=(n, m)))


@pytest.mark.parametrize("nrows,ncols,matrix", [
    (650, 650, True), (2, 21, True), (1000, 21, True),   # more than 20 columns: a matrix
    (10, 10, True), (8, 8, True), (20, 20, True),        # 8–20 columns in as many rows: a square map
    (300, 13, False), (4, 7, False), (15, 10, False),    # CMM tables, a 4-ball export, CloudCompare's
    (9, 10, False), (500, 10, False), (7, 7, False),     # 10 (a review: refused, or read as a map)
    (4, 6, False), (6, 6, False), (2, 5, False), (3, 3, False),  # x y z + up to 3 channels
])
def test_headerless_width_decides(tmp_path, nrows, ncols, matrix):
    p = tmp_path / "r.txt"
    p.write_text(_rows(nrows, ncols), encoding="utf-8")
    if matrix:
        with pytest.raises(InputError, match=rf"r.txt, line 1: {nrows} rows of {ncols} numbers and no "
                                             r"header naming the columns — a height matrix"):
            read_cloud(p)
        c = read_cloud(p, pixel_size_um=1.0, height_unit="nm")
        assert c.meta["grid"] == [ncols, nrows] and c.n == nrows * ncols
    else:
        c = read_cloud(p)
        assert c.meta["format"] == "text" and c.n == nrows
        assert len(c.channels) == ncols - 3 + 1  # col4 … and index


def test_wide_rows_with_a_header_are_points(tmp_path):
    """A CMM/CloudCompare export that names its columns stays points at any width."""
    names = ["x", "y", "z"] + [f"c{k}" for k in range(9)]
    p = tmp_path / "h.csv"
    p.write_text(",".join(names) + "\n" + _rows(5, 12, ","), encoding="utf-8")
    c = read_cloud(p)
    assert c.meta["format"] == "text" and c.n == 5 and "c8" in c.channels
    p = tmp_path / "cc.txt"
    p.write_text("//X Y Z R G B SF1 SF2 Nx Ny Nz W\n" + _rows(5, 12), encoding="utf-8")
    c = read_cloud(p)
    assert c.meta["format"] == "text" and c.n == 5 and "nz" in c.channels


def test_headerless_matrix_in_csv_with_a_title_and_nan(tmp_path):
    """MATLAB's writematrix: commas; a title line above, a NaN pixel: dropped and counted."""
    z = np.arange(96, dtype=float).reshape(4, 24)
    text = "".join(",".join("NaN" if (j, i) == (2, 5) else repr(float(v)) for i, v in enumerate(row)) + "\n"
                   for j, row in enumerate(z))
    p = tmp_path / "w.csv"
    p.write_text("surface 7\n" + text, encoding="utf-8")
    with pytest.raises(InputError, match=r"w.csv, line 2: 4 rows of 24 numbers"):
        read_cloud(p)
    c = read_cloud(p, pixel_size_um=0.5, height_unit="mm")
    assert c.n == 95 and c.meta["invalid_dropped"] == 1
    assert np.array_equal(c.z, z[c["row"], c["col"]])
    assert np.array_equal(c.x, c["col"] * 5e-4) and np.array_equal(c.y, c["row"] * 5e-4)


def test_headerless_rows_with_one_matrix_key_go_to_the_matrix_reader(tmp_path):
    """`pixel size=` alone above rows of 12: the matrix reader says what is still missing."""
    p = tmp_path / "k.txt"
    p.write_text("pixel size=0.5 µm\n" + _rows(12, 12), encoding="utf-8")
    with pytest.raises(InputError, match=r"k.txt: the Plain text file gives no length unit for its "
                                         r"heights; give the reader option height_unit"):
        read_cloud(p)
    c = read_cloud(p, height_unit="nm")
    assert c.meta["grid"] == [12, 12] and np.allclose(c.meta["pixel_mm"], [5e-4, 5e-4], rtol=1e-12)


def test_parameter_tables_are_not_matrices(tmp_path):
    """read_table (a recipe's parameter files) reads wide headed tables as before."""
    from pointspro.core.io.text import read_table

    p = tmp_path / "t.csv"
    p.write_text(",".join(f"c{k}" for k in range(12)) + "\n" + _rows(3, 12, ","), encoding="utf-8")
    cols = read_table(p, ("c0", "c11"))
    assert len(cols) == 12 and len(cols["c0"]) == 3


@pytest.mark.parametrize("sep", [" ", ","])
def test_points_under_a_preamble_with_width_and_height_lines_are_points(tmp_path, sep):
    """A part's drawing size in a preamble ("Width: 100 mm", "Height: 25 mm") looked like a matrix
    header: the x y z columns below it became a 3 × 6 height matrix of 33 mm pixels (a review). A
    line naming the axes right above the data makes them points."""
    rows = [(0, 0, 0.001), (10, 0, 0.002), (20, 0, 0.003), (0, 10, 0.004), (10, 10, 0.005), (20, 10, 0.006)]
    text = ("Part: bracket 7\nWidth: 100 mm\nHeight: 25 mm\n" + sep.join("xyz") + "\n"
            + "".join(sep.join(map(str, r)) + "\n" for r in rows))
    (tmp_path / "p.txt").write_text(text, encoding="utf-8")
    c = read_cloud(tmp_path / "p.txt")
    assert len(c) == 6 and np.array_equal(c.xyz, np.array(rows, dtype=float))
    # a Gwyddion export, whose header ends in "# Value units", is still a matrix
    (tmp_path / "g.txt").write_text("# Channel: h\n# Width: 3 mm\n# Height: 2 mm\n# Value units: m\n"
                                    "1 2 3\n4 5 6\n", encoding="utf-8")
    assert read_cloud(tmp_path / "g.txt").meta.get("grid") is not None


@pytest.mark.parametrize("rows", ["1,5 1,5 3\n-2 -3 -6\n", "1,5e-09 2,5e-09 3e-09\n4e-09 5e-09 6e-09\n",
                                  "1,2,3\n4,5,6\n", "1;2;3\n4;5;6\n"])
def test_a_matrix_with_decimal_commas_or_comma_separators_is_named(tmp_path, rows):
    """Gwyddion with 'decimal dot' off, or a matrix separated by ',' / ';': "ragged matrix" or "Could
    not find any topography data" (a review) — one line naming the first such row and what to do."""
    (tmp_path / "m.txt").write_text("# Channel: h\n# Width: 3 µm\n# Height: 2 µm\n# Value units: m\n" + rows,
                                    encoding="utf-8")
    with pytest.raises(InputError, match=r"m\.txt, line 5: values separated by ',' or ';', or written with "
                                         r"a decimal comma .*decimal dot"):
        read_cloud(tmp_path / "m.txt")
