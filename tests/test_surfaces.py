"""Nominal surfaces against closed forms, arbitrary-precision references and finite differences."""
from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from pointspro.core.errors import DomainError, InputError
from pointspro.core.surfaces import EvenAsphere, MeshSurface, XYPolynomial, surface_from_spec

mp.mp.dps = 50

# (c [1/mm], k, A, aperture [mm]) — concave/convex, k < −1, k = 0, k > 0, high orders
CASES = {
    "002_table1_concave": (1 / 3000, -0.98, {4: 7e-13, 6: 1e-19}, 1300),
    "002_data1_convex": (-1 / 1646.4, -0.9861, {4: 4e-16}, 600),
    "002_data2": (1 / 2085, -0.97, {4: 3e-19, 6: -2e-23}, 1000),
    "hyperbola_k_lt_-1": (1 / 500, -1.8, {}, 400),
    "sphere_k0": (1 / 200, 0.0, {}, 380),
    "oblate_k_gt_0": (-1 / 150, 0.6, {}, 180),
    "high_order": (1 / 80, -0.5, {4: 2e-7, 6: -3e-11, 8: 1e-15, 10: -2e-19, 12: 5e-24}, 60),
}


def mp_sag(c, k, A, r):
    c, k, r = mp.mpf(c), mp.mpf(k), mp.mpf(r)
    z = c * r ** 2 / (1 + mp.sqrt(1 - (1 + k) * c ** 2 * r ** 2))
    return z + sum(mp.mpf(a) * r ** n for n, a in A.items())


@pytest.mark.parametrize("name", CASES)
def test_even_asphere_sag_and_slope_exact_to_float64(name):
    c, k, A, D = CASES[name]
    s = EvenAsphere(c, k, A, D)
    r = np.linspace(0, D / 2, 101)
    z = s.sag_r(r)
    zr = np.array([float(mp_sag(c, k, A, ri)) for ri in r])
    scale = np.max(np.abs(zr)) + 1e-300
    assert np.max(np.abs(z - zr)) <= 4 * np.finfo(float).eps * scale
    slope = s.slope_r(r)
    sref = np.array([float(mp.diff(lambda t: mp_sag(c, k, A, t), mp.mpf(ri))) for ri in r])
    assert np.max(np.abs(slope - sref)) <= 1e-13 * (np.max(np.abs(sref)) + 1)


@pytest.mark.parametrize("name", CASES)
def test_even_asphere_gradient_matches_finite_differences(name):
    c, k, A, D = CASES[name]
    s = EvenAsphere(c, k, A, D)
    rng = np.random.default_rng(1)
    rr = np.sqrt(rng.uniform(0, 1, 200)) * D / 2 * 0.999
    t = rng.uniform(0, 2 * np.pi, 200)
    x, y = rr * np.cos(t), rr * np.sin(t)
    gx, gy = s.gradient(x, y)
    h = 1e-5 * D
    fx = (s.sag(x + h, y) - s.sag(x - h, y)) / (2 * h)
    fy = (s.sag(x, y + h) - s.sag(x, y - h)) / (2 * h)
    # central differences: truncation h²·f'''/6 (≤ 1e-7 on the steepest case, a sphere at 0.95 R)
    assert np.max(np.abs(gx - fx) / (1 + np.abs(gx))) < 1e-7
    assert np.max(np.abs(gy - fy) / (1 + np.abs(gy))) < 1e-7
    n = s.normal(x, y)
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-15)
    assert np.all(n[:, 2] > 0)
    assert np.allclose(n[:, 0] / n[:, 2], -gx, atol=1e-15) and np.allclose(n[:, 1] / n[:, 2], -gy, atol=1e-15)


