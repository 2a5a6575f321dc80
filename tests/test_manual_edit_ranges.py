"""manual_edit's compact form (issue 26): runs of consecutive input rows as ``remove_ranges`` pairs
[first, last], written by the window, replayed exactly by the step; the old ``remove`` list keeps its
meaning. Also the binary PLY reader's layouts (issue 26: read straight into the coordinate array)."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import RecipeError
from pointspro.core.recipe import make_step
from pointspro.core.session import Session
from pointspro.core.session.model import rows_to_ranges


def _expand(single, ranges) -> np.ndarray:
    parts = [np.asarray(single, dtype=np.int64)] + [np.arange(a, b + 1) for a, b in ranges]
    return np.unique(np.concatenate(parts)) if parts else np.empty(0, np.int64)


def _run(cloud, params):
    from pointspro.core.step import Context
    from pointspro.plugins.manual_edit import ManualEditStep

    return ManualEditStep().run(cloud, make_step("manual_edit", params).params, Context())


def _cloud(n):
    return PointCloud.from_xyz(np.arange(n, dtype=np.float64), np.zeros(n), np.zeros(n))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_rows_to_ranges_is_exact_and_compact(seed):
    rng = np.random.default_rng(seed)
    # runs of random lengths (1 included) with random gaps, as raster rows cut by a lasso
    lengths = rng.integers(1, 50, 400)
    gaps = rng.integers(2, 30, 400)
    starts = np.cumsum(gaps + np.concatenate(([0], lengths[:-1]))) + rng.integers(0, 5)
    rows = np.concatenate([np.arange(s, s + k) for s, k in zip(starts, lengths)])
    single, ranges = rows_to_ranges(rows)
    assert np.array_equal(_expand(single, ranges.tolist()), rows)
    assert ranges.shape == (int(np.count_nonzero(lengths > 1)), 2) and single.size == np.count_nonzero(lengths == 1)
    assert np.all(ranges[:, 1] > ranges[:, 0])
    s, r = rows_to_ranges(np.array([], dtype=np.int64))
    assert s.size == 0 and r.shape == (0, 2)
    s, r = rows_to_ranges(np.array([7]))
    assert s.tolist() == [7] and r.shape == (0, 2)


@pytest.mark.parametrize("seed", [0, 5, 11])
def test_step_removes_the_union_of_rows_and_ranges(seed):
    rng = np.random.default_rng(seed)
    n = 5000
    cloud = _cloud(n).select(rng.permutation(n)[: n - 300])  # shuffled rows, 300 already gone
    a = np.sort(rng.integers(0, n + 200, 120))
    ranges = [[int(x), int(x + rng.integers(0, 40))] for x in a]  # overlapping, out of range too
    single = rng.integers(0, n + 50, 60).tolist()
    res = _run(cloud, {"remove": single, "remove_ranges": ranges})
    wanted = _expand(single, ranges)
    assert np.array_equal(res.cloud.index, cloud.index[~np.isin(cloud.index, wanted)])
    absent = np.setdiff1d(wanted, cloud.index)
    assert res.report["removed"] == cloud.n - res.cloud.n
    got = _expand(res.report["not_found"], res.report["not_found_ranges"])
    assert np.array_equal(got, absent)
    assert f"{absent.size} index value(s) not in this cloud" in res.report["warnings"][0]


def test_old_form_keeps_its_meaning_and_a_huge_range_is_not_expanded():
    cloud = _cloud(100)
    old = _run(cloud, {"remove": [3, 4, 5, 99, 150]})
    assert old.cloud.index.tolist() == [i for i in range(100) if i not in (3, 4, 5, 99)]
    assert old.report["not_found"] == [150] and "not_found_ranges" not in old.report
    new = _run(cloud, {"remove": [99, 150], "remove_ranges": [[3, 5]]})
    assert np.array_equal(new.cloud.index, old.cloud.index) and new.report["not_found"] == [150]
    # the runs are tested, never expanded into rows: 10¹² rows named, 90 of them in the cloud
    big = _run(cloud, {"remove_ranges": [[10, 10**12]]})
    assert big.cloud.index.tolist() == list(range(10))
    assert big.report["not_found_ranges"] == [[100, 10**12]]
    assert f"{10**12 - 99} index value(s)" in big.report["warnings"][0]


@pytest.mark.parametrize("bad, says", [
    ([[3, 1]], r"key 'remove_ranges': .*pair 1 is \[3, 1\]"),
    ([[0, 2], [-1, 2]], r"key 'remove_ranges': .*pair 2 is \[-1, 2\]"),
    ([[1, 2, 3]], r"key 'remove_ranges.0'"),
    ([5], r"key 'remove_ranges.0'"),
])
def test_bad_ranges_are_one_line_naming_the_key(bad, says):
    with pytest.raises(RecipeError, match=says):
        make_step("manual_edit", {"remove_ranges": bad})


def test_a_lasso_of_a_million_raster_rows_saves_compactly_and_replays_exactly(tmp_path):
    from pointspro.core.io import write_cloud

    # a 1500 × 1500 pixel map in raster order; a lumpy disc of ~10⁶ of its pixels deleted
    nx = 1500
    j, i = np.divmod(np.arange(nx * nx), nx)
    x, y = (i - 700.0) / nx, (j - 760.0) / nx
    rng = np.random.default_rng(4)
    z = 1e-4 * rng.standard_normal(x.size)
    path = tmp_path / "map.ply"
    write_cloud(PointCloud.from_xyz(x, y, z), path)
    s = Session()
    s.open(path)
    t = np.arctan2(y, x)
    mask = np.hypot(x, y) < 0.37 * (1 + 0.1 * np.sin(3 * t))
    assert 0.9e6 < mask.sum() < 1.1e6
    assert s.delete(mask) == mask.sum()
    p = s.recipe.steps[-1].params
    assert np.array_equal(_expand(p.remove, p.remove_ranges), np.flatnonzero(mask))
    assert len(p.remove_ranges) < 2 * nx  # a pair or two per raster row, not 10⁶ numbers
    proj = tmp_path / "p.pointspro.yaml"
    s.save_project(proj)
    assert proj.stat().st_size < 100_000
    s2 = Session()
    s2.open_project(proj)
    assert np.array_equal(s2.shown.index, np.flatnonzero(~mask))
    assert s2.recipe.steps[-1].params == p
    # the recipe alone replays the same cleanup
    rec = tmp_path / "r.yaml"
    s.save_recipe(rec)
    s3 = Session()
    s3.open(path)
    s3.load_recipe(rec)
    assert np.array_equal(s3.run().cloud.index, np.flatnonzero(~mask))


@pytest.mark.parametrize("order", ["<", ">"])
def test_binary_ply_layouts_read_the_same_numbers(tmp_path, order):
    from pointspro.core.io.ply import read_ply

    fmt = "binary_little_endian" if order == "<" else "binary_big_endian"
    rng = np.random.default_rng(7)
    v = rng.standard_normal((257, 3))
    head = f"ply\nformat {fmt} 1.0\nelement vertex 257\n"
    # x, y, z double alone: read into the coordinate array itself
    a = np.empty(257, np.dtype([(c, order + "f8") for c in "xyz"]))
    a["x"], a["y"], a["z"] = v.T
    (tmp_path / "a.ply").write_bytes((head + "property double x\nproperty double y\nproperty double z\n"
                                      "end_header\n").encode("ascii") + a.tobytes())
    xyz, cols, _ = read_ply(tmp_path / "a.ply")
    assert xyz.dtype == np.float64 and xyz.flags.c_contiguous and np.array_equal(xyz, v) and cols == {}
    # another layout: properties in another order and types, an extra channel
    dt = np.dtype([("i", order + "i4"), ("z", order + "f4"), ("x", order + "f8"), ("y", order + "i2")])
    b = np.empty(257, dt)
    b["i"], b["z"], b["x"], b["y"] = np.arange(257), v[:, 2], v[:, 0], np.round(100 * v[:, 1])
    (tmp_path / "b.ply").write_bytes((head + "property int i\nproperty float z\nproperty double x\n"
                                      "property short y\nend_header\n").encode("ascii") + b.tobytes())
    xyz, cols, _ = read_ply(tmp_path / "b.ply")
    assert np.array_equal(xyz[:, 0], v[:, 0]) and np.array_equal(xyz[:, 1], np.round(100 * v[:, 1]))
    assert np.array_equal(xyz[:, 2], v[:, 2].astype(np.float32).astype(np.float64))
    assert list(cols) == ["i"] and cols["i"].dtype == np.int64 and cols["i"].tolist() == list(range(257))
    # truncated: one clear message, before or while reading
    data = (tmp_path / "a.ply").read_bytes()
    (tmp_path / "c.ply").write_bytes(data[:-9])
    from pointspro.core.errors import InputError

    with pytest.raises(InputError, match=r"c.ply: PLY file is truncated"):
        read_ply(tmp_path / "c.ply")


def test_rows_beyond_2_62_are_refused_and_the_absent_rows_are_reported_up_to_it():
    """[[5, 2⁶³ − 1]] reported no absent rows (the run's end + 1 wrapped); rows are now ≤ 2⁶²."""
    import numpy as np

    import pointspro.core as pp
    from pointspro.core.errors import RecipeError

    c = pp.PointCloud.from_numpy(np.random.default_rng(0).normal(size=(10, 3)))
    res = pp.run({"steps": [{"manual_edit": {"remove_ranges": [[5, 2**62]]}}]}, c)
    assert res.cloud.n == 5 and res.steps[0].report["not_found_ranges"] == [[10, 2**62]]
    for bad in ({"remove_ranges": [[2**63 - 2, 2**63 - 1]]}, {"remove": [2**62 + 1]}):
        with pytest.raises(RecipeError, match="at most"):
            pp.run({"steps": [{"manual_edit": bad}]}, c)
