"""Issue 26: large maps in bounded memory — chunked fits equal to the full design matrix, memory per
point bounded, a map too large for memory refused from its header before reading."""
from __future__ import annotations

import subprocess
import sys
import tracemalloc

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import memory as mem
from pointspro.core.io import read_cloud
from pointspro.core.maps import bspline as bs
from pointspro.core.metrics import zernike as zk


def _disk(n, seed, corner=False):
    rng = np.random.default_rng(seed)
    r = 50 * np.sqrt(rng.random(n))
    t = rng.random(n) * 2 * np.pi
    x, y = r * np.cos(t), r * np.sin(t)
    if corner:  # the data in one quadrant of the unit disk: an ill-conditioned fit (TSQR path)
        x, y = np.abs(x) * 0.5, np.abs(y) * 0.5
    z = 1e-4 * (x / 50) ** 2 - 3e-5 * (x * y / 2500) + 2e-6 * rng.standard_normal(n)
    return x, y, z


@pytest.mark.parametrize("n,seed,corner,terms", [
    (3 * zk.CHUNK + 17, 0, False, 36), (zk.CHUNK - 5, 1, False, 15), (50_000, 2, True, 36),
    (20_000, 3, True, 10), (40_000, 4, False, 66)])
def test_chunked_zernike_fit_equals_the_full_design_matrix(n, seed, corner, terms):
    x, y, z = _disk(n, seed, corner)
    pairs = zk.terms(terms, "fringe")
    f = zk.fit(x, y, z, 50.0, pairs)
    A = zk.design_matrix(x, y, 50.0, pairs)
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    _, sv, vt = np.linalg.svd(A, full_matrices=False)
    cond = sv[0] / sv[-1]
    assert f.cond == pytest.approx(cond, rel=1e-6)
    # the same numbers to 1e-9 relative on a well-posed pupil; on an ill-posed one (the data in a
    # corner: cond ~10⁸) no solver pins the coefficients below ε·cond, but the fit itself agrees
    tol = 1e-9 if cond < 1e4 else 1e-15 * cond * 10
    assert np.allclose(f.coef, coef, rtol=tol, atol=tol * np.abs(coef).max())
    resid = z - A @ coef
    assert np.abs(f.residual - resid).max() <= 1e-9 * np.abs(z).max()
    dof = n - len(pairs)
    ginv = (vt.T / sv**2) @ vt  # (AᵀA)⁻¹ from the SVD (forming AᵀA would square the condition)
    sd = np.sqrt(np.diag(ginv) * (resid @ resid) / dof)
    assert np.allclose(f.sd, sd, rtol=max(1e-6, tol))


def test_zernike_fit_holds_no_full_length_temporaries():
    """Beyond its inputs the fit holds the residual (one column) and chunk-sized blocks: the
    earlier form held u, v and the evaluated fit as full-length columns too (4 columns)."""
    n = 1_000_000
    x, y, z = _disk(n, 5)
    pairs = zk.terms(36, "fringe")
    tracemalloc.start()
    try:
        zk.fit(x, y, z, 50.0, pairs)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * n + 12 * 2**20, peak / n


def _dense_spline_system(x, y, z, w, h, x0, y0, nx, ny):
    shell = bs.TensorBSpline(x0, y0, h, np.zeros((nx + 3, ny + 3)))
    Bx = shell.design_1d(x, x0, nx).toarray()
    By = shell.design_1d(y, y0, ny).toarray()
    B = (Bx[:, :, None] * By[:, None, :]).reshape(len(x), -1)
    return B.T @ (w[:, None] * B), B.T @ (w * z)


def _box_points(rng, n, order):
    """n points in the 10 × 8 mm box with a smooth height and 1 % noise, in random order or sorted
    into rows (y-major, as a map is read)."""
    x, y = rng.uniform(-5, 5, n), rng.uniform(-4, 4, n)
    if order == "rows":
        k = np.lexsort((x, np.round(y, 1)))
        x, y = x[k], y[k]
    return x, y, np.sin(x) * np.cos(y) + 0.01 * rng.standard_normal(n)


