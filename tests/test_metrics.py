"""Zernike polynomials, form metrics (PV, RMS, PVr, slope RMS), profiles and PSDs."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core.metrics import form_metrics, pvr
from pointspro.core.metrics import zernike as zk


@pytest.mark.parametrize("ordering,j,nm", [
    ("noll", 1, (0, 0)), ("noll", 2, (1, 1)), ("noll", 3, (1, -1)), ("noll", 4, (2, 0)),
    ("noll", 5, (2, -2)), ("noll", 6, (2, 2)), ("noll", 7, (3, -1)), ("noll", 8, (3, 1)),
    ("noll", 11, (4, 0)), ("noll", 22, (6, 0)),
    ("ansi", 0, (0, 0)), ("ansi", 1, (1, -1)), ("ansi", 2, (1, 1)), ("ansi", 4, (2, 0)),
    ("ansi", 12, (4, 0)), ("ansi", 24, (6, 0)),
    ("fringe", 1, (0, 0)), ("fringe", 2, (1, 1)), ("fringe", 3, (1, -1)), ("fringe", 4, (2, 0)),
    ("fringe", 5, (2, 2)), ("fringe", 6, (2, -2)), ("fringe", 9, (4, 0)), ("fringe", 16, (6, 0)),
    # beyond Z36 the formula continues with the next group ((6, 6) …), not Code V's Z37 = (12, 0)
    ("fringe", 36, (10, 0)), ("fringe", 37, (6, 6)),
])
def test_index_conventions(ordering, j, nm):
    assert zk.nm_of(j, ordering) == nm
    assert zk.index_of(*nm, ordering) == j


@pytest.mark.parametrize("ordering", ["ansi", "noll", "fringe"])
def test_orderings_are_bijections(ordering):
    pairs = zk.terms(66, ordering)
    assert len(set(pairs)) == 66
    assert [zk.index_of(n, m, ordering) for n, m in pairs] == list(
        range(zk.first_index(ordering), zk.first_index(ordering) + 66))


def test_closed_forms():
    rho = np.linspace(0, 1, 11)
    th = np.linspace(0, 2 * np.pi, 11)
    assert np.allclose(zk.zernike(2, 0, rho, th), np.sqrt(3) * (2 * rho**2 - 1), atol=1e-15)
    assert np.allclose(zk.zernike(4, 0, rho, th), np.sqrt(5) * (6 * rho**4 - 6 * rho**2 + 1), atol=1e-14)
    assert np.allclose(zk.zernike(3, 1, rho, th), np.sqrt(8) * (3 * rho**3 - 2 * rho) * np.cos(th),
                       atol=1e-14)
    assert np.allclose(zk.zernike(2, -2, rho, th), np.sqrt(6) * rho**2 * np.sin(2 * th), atol=1e-15)
    assert np.allclose(zk.zernike(4, 0, rho, th, "peak"), 6 * rho**4 - 6 * rho**2 + 1, atol=1e-14)


def test_orthonormal_by_quadrature():
    """(1/π)∬ Z_i Z_j dA = δ_ij by Gauss–Legendre in ρ² and the trapezoid rule in θ (exact for
    these polynomials)."""
    from numpy.polynomial.legendre import leggauss

    t, w = leggauss(40)
    u = 0.5 * (t + 1)            # u = ρ², dA = ρ dρ dθ = ½ du dθ
    rho = np.sqrt(u)
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    R, T = np.meshgrid(rho, th)
    W = np.outer(np.full(len(th), 2 * np.pi / len(th)), 0.5 * w * 0.5)
    pairs = zk.terms(45, "noll")
    Z = np.array([zk.zernike(n, m, R, T) for n, m in pairs])
    G = np.einsum("iab,jab,ab->ij", Z, Z, W) / np.pi
    assert np.allclose(G, np.eye(len(pairs)), atol=1e-12)


def test_fit_recovers_coefficients_on_scattered_points():
    rng = np.random.default_rng(3)
    r = 50 * np.sqrt(rng.random(4000))
    t = 2 * np.pi * rng.random(4000)
    x, y = r * np.cos(t), r * np.sin(t)
    pairs = zk.terms(36, "fringe")
    true = rng.normal(0, 1e-4, len(pairs))
    z = zk.design_matrix(x, y, 50.0, pairs) @ true + rng.normal(0, 1e-6, len(x))
    coef, sd, resid, cond = zk.fit(x, y, z, 50.0, pairs)
    assert np.all(np.abs(coef - true) < 5 * sd + 1e-12)
    assert np.all(sd < 1e-7) and cond < 100


def test_pvr_is_robust_to_one_spike_and_pv_is_not():
    rng = np.random.default_rng(5)
    r = 100 * np.sqrt(rng.random(20000))
    t = 2 * np.pi * rng.random(20000)
    x, y = r * np.cos(t), r * np.sin(t)
    form = 1e-4 * zk.zernike(2, 2, r / 100, t) + rng.normal(0, 2e-6, len(x))
    spiked = form.copy()
    spiked[123] += 5e-3
    assert np.ptp(spiked) > 5 * np.ptp(form)
    # the spike moves PV by 4.5 µm; PVr by its 3·RMS share only (3 · 5 µm / √20000 ≈ 0.1 µm)
    d_pv = np.ptp(spiked) - np.ptp(form)
    d_pvr = pvr(x, y, spiked, 100) - pvr(x, y, form, 100)
    assert 0 < d_pvr < 0.03 * d_pv
    # PVr of a pure Zernike shape ≈ its PV (the fit holds it whole)
    assert pvr(x, y, form, 100) == pytest.approx(np.ptp(1e-4 * zk.zernike(2, 2, r / 100, t)), rel=0.05)


def test_slope_rms_of_a_known_surface():
    """z = a·cos(2πx/L): slope RMS = a·2π/L/√2 (no tilt)."""
    g = np.arange(-100, 100.01, 1.0)
    X, Y = np.meshgrid(g, g)
    a, L = 1e-4, 50.0
    z = a * np.cos(2 * np.pi * X / L)
    m = form_metrics(X.ravel(), Y.ravel(), z.ravel())
    expect = a * 2 * np.pi / L / np.sqrt(2) * 1e6
    assert m["slope_rms_urad"] == pytest.approx(expect, rel=0.03)
    assert m["rms_um"] == pytest.approx(a / np.sqrt(2) * 1e3, rel=0.01)
    assert m["pv_um"] == pytest.approx(2 * a * 1e3, rel=1e-6)


def _grid(z, spacing, xs=None):
    from pointspro.core.maps import MapGrid

    ny, nx = z.shape
    xs = spacing * (np.arange(nx) - nx // 2)
    ys = spacing * (np.arange(ny) - ny // 2)
    return MapGrid(xs, ys, z, spacing)


def test_psd_parseval_and_peak():
    from pointspro.core.metrics.profiles import psd_1d, psd_2d

    rng = np.random.default_rng(1)
    d = 0.5
    n = 256
    x = d * np.arange(n)
    X, Y = np.meshgrid(x, x)
    f0 = 0.1
    z = 1e-4 * np.sin(2 * np.pi * f0 * X) + rng.normal(0, 1e-5, (n, n))
    g = _grid(z, d)
    f, p = psd_1d(g, "x")
    var = np.var(z)
    assert np.sum(p) * (f[1] - f[0]) == pytest.approx(var, rel=0.05)
    assert f[np.argmax(p)] == pytest.approx(f0, abs=1 / (n * d))
    fx, fy, P = psd_2d(g)
    assert np.sum(P) * (fx[1] - fx[0]) * (fy[1] - fy[0]) == pytest.approx(var, rel=0.05)


def test_profiles_of_a_known_map():
    from pointspro.core.metrics.profiles import profile, radial_profile

    d = 1.0
    n = 201
    xs = d * (np.arange(n) - 100)
    X, Y = np.meshgrid(xs, xs)
    z = 1e-3 * (X**2 + Y**2) / 100**2
    z[np.hypot(X, Y) > 100] = np.nan
    g = _grid(z, d)
    s, v = profile(g, 30.0)
    assert s.min() >= -100.5 and s.max() <= 100.5
    assert np.allclose(v, 1e-3 * s**2 / 100**2, atol=2e-7)
    r, mean, std = radial_profile(g)
    assert np.allclose(mean, 1e-3 * r**2 / 100**2, rtol=0.02, atol=2e-6)


@pytest.mark.parametrize("ordering,count", [("fringe", 36), ("noll", 66), ("ansi", 28)])
def test_design_matrix_by_recurrence_equals_the_definition(ordering, count):
    """The chunked design matrix ((u + iv)^|m| and the Jacobi recurrence) equals Z_n^m evaluated by
    the definition (arctan2, cos/sin, scipy's eval_jacobi), over chunk boundaries too."""
    rng = np.random.default_rng(11)
    n = zk.CHUNK + 1234
    x, y = rng.uniform(-60, 60, n), rng.uniform(-55, 65, n)
    pairs = zk.terms(count, ordering)
    c, R = (3.0, 5.0), 70.0
    A = zk.design_matrix(x, y, R, pairs, center=c)
    rho, th = np.hypot(x - c[0], y - c[1]) / R, np.arctan2(y - c[1], x - c[0])
    ref = np.column_stack([zk.zernike(nn, m, rho, th) for nn, m in pairs])
    assert np.allclose(A, ref, rtol=0, atol=1e-11)
    coef = rng.normal(size=len(pairs))
    assert np.allclose(zk.evaluate(x, y, coef, R, pairs, center=c), ref @ coef, rtol=0, atol=1e-10)


@pytest.mark.parametrize("corner", [False, True])
def test_chunked_fit_equals_numpy_lstsq(corner):
    """Chunked fit (normal equations on a centred disk; TSQR when the data fill one corner of the
    pupil, cond ~10⁶) against numpy's lstsq of the whole matrix: coefficients, residual, cond."""
    rng = np.random.default_rng(5 + corner)
    n = 2 * zk.CHUNK + 777
    if corner:  # a map whose pupil sits at its corner: the ill-conditioned case of issue 15
        x, y, R, c = rng.uniform(0, 6, n), rng.uniform(0, 4, n), 7.3, (0.0, 0.0)
    else:
        r, t = 40 * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
        x, y, R, c = r * np.cos(t) + 2, r * np.sin(t) - 1, 40.0, (2.0, -1.0)
    pairs = zk.terms(36, "fringe")
    z = 1e-4 * np.sin(x / 3) * np.cos(y / 5) + rng.normal(0, 1e-6, n)
    f = zk.fit(x, y, z, R, pairs, center=c)
    A = zk.design_matrix(x, y, R, pairs, center=c)
    coef, _, _, sv = np.linalg.lstsq(A, z, rcond=None)
    assert (f.cond > 1e5) == corner
    assert f.cond == pytest.approx(sv[0] / sv[-1], rel=1e-6)
    assert np.allclose(f.residual, z - A @ coef, rtol=0, atol=1e-9 * np.ptp(z))
    if not corner:
        assert np.allclose(f.coef, coef, rtol=1e-9, atol=1e-15)


def test_pvr_is_not_given_on_72_points_or_fewer_never_the_pv_in_its_place():
    """The 36-term fit needs more than twice its terms: with 72 points or fewer PVr is None (it was
    the plain PV under PVr's name); the summary says null and a tolerance on PVr 'not computed'."""
    rng = np.random.default_rng(5)
    for n, given in ((60, False), (72, False), (73, True), (200, True)):
        x, y = rng.uniform(-10, 10, (2, n))
        r = 1e-4 * (x * x - y * y) / 100 + 1e-6 * rng.standard_normal(n)
        assert (pvr(x, y, r, 15.0) is not None) == given, n
        m = form_metrics(x, y, r, 15.0, slopes=False)
        assert (m["pvr_um"] is not None) == given and m["pv_um"] > 0