def test_closed_forms_sphere_and_paraboloid():
    R = 200.0
    r = np.linspace(0, 190, 50)
    assert np.allclose(EvenAsphere(1 / R, 0).sag_r(r), R - np.sqrt(R * R - r * r), rtol=1e-13, atol=1e-13)
    assert np.allclose(EvenAsphere(-1 / R, 0).sag_r(r), -(R - np.sqrt(R * R - r * r)), rtol=1e-13, atol=1e-13)
    c = 1 / 350
    assert np.allclose(EvenAsphere(c, -1).sag_r(r), c * r * r / 2, rtol=1e-15, atol=0)
    # sphere slope: dz/dr = r / sqrt(R² − r²)
    assert np.allclose(EvenAsphere(1 / R, 0).slope_r(r), r / np.sqrt(R * R - r * r), rtol=1e-13)
    # on the axis the gradient is exactly zero
    gx, gy = EvenAsphere(1 / R, 0, {4: 1e-9}).gradient(np.zeros(1), np.zeros(1))
    assert gx[0] == 0.0 and gy[0] == 0.0


def test_near_vertex_no_cancellation():
    """z ≈ c r²/2 at r = 1 µm on a 3 m mirror: R − sqrt(R² − r²) would lose every digit."""
    s = EvenAsphere(1 / 3000, -0.98)
    r = 1e-3
    assert s.sag_r(np.array([r]))[0] == pytest.approx(float(mp_sag(1 / 3000, -0.98, {}, r)), rel=1e-15)


def test_domain_error_names_radius():
    s = EvenAsphere(1 / 100, 0.0)  # sphere of R 100 exists for r ≤ 100
    with pytest.raises(DomainError, match=r"2 point\(s\) at r up to 150 mm lie outside the conic's domain r ≤ 100"):
        s.sag(np.array([0.0, 120.0, 150.0]), np.zeros(3))
    with pytest.raises(DomainError):
        s.gradient(np.array([101.0]), np.zeros(1))
    # hyperboloids and k < -1 have no limit
    assert np.isfinite(EvenAsphere(1 / 100, -2).sag(np.array([1e4]), np.zeros(1))).all()


def test_xy_polynomial_values_and_gradient():
    s = XYPolynomial({(2, 0): 1e-3, (0, 2): -2e-3, (1, 1): 5e-4, (3, 1): 1e-6}, c=1 / 500, k=-1,
                     norm_radius=10.0)
    x = np.array([0.0, 3.0, -7.5, 12.0])
    y = np.array([0.0, -4.0, 2.0, 9.0])
    u, v = x / 10, y / 10
    expected = (x * x + y * y) / 1000 + 1e-3 * u ** 2 - 2e-3 * v ** 2 + 5e-4 * u * v + 1e-6 * u ** 3 * v
    assert np.allclose(s.sag(x, y), expected, rtol=1e-14, atol=1e-16)
    gx, gy = s.gradient(x, y)
    h = 1e-5
    assert np.allclose(gx, (s.sag(x + h, y) - s.sag(x - h, y)) / (2 * h), atol=1e-9)
    assert np.allclose(gy, (s.sag(x, y + h) - s.sag(x, y - h)) / (2 * h), atol=1e-9)


def test_generic_signed_distance_on_sphere():
    R = 200.0
    s = EvenAsphere(1 / R, 0)  # concave sphere, centre at (0, 0, R)
    rng = np.random.default_rng(3)
    r = rng.uniform(0, 150, 50)
    t = rng.uniform(0, 2 * np.pi, 50)
    d_true = rng.uniform(-2, 2, 50)  # + is the +z side, i.e. towards the centre here
    n = s.normal(r * np.cos(t), r * np.sin(t))
    foot = np.column_stack([r * np.cos(t), r * np.sin(t), s.sag_r(r)])
    p = foot + d_true[:, None] * n
    assert np.allclose(s.signed_distance(p), d_true, atol=1e-12)
    # closed form: distance from the centre
    assert np.allclose(R - np.linalg.norm(p - [0, 0, R], axis=1), d_true, atol=1e-12)