@pytest.mark.parametrize("seed,order", [(0, "random"), (1, "rows"), (2, "random")])
def test_chunked_spline_moments_equal_the_dense_normal_equations(seed, order, monkeypatch):
    monkeypatch.setattr(bs, "CHUNK", 1000)  # many chunks, partial last one
    rng = np.random.default_rng(seed)
    n = 5_321
    x, y, z = _box_points(rng, n, order)
    w = rng.uniform(0.5, 2.0, n)
    h, nx, ny = 1.0, 10, 8
    x0, y0 = -5.0, -4.0
    mom = bs._cell_moments(x, y, z, w, x0, y0, h, nx, ny)
    ab, rhs, bw = bs._banded_normal_equations(mom, nx, ny)
    A, b = _dense_spline_system(x, y, z, w, h, x0, y0, nx, ny)
    N = A.shape[0]
    full = np.zeros_like(A)
    for d in range(bw + 1):  # upper band storage: ab[bw + i − j, j] = A[i, j]
        j = np.arange(d, N)
        full[j - d, j] = ab[bw - d, d:]
    full = np.triu(full) + np.triu(full, 1).T
    assert np.allclose(full, A, rtol=1e-12, atol=1e-12 * np.abs(A).max())
    assert np.allclose(rhs, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_weighted_spline_equals_the_fit_of_repeated_points():
    """Weight w (an integer here) = the point counted w times: Σ w (z − s)² (module doc). The system,
    penalty scale included (it follows trace(BᵀWB)), is then the same; the earlier weighting (bx
    and by both scaled by √w) gave w² and failed this."""
    rng = np.random.default_rng(7)
    n = 4000
    x, y = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
    z = 0.1 * x * y + 0.05 * rng.standard_normal(n)
    w = rng.integers(1, 4, n)
    b = (-5.0, 5.0, -5.0, 5.0)
    s = bs.fit_bspline(x, y, z, knot_spacing=1.25, weights=w.astype(float), bounds=b)
    rep = np.repeat(np.arange(n), w)
    r = bs.fit_bspline(x[rep], y[rep], z[rep], knot_spacing=1.25, bounds=b)
    assert np.allclose(s.coef, r.coef, rtol=1e-9, atol=1e-10)


def test_spline_fit_memory_per_point_is_small():
    """The linear part of fit_bspline's memory: a few bytes a point (chunked moments), not the
    ~200 B/point of 116 full-length products."""
    peaks = []
    for n in (400_000, 800_000):
        x, y, z = _disk(n, 3)
        tracemalloc.start()
        try:
            bs.fit_bspline(x, y, z, knot_spacing=100 / 150)
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
    assert (peaks[1] - peaks[0]) / 400_000 < 16, [p / 1e6 for p in peaks]


# --- a map too large for memory: refused from its header, before reading ---------------------------
def _fake_ply(path, n):
    path.write_bytes(("ply\nformat binary_little_endian 1.0\n"
                      f"element vertex {n}\nproperty double x\nproperty double y\nproperty double z\n"
                      "end_header\n").encode("ascii") + np.zeros(30).tobytes())
    return path


def test_a_header_claiming_1e11_points_is_refused_before_reading(tmp_path, monkeypatch):
    monkeypatch.delenv("POINTSPRO_MEMORY_CHECK", raising=False)
    p = _fake_ply(tmp_path / "huge.ply", 10**11)
    with pytest.raises(InputError) as e:
        read_cloud(p)
    msg = str(e.value)
    assert "huge.ply" in msg and "100,000,000,000 points" in msg and "nothing was read" in msg
    # 30 doubles under it: the count is the fault, not the memory (no advice to decimate)
    assert "more than the file holds — the header is damaged or the file truncated" in msg
    assert "decimate" not in msg
    # a text PLY too (a review: 10¹² vertices over 8 bytes was advised to decimate)
    t = tmp_path / "huge_text.ply"
    t.write_text("ply\nformat ascii 1.0\nelement vertex 999999999999\nproperty double x\nproperty double y\n"
                 "property double z\nend_header\n0 0 0\n", encoding="ascii")
    with pytest.raises(InputError, match=r"huge_text\.ply: its PLY header \(element vertex\) states "
                                         r"999,999,999,999 points, more than the file holds"):
        read_cloud(t)


def test_memory_check_against_a_stated_budget(tmp_path, monkeypatch):
    monkeypatch.delenv("POINTSPRO_MEMORY_CHECK", raising=False)
    budget = mem.BASE_BYTES + 1_000_000 * mem.BYTES_PER_POINT
    mem.check_fits("m.ply", 1_000_000, available=budget)  # fits exactly
    with pytest.raises(InputError, match=r"m\.ply: its header states 4,000,000 points.*About "
                                         r"1,000,000 points fit.*k ≥ 2 along each axis"):
        mem.check_fits("m.ply", 4_000_000, available=budget)
    monkeypatch.setenv("POINTSPRO_MEMORY_CHECK", "0")
    mem.check_fits("m.ply", 4_000_000, available=budget)


def test_available_bytes_is_plausible():
    a = mem.available_bytes()
    assert a is None or 0 <= a < 2**50


def test_batch_refuses_the_huge_map_in_one_line_and_writes_nothing(tmp_path):
    p = _fake_ply(tmp_path / "huge.ply", 10**11)
    recipe = tmp_path / "r.yaml"
    recipe.write_text("pointspro: 1\nsteps:\n  - zernike: {terms: 36}\n  - bspline_map: {}\n",
                      encoding="utf-8")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(p),
                           "--out", str(out), "--quiet"], capture_output=True, text=True,
                          encoding="utf-8", env={**__import__("os").environ, "POINTSPRO_MEMORY_CHECK": "1"})
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr + proc.stdout
    assert "100,000,000,000 points" in proc.stderr + proc.stdout
    assert not (out / "huge").exists()


