"""register's coarse stage, a point-to-plane ICP of its own (numpy, scipy's cKDTree): it converges from a
start off by 2° and 1 mm, and gives the same bits whatever the thread count, in this process and in
another (open3d's threaded ICP did not; on one thread it was 2.4× slower); and the residual's sign on
a mesh that is no height field (an undercut wall, a closed solid's underside): outside the part is +."""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pointspro.core import PointCloud
from pointspro.core.step import Context
from pointspro.core.surfaces.mesh import MeshSurface
from pointspro.plugins import register as reg


def freeform(x, y):
    return x**2 / 250 - y**2 / 180 + x * y / 400 + 2e-4 * x**3 - 1e-4 * x * y**2


def sheet(f, half, h):
    """Height-field mesh of z = f(x, y) over ±half at spacing h (mm): vertices, triangles."""
    g = np.linspace(-half, half, int(round(2 * half / h)) + 1)
    X, Y = np.meshgrid(g, g)
    V = np.column_stack([X.ravel(), Y.ravel(), f(X, Y).ravel()])
    nx = len(g)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    return V, np.concatenate([np.column_stack([a, a + 1, a + nx + 1]),
                              np.column_stack([a, a + nx + 1, a + nx])])


def write_ply(path, V, T):
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T))
    assert o3d.io.write_triangle_mesh(str(path), m)


def moved_freeform(n=4000, seed=7):
    """Points on the freeform moved by 2° (about (1, −1, 0.5)) and (0.6, −0.6, 0.5) mm; the transform
    measuring → part."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-16, 16, (2, n))
    part = np.column_stack([x, y, freeform(x, y) + rng.normal(0, 1e-4, n)])
    rot = Rotation.from_rotvec(np.radians(2) * np.array([1, -1, 0.5]) / 1.5)
    t = np.array([0.6, -0.6, 0.5])
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = rot.inv().as_matrix(), -rot.inv().apply(t)
    return rot.apply(part) + t, truth


def test_coarse_icp_converges_from_2_degrees_and_1_mm_the_same_bits_on_any_thread_count():
    from threadpoolctl import threadpool_limits

    V, T = sheet(freeform, 20, 0.5)
    surf = MeshSurface(V, T)
    p, truth = moved_freeform()
    tp, tn = reg._target_points(surf, p, len(p))
    extent = float(np.linalg.norm(np.ptp(p, axis=0)))
    q = p[reg._locality_order(p)]
    a = reg._icp(q, tp, tn, np.eye(4), 0.05 * extent, 60, extent, workers=1)
    with threadpool_limits(2, user_api="blas"):
        b = reg._icp(q, tp, tn, np.eye(4), 0.05 * extent, 60, extent, workers=3)
    assert np.array_equal(a.T, b.T) and (a.fitness, a.rmse, a.iterations) == (b.fitness, b.rmse, b.iterations)
    assert a.fitness == 1.0 and a.iterations < 20
    # to the mesh's chords (0.5 mm facets): open3d's ICP stopped at the same pose (to 10⁻¹⁵)
    ang = np.degrees(Rotation.from_matrix(a.T[:3, :3] @ truth[:3, :3].T).magnitude())
    assert ang < 0.005 and np.abs(a.T[:3, 3] - truth[:3, 3]).max() < 2e-3
    # rotations stay rotations
    assert np.allclose(a.T[:3, :3] @ a.T[:3, :3].T, np.eye(3), atol=1e-15, rtol=0)


_CHILD = """
import hashlib, sys, numpy as np
from pointspro.core import PointCloud
from pointspro.core.step import Context
from pointspro.plugins.register import RegisterStep
p = np.load(sys.argv[1])
res = RegisterStep().run(PointCloud.from_numpy(p), RegisterStep.Params(mesh=sys.argv[2]), Context())
print(np.array(res.report["transform"]).tobytes().hex(),
      hashlib.sha256(res.cloud["residual"].tobytes()).hexdigest())
