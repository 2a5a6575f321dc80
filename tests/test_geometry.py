"""Pose conventions and least-squares features with their standard uncertainties."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pointspro.core.errors import StepError
from pointspro.core.geometry import Pose, fit_circle, fit_plane, fit_sphere, rot_x, rot_y


def test_pose_matches_design_convention():
    p = Pose(alpha_deg=90, beta_deg=0, dx=1, dy=2, dz=3)
    # Rx(90°) maps y to z
    assert np.allclose(p.to_measuring([[0, 1, 0]]), [[1, 2, 4]])
    q = Pose(beta_deg=90)
    # Ry(90°) maps z to x (Ry = [[cos, 0, sin], ...])
    assert np.allclose(q.to_measuring([[0, 0, 1]]), [[1, 0, 0]])
    a, b = np.radians(0.17), np.radians(-0.01)
    assert np.allclose(Pose(0.17, -0.01).rotation, rot_x(a) @ rot_y(b))
    assert np.allclose(Pose(1, 2, 3, 4, 5).matrix() @ Pose(1, 2, 3, 4, 5).inverse_matrix(), np.eye(4))


@settings(max_examples=60, deadline=None)
@given(st.floats(-10, 10), st.floats(-10, 10), st.floats(-100, 100), st.floats(-100, 100),
       st.floats(-100, 100))
def test_pose_round_trip(a, b, dx, dy, dz):
    rng = np.random.default_rng(0)
    p = rng.uniform(-650, 650, (20, 3))
    pose = Pose(a, b, dx, dy, dz)
    back = pose.to_part(pose.to_measuring(p))
    assert np.max(np.abs(back - p)) < 1e-11


def _sphere_patch(centre, radius, n, half_angle_deg, sigma, rng):
    u = rng.uniform(np.cos(np.radians(half_angle_deg)), 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - u * u)
    d = np.column_stack([s * np.cos(phi), s * np.sin(phi), u])
    return centre + d * (radius + rng.normal(0, sigma, (n, 1)))  # radial noise σ


def test_sphere_fit_recovers_ball_and_its_uncertainty_is_honest():
    """Monte Carlo: the reported σ of the centre matches the scatter over repeated fits (±25 %)."""
    rng = np.random.default_rng(42)
    centre, radius, sigma = np.array([10.0, -20.0, 5.0]), 4.9985, 0.5e-3
    fits = [fit_sphere(_sphere_patch(centre, radius, 60, 70, sigma, rng)) for _ in range(300)]
    est = np.array([[f["x0"], f["y0"], f["z0"], f["radius"]] for f in fits])
    reported = np.median([[f.uncertainty[k] for k in ("x0", "y0", "z0", "radius")] for f in fits], axis=0)
    scatter = est.std(axis=0, ddof=1)
    assert np.all(np.abs(est.mean(axis=0) - [*centre, radius]) < 4 * scatter / np.sqrt(len(fits)) + 1e-9)
    assert np.all(np.abs(reported / scatter - 1) < 0.25), (reported, scatter)
    f = fits[0]
    assert f.rms == pytest.approx(sigma, rel=0.3) and f.dof == 56 and not f.warnings


def test_sphere_fit_fixed_radius_and_small_patch_warning():
    rng = np.random.default_rng(1)
    centre, radius = np.array([0.0, 0.0, 100.0]), 4.9985
    pts = _sphere_patch(centre, radius, 20, 40, 0.2e-3, rng)
    f = fit_sphere(pts, radius=radius)
    assert f.names == ["x0", "y0", "z0"]
    assert np.allclose([f["x0"], f["y0"], f["z0"]], centre, atol=3e-3)
    # a tiny patch: centre and radius trade — the fit says so
    tiny = _sphere_patch(centre, radius, 20, 1.0, 0.2e-3, rng)
    g = fit_sphere(tiny)
    assert g.condition_number > 1e3
    assert abs(g.correlation[2, 3]) > 0.99  # z0 and radius
    with pytest.raises(StepError, match="at least 4 points"):
        fit_sphere(pts[:3])


def test_plane_fit_tilts_flatness_and_uncertainty():
    rng = np.random.default_rng(3)
    n = 400
    xy = rng.uniform(-50, 50, (n, 2))
    z = 0.002 * xy[:, 0] - 0.001 * xy[:, 1] + 7.0
    sigma = 1e-4
    pts = np.column_stack([xy, z + rng.normal(0, sigma, n)])
    f = fit_plane(pts)
    nrm = np.array(f.extra["normal"])
    assert np.allclose(nrm, np.array([-0.002, 0.001, 1]) / np.linalg.norm([-0.002, 0.001, 1]), atol=1e-6)
    assert f.rms == pytest.approx(sigma, rel=0.15)
    assert f.extra["flatness"] == pytest.approx(np.ptp(f.residuals))
    # angular σ of the normal ≈ σ / sqrt(Σ u²) for points spread ±50 mm
    expected = sigma / np.sqrt(np.sum((xy[:, 0] - xy[:, 0].mean()) ** 2))
    assert f.uncertainty["tilt_u"] == pytest.approx(expected, rel=0.3)
    assert f.uncertainty["d"] == pytest.approx(sigma / np.sqrt(n), rel=0.2)
    col = np.column_stack([np.linspace(0, 1, 10), np.zeros(10), np.zeros(10)])
    assert any("collinear" in w for w in fit_plane(col).warnings)


def test_circle_fit_2d_and_3d():
    rng = np.random.default_rng(4)
    t = rng.uniform(0, 2 * np.pi, 100)
    sigma = 1e-3
    xy = np.column_stack([3 + 25 * np.cos(t), -4 + 25 * np.sin(t)]) + rng.normal(0, sigma, (100, 2))
    f = fit_circle(xy)
    assert f["x0"] == pytest.approx(3, abs=5 * f.uncertainty["x0"])
    assert f["radius"] == pytest.approx(25, abs=5 * f.uncertainty["radius"])
    assert f.uncertainty["radius"] == pytest.approx(sigma / np.sqrt(100), rel=0.3)
    # the same circle tilted in 3-D
    p3 = np.column_stack([xy, np.zeros(100)]) @ rot_x(np.radians(20)).T + [1, 2, 3]
    g = fit_circle(p3)
    assert g["radius"] == pytest.approx(f["radius"], abs=1e-9)
    c3 = np.array([3, -4, 0.0]) @ rot_x(np.radians(20)).T + [1, 2, 3]
    assert np.allclose(g.extra["center"], c3, atol=5e-3)