# --- a gridded input stays a grid ----------------------------------------------------------------
def _grid_ply(path, n=120, seed=0, shuffle=False, jitter=0.0):
    from pointspro.core.io.ply import write_ply

    rng = np.random.default_rng(seed)
    h = 100.0 / n
    ax = -50.0 + h * (np.arange(n) + 0.5)
    X, Y = np.meshgrid(ax, ax)
    keep = (X**2 + Y**2 <= 2500) & (rng.random(X.shape) > 0.02)  # a disk with dropouts
    x, y = X[keep], Y[keep]
    x = x + jitter * h * rng.standard_normal(len(x))
    z = 1e-4 * ((x / 50) ** 2 + (y / 50) ** 2) + 3e-5 * (x / 50) ** 3 + 1e-6 * rng.standard_normal(len(x))
    if shuffle:
        k = rng.permutation(len(x))
        x, y, z = x[k], y[k], z[k]
    write_ply(path, np.column_stack([x, y, z]), {})
    return path


@pytest.mark.parametrize("n,seed,shuffle", [(120, 0, False), (97, 1, True), (64, 2, False)])
def test_ply_pixel_grid_is_recorded(tmp_path, n, seed, shuffle):
    c = read_cloud(_grid_ply(tmp_path / "g.ply", n, seed, shuffle))
    assert c.meta["grid"] == [n, n]
    assert c.meta["pixel_mm"] == pytest.approx([100.0 / n] * 2, rel=1e-12)
    assert c.meta["grid_origin_mm"] == pytest.approx([-50 + 50.0 / n] * 2, rel=1e-12)


def test_scattered_or_jittered_ply_is_no_grid(tmp_path):
    assert "grid" not in read_cloud(_grid_ply(tmp_path / "j.ply", 80, 3, jitter=1e-3)).meta
    from pointspro.core.io.gridcloud import detect_grid

    rng = np.random.default_rng(4)
    assert detect_grid(rng.random(5000), rng.random(5000)) is None
    # the same pixel twice is no map
    x = np.repeat(np.arange(10.0), 10)
    y = np.tile(np.arange(10.0), 10)
    assert detect_grid(np.r_[x, 3.0], np.r_[y, 4.0]) is None


def _batch(tmp_path, data, recipe_text, out, *extra):
    recipe = tmp_path / "r.yaml"
    recipe.write_text(recipe_text, encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(data),
                           "--out", str(out), "--quiet", "--figures", "none", *extra],
                          capture_output=True, text=True, encoding="utf-8")
    assert proc.returncode == 0, proc.stderr
    import json

    return json.loads((out / data.stem / "report.json").read_text(encoding="utf-8"))


ZRECIPE = "pointspro: 1\nsteps:\n  - zernike: {terms: 36, remove: [piston, tilt, power]}\n"


