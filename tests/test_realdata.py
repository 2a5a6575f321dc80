"""Real instrument files (tests/data/realdata, SurfaceTopography's published examples, MIT) read by
PointsPro's read_cloud and checked against SurfaceTopography's own reader: number of valid points,
lateral extent in mm, height unit, mean and std of the heights in mm (1e-12 relative)."""
from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

DATA = Path(__file__).parent / "data" / "realdata"
TO_MM = {"m": 1e3, "mm": 1.0, "µm": 1e-3, "nm": 1e-6}

# file, (nx, ny) as the file states it, the unit SurfaceTopography reports for it
MAPS = [
    ("metropro-1.dat", (640, 480), "m"),
    ("sur-2.sur", (563, 484), "mm"),
    ("opd-1.opd", (640, 480), "mm"),
    ("mi-1.mi", (256, 256), "µm"),
    ("matrix-3.txt", (256, 256), "m"),
    ("gwyddion-export-english.txt", (3, 4), "m"),
    ("sdf-1.sdf", (7, 4), "µm"),
    ("tmd-1.tmd", (300, 300), "mm"),
]
#: maps whose rows PointsPro reverses from SurfaceTopography's (Gwyddion's y-down order): y up the
#: instrument's picture — OPD and MI store the bottom line first (SurfaceTopography reverses them),
#: MetroPro, SUR and TMD the top one (tmd-1.tmd, a dime, reads right only so; docs/formats.md)
LINES_REVERSED_BY_ST = {"opd-1.opd", "mi-1.mi", "metropro-1.dat", "sur-2.sur", "tmd-1.tmd"}