"""


def test_register_gives_the_same_pose_bits_whatever_the_threads_and_in_another_process(tmp_path, monkeypatch):
    V, T = sheet(freeform, 20, 1.0)
    write_ply(tmp_path / "nominal.ply", V, T)
    p, truth = moved_freeform(2000, seed=3)
    np.save(tmp_path / "cloud.npy", p)

    def run():
        res = reg.RegisterStep().run(PointCloud.from_numpy(p), reg.RegisterStep.Params(
            mesh=str(tmp_path / "nominal.ply")), Context())
        return np.array(res.report["transform"]), res.cloud["residual"]

    monkeypatch.setenv("OMP_NUM_THREADS", "1")  # the neighbour searches' workers (core.parallel)
    T1, d1 = run()
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    T3, d3 = run()
    assert np.array_equal(T1, T3) and np.array_equal(d1, d3)
    assert np.abs(T1 - truth).max() < 2e-3  # the 1 mm facets: 0.9 µm
    env = {**os.environ, "OMP_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", _CHILD, str(tmp_path / "cloud.npy"),
                          str(tmp_path / "nominal.ply")],
                         capture_output=True, text=True, env=env, timeout=120, check=True).stdout.split()
    assert out == [T1.tobytes().hex(), hashlib.sha256(d1.tobytes()).hexdigest()], json.dumps(out)[:200]


def sheared_wave(n_s=200, n_y=21):
    """A sheet with undercut walls: the height field z = 2 cos u sheared to x = u − 2 cos u (a shear
    is one-to-one: no self-intersection), faces oriented out of the part (material below); the
    profile and its outward normal in (x, z) at each profile vertex."""
    s = np.linspace(0, 13, n_s)
    prof = np.column_stack([s - 2 * np.cos(s), 2 * np.cos(s)])
    ys = np.linspace(-3, 3, n_y)
    V = np.column_stack([np.tile(prof[:, 0], n_y), np.repeat(ys, n_s), np.tile(prof[:, 1], n_y)])
    j, i = np.meshgrid(np.arange(n_y - 1), np.arange(n_s - 1), indexing="ij")
    a = (j * n_s + i).ravel()
    T = np.concatenate([np.column_stack([a, a + 1, a + n_s + 1]), np.column_stack([a, a + n_s + 1, a + n_s])])
    tang = np.gradient(prof, axis=0)
    tang /= np.linalg.norm(tang, axis=1)[:, None]
    return V, T, prof, np.column_stack([-tang[:, 1], tang[:, 0]])


@pytest.mark.parametrize("turned", [False, True])
def test_outside_an_undercut_wall_the_residual_is_positive(tmp_path, turned):
    """MeshSurface turns every face to +z; on a wall that leans over (its outward normal has z < 0)
    a point outside the part had a negative residual (on the −z side of the turned face). The sign
    is now that of the coherently oriented sheet facing +z, the file's own orientation either way."""
    V, T, prof, out = sheared_wave()
    write_ply(tmp_path / "wave.ply", V, T[:, ::-1] if turned else T)
    surf = MeshSurface.from_file(tmp_path / "wave.ply")
    assert np.any(surf.face_normals[:, 2] > 0) and not surf.mesh_info["check"]["inconsistent_edges"]
    k = np.arange(3, len(prof) - 3, 2)
    over = out[k, 1] < 0  # the points on undercut walls
    assert over.sum() > 10
    geo = reg._Geometry(surf)
    for side in (1, -1):
        xz = prof[k] + side * 0.005 * out[k]
        d = geo.evaluate(np.column_stack([xz[:, 0], np.full(len(k), 0.4), xz[:, 1]])).d
        assert np.allclose(d, side * 0.005, atol=1e-4), (side, d[over])
    # a height field keeps its faces: +z is out, nothing turned
    flat = MeshSurface(*sheet(freeform, 5, 0.5))
    assert reg._Geometry(flat).fn is flat.face_normals