def test_gridded_input_writes_cloud_x3p_by_default_and_csv_on_request(tmp_path):
    data = _grid_ply(tmp_path / "map.ply", 90, 5, shuffle=True)
    rep = _batch(tmp_path, data, ZRECIPE, tmp_path / "a")
    folder = tmp_path / "a" / "map"
    assert rep["cloud_file"] == "cloud.x3p" and rep["cloud_format_asked"] == "auto"
    assert "regular grid (90 × 90 pixels" in rep["cloud_file_note"]
    assert "--cloud-format csv" in rep["cloud_file_note"]
    assert sorted(p.name for p in folder.glob("cloud.*")) == ["cloud.x3p"]
    rep_csv = _batch(tmp_path, data, ZRECIPE, tmp_path / "b", "--cloud-format", "csv")
    assert rep_csv["cloud_file"] == "cloud.csv"
    ref = read_cloud(tmp_path / "b" / "map" / "cloud.csv")
    got = read_cloud(folder / "cloud.x3p")  # the residual as the map's heights
    assert got.n == ref.n
    a = np.lexsort((ref.x, ref.y))
    b = np.lexsort((got.x, got.y))
    assert np.allclose(got.x[b], ref.x[a], rtol=0, atol=1e-12)
    assert np.allclose(got.y[b], ref.y[a], rtol=0, atol=1e-12)
    assert np.allclose(got.z[b], ref["residual"][a], rtol=1e-14, atol=1e-20)
    # --resume with the default finds the x3p output complete
    recipe = tmp_path / "r.yaml"
    proc = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(data),
                           "--out", str(tmp_path / "a"), "--quiet", "--figures", "none", "--resume"],
                          capture_output=True, text=True, encoding="utf-8")
    assert proc.returncode == 0, proc.stderr
    import json

    summary = json.loads((tmp_path / "a" / "summary.json").read_text(encoding="utf-8"))
    assert summary["inputs"][0]["status"] == "skipped"


def test_scattered_input_keeps_cloud_csv_and_says_why(tmp_path):
    data = _grid_ply(tmp_path / "s.ply", 60, 6, jitter=1e-3)
    rep = _batch(tmp_path, data, ZRECIPE, tmp_path / "o")
    assert rep["cloud_file"] == "cloud.csv"
    assert "not a regular grid" in rep["cloud_file_note"]


def test_spline_evaluation_holds_only_its_result():
    """s(x, y) and its slopes: the result (8 bytes a point) and chunk-sized blocks; the earlier form
    held ~100 bytes a point of cell indices and basis values (bspline_map's and the summary's peak)."""
    x, y, z = _disk(50_000, 8)
    s = bs.fit_bspline(x, y, z, knot_spacing=5.0)
    peaks = []
    for n in (400_000, 800_000):
        x, y, _ = _disk(n, 9)
        tracemalloc.start()
        try:
            s(x, y, dx=1)
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
    assert (peaks[1] - peaks[0]) / 400_000 < 16, [p / 1e6 for p in peaks]


@pytest.mark.parametrize("order", ["random", "rows"])
def test_threaded_spline_moments_are_bit_identical(order, monkeypatch):
    """Chunks computed by several threads and added in chunk order: the same bits as one thread, so a
    map does not depend on how many cores the process had (a batch's --workers)."""
    monkeypatch.setattr(bs, "CHUNK", 700)
    x, y, z = _box_points(np.random.default_rng(11), 9_999, order)
    one = bs._cell_moments(x, y, z, None, -5.0, -4.0, 1.0, 10, 8, threads=1)
    for threads in (2, 3, 8):
        assert np.array_equal(bs._cell_moments(x, y, z, None, -5.0, -4.0, 1.0, 10, 8, threads=threads), one)


def test_a_cloud_format_asked_for_is_said_so(tmp_path):
    """With --cloud-format ply the report had no cloud_file_note (the README says every report names
    its cloud file and why; a review)."""
    data = _grid_ply(tmp_path / "s.ply", 60, 6, jitter=1e-3)
    rep = _batch(tmp_path, data, ZRECIPE, tmp_path / "o", "--cloud-format", "ply")
    assert rep["cloud_file"] == "cloud.ply" and rep["cloud_file_note"] == "cloud.ply: asked by --cloud-format ply"
