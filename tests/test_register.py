"""register: seed 000's freeforms (F-theta lens, sinusoid) from generated meshes with a known pose."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pointspro.core import PointCloud
from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context
from pointspro.plugins.register import RegisterStep


def f_theta(x, y):
    return -x**2 / 250 + x**4 / 92000 - y**2 / 25


def sinusoid(x, y):
    return 0.5 * (np.sin(np.pi * x / 9) + np.cos(np.pi * y / 9))


def write_mesh(path, f, half_x, half_y, h):
    """Height-field mesh of z = f(x, y) at spacing h (mm), written with open3d."""
    import open3d as o3d

    gx = np.arange(-half_x, half_x + 1e-9, h)
    gy = np.arange(-half_y, half_y + 1e-9, h)
    X, Y = np.meshgrid(gx, gy)
    V = np.column_stack([X.ravel(), Y.ravel(), f(X, Y).ravel()])
    nx = len(gx)
    i, j = np.meshgrid(np.arange(len(gy) - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    T = np.concatenate([np.column_stack([a, a + 1, a + nx + 1]), np.column_stack([a, a + nx + 1, a + nx])])
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    o3d.io.write_triangle_mesh(str(path), m)
    return V, T


CASES = {
    # F-theta lens of seed 000: z = −x²/250 + x⁴/92000 − y²/25 over 60 × 30 mm
    "f_theta": (f_theta, 30.0, 15.0),
    # sinusoid of seed 000: z = 0.5(sin(πx/9) + cos(πy/9)) over 40 × 40 mm
    "sinusoid": (sinusoid, 20.0, 20.0),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_recovers_a_known_pose(tmp_path, name):
    f, hx, hy = CASES[name]
    write_mesh(tmp_path / "nominal.ply", f, hx, hy, 0.1)
    rng = np.random.default_rng(11)
    n = 3000
    x = rng.uniform(-0.85 * hx, 0.85 * hx, n)
    y = rng.uniform(-0.85 * hy, 0.85 * hy, n)
    part = np.column_stack([x, y, f(x, y) + rng.normal(0, 2e-4, n)])  # 0.2 µm noise
    rot = Rotation.from_euler("ZYX", [1.2, -0.8, 0.5], degrees=True)
    t = np.array([0.3, -0.2, 0.15])
    meas = rot.apply(part) + t
    cloud = PointCloud.from_xyz(*meas.T)
    res = RegisterStep().run(cloud, RegisterStep.Params.model_validate({"mesh": "nominal.ply"}),
                             Context(base_dir=tmp_path))
    rep = res.report
    T = np.array(rep["transform"])
    # expected transform measuring → part is the inverse of the simulated pose
    inv_R = rot.inv().as_matrix()
    ang = np.degrees(Rotation.from_matrix(T[:3, :3] @ inv_R.T).magnitude())
    assert ang < 1e-3, ang                                   # degrees
    assert np.allclose(T[:3, 3], -inv_R @ t, atol=5e-4)      # mm (tessellation chord error ~50 nm)
    assert np.allclose(res.cloud.xyz, part, atol=1e-3)
    assert rep["residual_rms_um"] < 0.35                     # noise 0.2 µm + chord error
    assert np.std(res.cloud["residual"]) * 1e3 == pytest.approx(rep["residual_rms_um"], rel=0.2)
    assert res.cloud.frame == "part" and rep["icp_fitness"] > 0.99
    assert all(v < 1e-3 for v in rep["uncertainty"].values())


def _broken(V, T, nx):
    """Three problems on the sinusoid sheet: two holes (the faces round two interior vertices
    removed), a duplicated vertex (a copy of vertex 5·nx + 5 used by one face) and a non-manifold
    edge (a small fin on an interior diagonal)."""
    keep = np.array([k for k, tri in enumerate(T) if not ({2 * nx + 2, 7 * nx + 7} & set(tri))])
    T = T[keep].copy()
    V = np.vstack([V, V[5 * nx + 5], V[4 * nx + 4] + [0.1, 0.0, 0.2]])
    k = int(np.flatnonzero((T == 5 * nx + 5).any(axis=1))[0])
    T[k][T[k] == 5 * nx + 5] = len(V) - 2
    diag = [4 * nx + 4, 5 * nx + 5]  # the diagonal a, a + nx + 1 of cell (4, 4)
    return V, np.vstack([T, [diag[0], diag[1], len(V) - 1]])


def _write_o3d(path, V, T):
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    assert o3d.io.write_triangle_mesh(str(path), m)


def test_bad_meshes(tmp_path):
    import open3d as o3d

    cloud = PointCloud.from_xyz(np.arange(10.0), np.arange(10.0) ** 2 % 7, np.zeros(10))
    empty = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.eye(3)), o3d.utility.Vector3iVector(
        np.zeros((0, 3), dtype=np.int32)))
    o3d.io.write_triangle_mesh(str(tmp_path / "empty.ply"), empty)
    with pytest.raises(InputError, match="empty.ply: unusable nominal mesh: it has no faces"):
        RegisterStep().run(cloud, RegisterStep.Params(mesh=str(tmp_path / "empty.ply")), Context())
    with pytest.raises(InputError, match="empty.ply: unusable nominal mesh: it has no faces"):
        RegisterStep().run(cloud, RegisterStep.Params(mesh=str(tmp_path / "empty.ply"), repair=True),
                           Context())
    V, T = write_mesh(tmp_path / "ok.ply", sinusoid, 5.0, 5.0, 1.0)
    nx = 11
    holes = np.array([k for k, tri in enumerate(T) if not ({2 * nx + 2, 7 * nx + 7} & set(tri))])
    _write_o3d(tmp_path / "holes.ply", V, T[holes])
    with pytest.raises(InputError, match=r"holes.ply: unusable nominal mesh: 2 holes \(boundary loops "
                                         r"besides the outline\) — fix the mesh or set repair: true$"):
        RegisterStep().run(cloud, RegisterStep.Params(mesh=str(tmp_path / "holes.ply")), Context())
    with pytest.raises(InputError, match="nominal mesh file not found"):
        RegisterStep().run(cloud, RegisterStep.Params(mesh=str(tmp_path / "nope.stl")), Context())
    with pytest.raises(StepError, match="no mesh given and the recipe has no nominal"):
        RegisterStep().run(cloud, RegisterStep.Params(), Context())


def test_broken_mesh_refused_by_name_then_repaired(tmp_path):
    """Holes, a duplicated vertex and a non-manifold edge: one line naming the file and each problem
    with its count; with repair: true the step runs on the repaired mesh and reports the repairs."""
    V, T = write_mesh(tmp_path / "ok.ply", sinusoid, 5.0, 5.0, 1.0)
    Vb, Tb = _broken(V, T, 11)
    _write_o3d(tmp_path / "part.ply", Vb, Tb)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-4, 4, (2, 300))
    cloud = PointCloud.from_xyz(x + 0.05, y - 0.03, sinusoid(x, y) + 0.02)
    with pytest.raises(InputError) as e:
        RegisterStep().run(cloud, RegisterStep.Params(mesh="part.ply"), Context(base_dir=tmp_path))
    msg = str(e.value)
    assert msg.startswith(f"{tmp_path / 'part.ply'}: unusable nominal mesh: ") and "\n" not in msg
    # the fin's two free edges make one more boundary loop: 3 holes until it is removed
    for part in ("1 non-manifold edge", "3 holes (boundary loops besides the outline)",
                 "1 duplicated vertex", "fix the mesh or set repair: true"):
        assert part in msg, msg
    res = RegisterStep().run(cloud, RegisterStep.Params(mesh="part.ply", repair=True, refine_iterations=5),
                             Context(base_dir=tmp_path))
    done = " ".join(res.report["mesh_repaired"])
    assert "merged 1 duplicated vertex" in done and "non-manifold edge" in done
    assert "closed 2 holes" in done
    assert res.report["residual_rms_um"] < 200  # registered on the repaired sheet (1 mm chords)


def test_recipe_mesh_surface_checked_and_repaired(tmp_path):
    """`surface: {type: mesh, ...}` is checked where it is built; `repair: true` there repairs it, and
    register (no mesh of its own) reports what was repaired."""
    from pointspro.core.surfaces import surface_from_spec

    V, T = write_mesh(tmp_path / "ok.ply", sinusoid, 5.0, 5.0, 1.0)
    Vb, Tb = _broken(V, T, 11)
    _write_o3d(tmp_path / "part.ply", Vb, Tb)
    with pytest.raises(InputError, match=r"part.ply: unusable nominal mesh: .*3 holes.*set repair: true"):
        surface_from_spec({"type": "mesh", "path": "part.ply"}, tmp_path)
    surf = surface_from_spec({"type": "mesh", "path": "part.ply", "repair": True}, tmp_path)
    assert surf.describe()["repaired"] and surf.mesh_info["check"]["holes"] == 3
    rng = np.random.default_rng(4)
    x, y = rng.uniform(-4, 4, (2, 300))
    cloud = PointCloud.from_xyz(x, y, sinusoid(x, y))
    res = RegisterStep().run(cloud, RegisterStep.Params(refine_iterations=3), Context(surface=surf))
    assert res.report["mesh_repaired"] == surf.mesh_info["repaired"]


def test_in_memory_mesh_surface_checked(tmp_path):
    """A MeshSurface built from arrays (not a file) is checked by register, repaired when asked."""
    from pointspro.core.surfaces import MeshSurface

    V, T = write_mesh(tmp_path / "ok.ply", sinusoid, 5.0, 5.0, 1.0)
    keep = np.array([k for k, tri in enumerate(T) if 3 * 11 + 3 not in tri])
    surf = MeshSurface(V, T[keep], source="sheet")
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-4, 4, (2, 200))
    cloud = PointCloud.from_xyz(x, y, sinusoid(x, y))
    with pytest.raises(InputError, match=r"^sheet: unusable nominal mesh: 1 hole \(boundary loops"):
        RegisterStep().run(cloud, RegisterStep.Params(), Context(surface=surf))
    res = RegisterStep().run(cloud, RegisterStep.Params(repair=True, refine_iterations=3),
                             Context(surface=surf))
    assert res.report["mesh_repaired"] == ["closed 1 hole with 4 new faces"]  # a hexagon: 4 triangles


@pytest.mark.parametrize("rot_deg, seed", [([0, 4, -3], 1), ([0, 1, -0.5], 2), ([0, 0.2, 0.1], 3)])
def test_a_surface_of_revolution_registers_to_the_noise_and_says_the_free_rotation(rot_deg, seed):
    """An even asphere (an analytic nominal, exactly symmetric): the rotation about its axis is
    free. The least squares held it instead of stepping 10¹¹° along it (the residual went from
    0.1 µm to 29–286 µm, exit 0); the report says which motion is free and gives no uncertainty
    for it."""
    import pointspro.core as pp

    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-12, 12, (2, 3000))
    part = np.column_stack([x, y, (x * x + y * y) / 100 + 1e-6 * (x * x + y * y) ** 2
                            + rng.normal(0, 1e-4, x.size)])
    moved = Rotation.from_euler("ZYX", rot_deg, degrees=True).apply(part) + [0.5, -0.3, 0.2]
    res = pp.run({"surface": {"type": "even_asphere", "R": 50.0, "k": -1.0, "A": {4: 1e-6}},
                  "steps": [{"register": {}}]}, PointCloud.from_numpy(moved))
    rep = res.steps[0].report
    assert rep["residual_rms_um"] < 0.11  # the noise: 0.1 µm
    q = res.cloud.xyz
    true = q[:, 2] - ((q[:, 0] ** 2 + q[:, 1] ** 2) / 100 + 1e-6 * (q[:, 0] ** 2 + q[:, 1] ** 2) ** 2)
    assert np.sqrt(np.mean(true**2)) < 1.1e-4
    assert any("rotation about z" in w for w in rep["warnings"])
    assert rep["uncertainty"]["rz_deg"] is None and rep["uncertainty"]["rx_deg"] is not None