def test_below_a_closed_solid_the_residual_is_positive(tmp_path):
    """A closed solid (a disc): its underside faces −z; outside the part is + there too (it was −)."""
    import open3d as o3d

    m = o3d.geometry.TriangleMesh.create_cylinder(radius=10.0, height=4.0, resolution=40, split=2)
    assert o3d.io.write_triangle_mesh(str(tmp_path / "disc.ply"), m)
    geo = reg._Geometry(MeshSurface.from_file(tmp_path / "disc.ply"))
    x = np.array([[1.0, 2.0, 2.01], [1.0, 2.0, 1.99], [1.0, 2.0, -2.01], [1.0, 2.0, -1.99],
                  [-3.0, 0.5, -2.003], [9.5, 0.0, 1.0], [-9.0, 0.0, 1.0]])
    d = geo.evaluate(x).d
    assert np.allclose(d[:5], [0.01, -0.01, 0.01, -0.01, 0.003]) and d[5] < 0 and d[6] < 0
    r = 10 * np.cos(np.pi / 40)  # outside a side facet, at its middle
    a = 3 * np.pi / 40
    d = geo.evaluate(np.array([[(r + 0.02) * np.cos(a), (r + 0.02) * np.sin(a), 0.5]])).d
    assert d[0] == pytest.approx(0.02)


@pytest.mark.parametrize("turned", [False, True])
def test_an_in_memory_undercut_sheet_is_registered_not_refused(turned):
    """A MeshSurface built from arrays with undercut walls: register checked it after each face had
    been turned to +z, so a coherent sheet read "edges with inconsistent orientation" and was refused
    (a file was checked as read). It is checked as given now, and the residual outside is +."""
    from pointspro.core.errors import InputError
    from pointspro.core.io.mesh import check_mesh

    V, T, prof, out = sheared_wave()
    T = T[:, ::-1] if turned else T
    surf = MeshSurface(V, T, source="wave")
    assert check_mesh(V, surf.triangles).inconsistent_edges > 0  # what register used to judge
    k = np.arange(3, len(prof) - 3, 2)
    rng = np.random.default_rng(11)
    ys = rng.uniform(-2.5, 2.5, len(k))
    cloud = PointCloud.from_xyz(prof[k, 0], ys, prof[k, 1])  # on the part, walls and crests alike
    res = reg.RegisterStep().run(cloud, reg.RegisterStep.Params(refine_iterations=3), Context(surface=surf))
    assert res.report["residual_rms_um"] < 0.5
    over = out[k, 1] < 0
    assert over.sum() > 10
    for side in (1, -1):  # outside the part is +, under the overhangs too
        xz = prof[k] + side * 0.005 * out[k]
        d = reg._Geometry(surf).evaluate(np.column_stack([xz[:, 0], ys, xz[:, 1]])).d
        assert np.allclose(d, side * 0.005, atol=1e-4), (side, d[over][:5])
    # a flipped face among coherent ones is still refused as given
    bad = T.copy()
    bad[7] = bad[7, ::-1]
    with pytest.raises(InputError, match=r"^wave: unusable nominal mesh: .*inconsistent orientation"):
        reg.RegisterStep().run(cloud, reg.RegisterStep.Params(), Context(surface=MeshSurface(V, bad, source="wave")))


def test_in_memory_height_fields_wound_both_ways_or_with_a_zero_area_face_still_register():
    """What register accepted before checking faces as given, it accepts still (a review): a height
    field whose faces are wound both ways (coherent once each is turned to +z) and one with an extra
    zero-area face (MeshSurface drops it)."""
    V, T = sheet(freeform, 5, 0.5)
    mixed = T.copy()
    mixed[::2] = mixed[::2, ::-1]
    extra = np.vstack([T, [[0, 0, 1]]])
    rng = np.random.default_rng(12)
    x, y = rng.uniform(-4, 4, (2, 300))
    cloud = PointCloud.from_xyz(x, y, freeform(x, y))
    for faces in (mixed, extra):
        surf = MeshSurface(V, faces, source="sheet")
        assert len(surf.triangles_given) == len(T)
        res = reg.RegisterStep().run(cloud, reg.RegisterStep.Params(refine_iterations=3), Context(surface=surf))
        assert res.report["residual_rms_um"] < 1.0  # the facets' chord error (~0.13 µm)