def st_read(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from SurfaceTopography.IO import open_topography

        if name in ("matrix-3.txt", "gwyddion-export-english.txt"):  # 'µm' in their header, and
            # SurfaceTopography's text reader opens a path in the locale's encoding (ASCII under C)
            import io

            r = open_topography(io.StringIO((DATA / name).read_text(encoding="utf-8")), format="asc")
        else:
            r = open_topography(str(DATA / name))
        return r, r.topography()


def test_the_licence_travels_with_the_data():
    assert (DATA / "LICENSE-SurfaceTopography.md").read_text(encoding="utf-8").startswith("### MIT license")
    assert "SurfaceTopography" in (DATA / "README.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("name,grid,unit", MAPS)
def test_map_matches_surfacetopography(name, grid, unit):
    c = read_cloud(DATA / name)
    reader, t = st_read(name)
    assert t.nb_grid_pts == grid and t.unit == unit
    h = t.heights()
    valid = ~np.ma.getmaskarray(h) & np.isfinite(np.ma.getdata(h))
    f = TO_MM[unit]
    # points: every valid pixel, none of the invalid ones
    assert c.n == valid.sum()
    assert c.meta["invalid_dropped"] == valid.size - valid.sum()
    assert c.meta["grid"] == list(grid)
    # lateral size: pixel (i, j) at (i·Δx, j·Δy), Δ = physical size / pixels (file's unit → mm)
    dx, dy = (s / n * f for s, n in zip(t.physical_sizes, t.nb_grid_pts))
    assert np.allclose(c.meta["pixel_mm"], [dx, dy], rtol=1e-12, atol=0)
    assert np.allclose(c.x, c["col"] * dx, rtol=1e-12, atol=1e-15)
    assert np.allclose(c.y, c["row"] * dy, rtol=1e-12, atol=1e-15)
    if name in LINES_REVERSED_BY_ST:
        h, valid = h[:, ::-1], valid[:, ::-1]
    i, j = np.nonzero(valid)
    assert np.isclose(np.ptp(c.x), (i.max() - i.min()) * dx, rtol=1e-12)
    assert np.isclose(np.ptp(c.y), (j.max() - j.min()) * dy, rtol=1e-12)
    # heights: the same pixels, the unit converted to mm
    zst = np.ma.getdata(h)[valid].astype(np.float64) * f
    assert np.isclose(c.z.mean(), zst.mean(), rtol=1e-12, atol=0)
    assert np.isclose(c.z.std(), zst.std(), rtol=1e-12, atol=0)
    assert np.array_equal(c.z, np.ma.getdata(h)[c["col"], c["row"]] * f)  # (x, y) storage in ST
    assert c.meta["instrument_unit"] == unit


@pytest.mark.parametrize("name,n_pts,n_invalid,size_mm,mean_um,std_um", [
    # figures that do not come from SurfaceTopography (numpy on the file's own numbers, the
    # README's pixel counts) — so a change in the library cannot move them unnoticed
    ("metropro-1.dat", 307200, 0, (0.7017830, 0.5260627), 50.740406, 0.0752882),
    ("sur-2.sur", 272375, 117, (1.9580081, 1.6827721), 10.157376, 0.0175179),
    ("opd-1.opd", 307084, 116, (0.1257124, 0.0942351), -0.2722895, 0.0083565),
    ("mi-1.mi", 65536, 0, (0.0199219, 0.0199219), -0.5588049, 0.0332154),
    ("sdf-1.sdf", 28, 0, (0.006, 0.003), 0.9835632, 0.0136029),
])
def test_map_figures(name, n_pts, n_invalid, size_mm, mean_um, std_um):
    c = read_cloud(DATA / name)
    assert c.n == n_pts and c.meta["invalid_dropped"] == n_invalid
    assert np.allclose([np.ptp(c.x), np.ptp(c.y)], size_mm, rtol=1e-6)
    assert np.isclose(c.z.mean() * 1e3, mean_um, rtol=1e-6)
    assert np.isclose(c.z.std() * 1e3, std_um, rtol=1e-4)


def test_gwyddion_matrix_by_hand():
    """3 values a line, 4 lines: Width 12.34 µm over 3 columns, Height 5678.9 nm over 4 rows,
    values in m — the matrix, not 4 points of x y z."""
    c = read_cloud(DATA / "gwyddion-export-english.txt")
    assert c.n == 12 and c.meta["format"] == "matrix"
    dx, dy = 12.34e-3 / 3, 5678.9e-6 / 4
    rows = np.array([[1, 1.5, 3], [-2, -3, -6], [0, 0, 0], [9, 9, 9]], float)
    assert np.allclose(c.x, c["col"] * dx, rtol=1e-12) and np.allclose(c.y, c["row"] * dy, rtol=1e-12)
    assert np.array_equal(c.z, rows[c["row"], c["col"]] * 1e3)  # m → mm
    assert c.meta["channel"] == "My Channel Name"


def test_matrix_3_against_numpy():
    """A 256 × 256 Gwyddion matrix (10 µm × 10 µm, m): numpy's loadtxt of the same numbers."""
    c = read_cloud(DATA / "matrix-3.txt")
    z = np.loadtxt(DATA / "matrix-3.txt", comments="#", encoding="utf-8")
    assert z.shape == (256, 256) and c.n == z.size
    assert np.array_equal(c.z, z[c["row"], c["col"]] * 1e3)
    assert np.isclose(np.ptp(c.x), 255 * 10e-3 / 256, rtol=1e-12)
    assert np.isclose(c.z.std(), z.std() * 1e3, rtol=1e-12)


def test_xyz_columns_are_points():
    """x y z columns are points in mm (16 here); SurfaceTopography reads the same numbers as a
    4 × 4 grid without unit — the same heights and extent."""
    c = read_cloud(DATA / "xyz-1.txt")
    _, t = st_read("xyz-1.txt")
    assert c.n == 16 == t.nb_grid_pts[0] * t.nb_grid_pts[1]
    assert c.meta["format"] == "text" and t.unit is None
    assert (np.ptp(c.x), np.ptp(c.y)) == (3.0, 3.0)
    assert np.isclose(c.z.mean(), np.mean(t.heights()), rtol=1e-12)
    assert np.isclose(c.z.std(), np.std(t.heights()), rtol=1e-12)


# --- the content decides, and bad files are one line ------------------------------------------------
def test_extension_that_lies_is_read_for_what_it_is(tmp_path):
    shutil.copy(DATA / "metropro-1.dat", tmp_path / "export.csv")  # a MetroPro named .csv
    shutil.copy(DATA / "sur-2.sur", tmp_path / "map.opd")         # a Digital Surf named .opd
    shutil.copy(DATA / "matrix-3.txt", tmp_path / "matrix.xyz")    # a matrix named .xyz
    for lie, true in (("export.csv", "metropro-1.dat"), ("map.opd", "sur-2.sur"),
                      ("matrix.xyz", "matrix-3.txt")):
        a, b = read_cloud(tmp_path / lie), read_cloud(DATA / true)
        assert np.array_equal(a.xyz, b.xyz) and a.meta["instrument_format"] == \
            b.meta["instrument_format"]


@pytest.mark.parametrize("name,keep,pattern", [
    ("sur-2.sur", 5000, r"t.sur: cannot read this damaged or truncated Digital Surf SUR file "
                        r"\(The file ended after 4488 of 1089968 bytes"),
    ("sur-2.sur", 600000, r"t.sur: cannot read this damaged or truncated Digital Surf SUR file"),
    ("opd-1.opd", 5000, r"t.opd: a damaged or truncated Wyko OPD file \(The file ended"),
    ("metropro-1.dat", 5000, r"t.dat: cannot read this damaged or truncated Zygo MetroPro DAT file"),
    ("metropro-1.dat", 300, r"t.dat: "),
    ("mi-1.mi", 5000, r"t.mi: a damaged or truncated Molecular Imaging \(MI\) file"),
])
def test_truncated_instrument_files(tmp_path, name, keep, pattern):
    p = tmp_path / ("t" + Path(name).suffix)
    p.write_bytes((DATA / name).read_bytes()[:keep])
    with pytest.raises(InputError, match=pattern) as e:
        read_cloud(p)
    assert "\n" not in str(e.value) and len(str(e.value)) < 400 and str(e.value).startswith(str(p))


def test_foreign_and_lying_files(tmp_path):
    png = tmp_path / "photo.sur"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0\0\0\rIHDR" + bytes(200))
    with pytest.raises(InputError, match=r"photo.sur: a PNG image, not a measurement file; the "
                                         r"extension '.sur' says Digital Surf SUR"):
        read_cloud(png)
    txt = tmp_path / "notes.opd"
    txt.write_text("measured on Monday\nall fine\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"notes.opd: no numeric data rows found .* — the content is "
                                         r"text, not a Wyko OPD file as the extension '.opd' says"):
        read_cloud(txt)
    pdf = tmp_path / "report.datx"
    pdf.write_bytes(b"%PDF-1.4\n" + bytes(range(256)))
    with pytest.raises(InputError, match=r"report.datx: a PDF document, not a measurement file; "
                                         r"the extension '.datx' says Zygo DATX"):
        read_cloud(pdf)


def test_ragged_and_damaged_matrices(tmp_path):
    head = "# Channel: Z\n# Width: 3 µm\n# Height: 3 µm\n# Value units: nm\n"
    p = tmp_path / "ragged.txt"
    p.write_text(head + "1 2 3\n4 5 6\n7 8\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"ragged.txt, line 7: 2 values where the matrix rows from "
                                         r"line 5 on have 3 \(ragged matrix"):
        read_cloud(p)
    p = tmp_path / "word.txt"
    p.write_text(head + "1 2 3\n4 x 6\n7 8 9\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"word.txt, line 6, column 2: 'x' is not a number"):
        read_cloud(p)
    p = tmp_path / "nan.txt"
    p.write_text(head + "1 2 3\n4 nan 6\n7 8 9\n", encoding="utf-8")
    c = read_cloud(p)
    assert c.n == 8 and c.meta["invalid_dropped"] == 1 and np.isclose(c.z.max(), 9e-6)
    p = tmp_path / "nounits.txt"
    p.write_text("# Width: 3\n# Height: 3\n1 2 3\n4 5 6\n7 8 9\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"nounits.txt: the Plain text file gives no length unit "
                                         r"for its heights; give the reader option height_unit"):
        read_cloud(p)
    c = read_cloud(p, height_unit="µm")
    assert np.isclose(c.z.max(), 9e-3) and np.isclose(np.ptp(c.x), 2e-3)


def test_two_column_profile_reads_as_a_profile(tmp_path):
    """A profilometer's two columns (x, z) are a stylus profile at azimuth 0° (issue 19; it was
    refused before); a scan that turns back is refused naming its line."""
    p = tmp_path / "profile.txt"
    p.write_text("0.0 0.1\n0.5 0.2\n1.0 0.15\n", encoding="utf-8")
    c = read_cloud(p)
    assert c.n == 3 and np.all(c.y == 0) and np.all(c["angle"] == 0)
    np.testing.assert_array_equal(c.x, [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(c.z, [0.1, 0.2, 0.15])
    back = tmp_path / "back.txt"
    back.write_text("0.0 0.1\n0.5 0.2\n0.2 0.15\n", encoding="utf-8")
    with pytest.raises(InputError, match="back.txt"):
        read_cloud(back)