def _grid_mesh(f, half, n, offset=(0.0, 0.0)):
    g = np.linspace(-half, half, n)
    X, Y = np.meshgrid(g + offset[0], g + offset[1])
    V = np.column_stack([X.ravel(), Y.ravel(), f(X.ravel(), Y.ravel())])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    T = np.vstack([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return V, T


def test_mesh_nominal_from_stl_float64_far_from_origin(tmp_path):
    """A tilted plane as STL, 1 m off the origin: distances exact to 1e-9 mm, not float32's 0.1 µm."""
    import open3d as o3d

    f = lambda x, y: 0.01 * x - 0.02 * y + 250.0  # noqa: E731
    V, T = _grid_mesh(f, 50, 11, offset=(1000.0, -800.0))
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    m.compute_triangle_normals()
    path = tmp_path / "nominal.stl"
    assert o3d.io.write_triangle_mesh(str(path), m)
    surf = surface_from_spec({"type": "mesh", "path": "nominal.stl", "aperture": 90}, tmp_path)
    assert isinstance(surf, MeshSurface)
    rng = np.random.default_rng(5)
    x = rng.uniform(960, 1040, 100)
    y = rng.uniform(-840, -760, 100)
    nrm = np.array([-0.01, 0.02, 1.0]) / np.sqrt(1 + 0.01 ** 2 + 0.02 ** 2)
    d_true = rng.uniform(-1e-3, 1e-3, 100)  # ±1 µm
    # STL stores float32 vertices: compare with the plane through the stored vertices
    assert np.allclose(surf.sag(x, y), f(x, y), atol=2e-5)
    foot = np.column_stack([x, y, surf.sag(x, y)])
    p = foot + d_true[:, None] * nrm
    assert np.allclose(surf.signed_distance(p), d_true, atol=1e-9)
    gx, gy = surf.gradient(x, y)
    # slopes of the stored (float32 in STL) vertices
    assert np.allclose(gx, 0.01, atol=1e-5) and np.allclose(gy, -0.02, atol=1e-5)
    with pytest.raises(DomainError, match="outside the mesh's footprint"):
        surf.sag(np.array([0.0]), np.array([0.0]))


def test_mesh_nominal_of_a_sphere_cap_signed_distance(tmp_path):
    import open3d as o3d

    R = 100.0
    f = lambda x, y: R - np.sqrt(R * R - x * x - y * y)  # noqa: E731
    V, T = _grid_mesh(f, 30, 121)
    path = tmp_path / "cap.ply"
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    assert o3d.io.write_triangle_mesh(str(path), m)
    surf = MeshSurface.from_file(path)
    rng = np.random.default_rng(9)
    p = np.column_stack([rng.uniform(-20, 20, 200), rng.uniform(-20, 20, 200), np.zeros(200)])
    p[:, 2] = f(p[:, 0], p[:, 1]) + rng.uniform(-0.5, 0.5, 200)
    d_true = R - np.linalg.norm(p - [0, 0, R], axis=1)
    # chord error of a 0.5 mm tessellation on R 100: h²/(8R) ≈ 0.3 µm
    assert np.max(np.abs(surf.signed_distance(p) - d_true)) < 1e-3


def test_mesh_file_errors(tmp_path):
    with pytest.raises(InputError, match="nominal mesh file not found"):
        MeshSurface.from_file(tmp_path / "missing.stl")
    bad = tmp_path / "points.ply"
    bad.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                   "property float z\nend_header\n0 0 0\n", encoding="utf-8")
    with pytest.raises(InputError, match="no triangles"):
        MeshSurface.from_file(bad)


def test_spec_validation():
    from pydantic import ValidationError

    s = surface_from_spec({"type": "even_asphere", "R": -1646.4, "k": -0.9861, "A": {4: 4e-16}})
    assert s.c == pytest.approx(-1 / 1646.4)
    with pytest.raises(ValidationError, match="exactly one of c"):
        surface_from_spec({"type": "even_asphere", "c": 0.001, "R": 1000})
    with pytest.raises(ValidationError, match="x<i>y<j>"):
        surface_from_spec({"type": "xy_polynomial", "terms": {"x2z1": 1.0}})
    with pytest.raises(ValidationError):
        surface_from_spec({"type": "torus"})


# -- Forbes Q-con / Q-bfs ------------------------------------------------------------------------

def test_qbfs_polynomials_closed_forms_and_slope_orthonormality():
    from numpy.polynomial.legendre import leggauss

    from pointspro.core.surfaces.forbes import qbfs_polynomials

    v = np.linspace(0, 1, 7)
    Q = qbfs_polynomials(2, v)
    assert np.allclose(Q[1][0], (13 - 16 * v) / np.sqrt(19), atol=1e-15)          # Forbes 2007 eq. 3.4
    assert np.allclose(Q[2][0], np.sqrt(2) * (29 - 4 * v * (25 - 19 * v)) / np.sqrt(95), atol=1e-14)
    # (2/π)∫₀¹ S_m' S_n' du / sqrt(1 − u²) = δ_mn, S_m = u²(1 − u²) Q_m(u²); u = sin θ
    t, w = leggauss(120)
    th = (t + 1) * np.pi / 4
    u = np.sin(th)
    wt = w * np.pi / 4
    M = 10
    Qs = qbfs_polynomials(M, u * u)
    # S'(u) = d/du[v(1 − v) Q(v)] = 2u [(1 − 2v) Q + v(1 − v) Q']
    v = u * u
    D = np.array([2 * u * ((1 - 2 * v) * q + v * (1 - v) * qd) for q, qd, _ in Qs])
    G = (2 / np.pi) * np.einsum("ia,ja,a->ij", D, D, wt)
    assert np.allclose(G, np.eye(M + 1), atol=1e-10)


@pytest.mark.parametrize("kind", ["qcon", "qbfs"])
def test_forbes_surfaces_derivatives_and_spec(kind):
    from mpmath import mp

    from pointspro.core.surfaces import surface_from_spec

    spec = {"type": kind, "R": 400.0, "norm_radius": 60.0, "a": [2e-3, -4e-4, 1e-4, 3e-5]}
    if kind == "qcon":
        spec["k"] = -0.7
    s = surface_from_spec(spec)
    r = np.array([0.0, 5.0, 23.0, 41.0, 59.0])
    h = 1e-4
    d1 = (s.sag_r(r + h) - s.sag_r(r - h)) / (2 * h)
    d2 = (s.sag_r(r + h) - 2 * s.sag_r(r) + s.sag_r(r - h)) / h**2
    assert np.allclose(s.slope_over_r(r) * r, d1, atol=1e-9)
    assert np.allclose(s.curvature_r(r), d2, atol=2e-5)
    assert s.slope_over_r(np.array([0.0]))[0] == pytest.approx(s.curvature_r(np.array([0.0]))[0])
    # sag against a direct high-precision evaluation of the defining formula at one radius
    mp.dps = 40
    rr = mp.mpf(37)
    c = mp.mpf(1) / 400
    v = (rr / 60) ** 2
    if kind == "qcon":
        base = c * rr**2 / (1 + mp.sqrt(1 - (1 + mp.mpf(-0.7)) * c**2 * rr**2))
        dep = v**2 * sum(mp.mpf(a) * mp.jacobi(m, 0, 4, 2 * v - 1) for m, a in enumerate(spec["a"]))
    else:
        base = c * rr**2 / (1 + mp.sqrt(1 - c**2 * rr**2))
        q = [mp.mpf(1), (13 - 16 * v) / mp.sqrt(19), mp.sqrt(2) * (29 - 4 * v * (25 - 19 * v)) / mp.sqrt(95)]
        from pointspro.core.surfaces.forbes import qbfs_polynomials

        q.append(mp.mpf(qbfs_polynomials(3, np.array([float(v)]))[3][0][0]))
        dep = v * (1 - v) / mp.sqrt(1 - c**2 * rr**2) * sum(mp.mpf(a) * qq for a, qq in zip(spec["a"], q))
    assert float(s.sag_r(np.array([37.0]))[0]) == pytest.approx(float(base + dep), abs=1e-13)
    # exact foot point of the surface of revolution
    p = np.array([[10.0, 20.0, float(s.sag(10.0, 20.0)) + 0.01]])
    foot, n, d = s.foot_point(p)
    assert d[0] == pytest.approx(0.01 / np.sqrt(1 + s.slope_r(np.hypot(10, 20)) ** 2), rel=1e-3)
    assert np.allclose(foot + d[:, None] * n, p, atol=1e-12)
    assert foot[0, 2] == pytest.approx(float(s.sag(foot[0, 0], foot[0, 1])), abs=1e-13)
    assert np.allclose(n, s.normal(foot[:, 0], foot[:, 1]), atol=1e-12)
    assert s.describe()["type"] == kind
