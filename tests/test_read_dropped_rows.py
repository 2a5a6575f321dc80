"""Rows dropped on reading for a NaN or infinite value are said, with the columns that held them: a
NaN in an extra channel (a quality flag, a temperature) drops the point whole, and a review's file
lost 713 of 4,984 points (14 %) with no word but a count in report.json."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pointspro.core.batch import read_warning
from pointspro.core.io import read_cloud

EXAMPLE = Path(__file__).resolve().parents[1] / "resources" / "example"


def _with_quality(tmp_path: Path, every: int = 7) -> tuple[Path, int]:
    """The example with a `quality` channel that is NaN on every ``every``-th row."""
    lines = (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8").splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))  # the column names' line
    comments, head, rows = lines[:h], lines[h], lines[h + 1:]
    out = comments + [head + ",quality"] + [r + ("," + ("nan" if k % every == 3 else "1"))
                                            for k, r in enumerate(rows)]
    path = tmp_path / "part.csv"
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path, sum(1 for k in range(len(rows)) if k % every == 3)


def _comment_lines() -> list[str]:
    lines = (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8").splitlines()
    return [line for line in lines[:10] if line.startswith("#")]


def test_the_reader_names_the_columns_and_the_first_line(tmp_path):
    path, n_bad = _with_quality(tmp_path)
    c = read_cloud(path)
    assert c.meta["invalid_dropped"] == n_bad and c.meta["invalid_columns"] == {"quality": n_bad}
    first = len(_comment_lines()) + 1 + 4  # the comments, the column names, then data rows 0…3
    assert c.meta["invalid_first_line"] == first
    words = read_warning(c)
    assert words.startswith(f"{n_bad:,} row(s) dropped on reading, each point whole: a NaN or infinite "
                            f"value in quality ({n_bad}), the first at line {first}")
    assert read_warning(read_cloud(EXAMPLE / "asphere_cmm.csv")) is None


def test_a_large_file_read_by_the_fast_reader_names_them_too(tmp_path):
    rng = np.random.default_rng(5)
    n = 160_000  # > 4 MB: Arrow's CSV reader
    x, y = rng.uniform(-10, 10, n), rng.uniform(-10, 10, n)
    q = np.where(np.arange(n) % 1000 == 10, np.nan, 1.0)
    path = tmp_path / "big.csv"
    np.savetxt(path, np.column_stack([x, y, 0.01 * x * y, q]), fmt="%.9f", delimiter=",",
               header="x,y,z,quality", comments="")
    assert path.stat().st_size > 4_000_000
    c = read_cloud(path)
    assert c.n == n - 160 and c.meta["invalid_columns"] == {"quality": 160}
    assert c.meta["invalid_first_line"] == 12


def test_the_batch_warns_and_the_report_says_which_columns(tmp_path, run_cli):
    path, n_bad = _with_quality(tmp_path)
    code, _, err = run_cli("--batch", EXAMPLE / "recipe.yaml", path, "--out", tmp_path / "o")
    assert code == 0, err
    assert (f"part.csv: warning: 'read': {n_bad:,} row(s) dropped on reading, each point whole: a NaN or "
            f"infinite value in quality ({n_bad})") in err
    rep = json.loads((tmp_path / "o" / "part" / "report.json").read_text(encoding="utf-8"))
    assert rep["input_file"]["invalid_dropped"] == n_bad
    assert rep["input_file"]["invalid_columns"] == {"quality": n_bad}


def test_an_instrument_map_s_masked_pixels_are_no_warning():
    """A review of the warning: every interferometer map with pixels masked outside its aperture (opd-1:
    116 of 640 × 480) was warned of, with advice (`invalid: error`) that does not apply to maps."""
    c = read_cloud(Path(__file__).resolve().parent / "data" / "realdata" / "opd-1.opd")
    assert c.meta["invalid_dropped"] > 0 and read_warning(c) is None


def test_a_point_file_s_dropped_rows_are_warned_of_without_columns(tmp_path):
    from pointspro.core.cloud import PointCloud
    from pointspro.core.io.npz import write_npz_cloud

    g = np.linspace(0.0, 1.0, 20)
    z = g.copy()
    z[4] = np.nan
    write_npz_cloud(PointCloud.from_xyz(g, g, np.nan_to_num(z)), tmp_path / "c.npz")
    with np.load(tmp_path / "c.npz") as f:
        arrays = dict(f)
    arrays["z"] = z
    np.savez(tmp_path / "c.npz", **arrays)
    c = read_cloud(tmp_path / "c.npz")
    assert read_warning(c) == ("1 row(s) dropped on reading, each point whole: a NaN or infinite value — the "
                               "recipe's input: {invalid: error} refuses such a file instead")
