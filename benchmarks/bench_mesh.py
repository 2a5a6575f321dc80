"""Nominal meshes: read + check on a ~10⁶-face mesh, pymeshlab against open3d against numpy edge
counting; and writing a map grid as a mesh, numpy against pymeshlab and open3d.

    .venv/bin/python benchmarks/bench_mesh.py [--n 708] [--repeat 2]

The mesh: a height field (an off-axis asphere-like sag plus a ripple) on an n × n grid over
±100 mm, 2(n − 1)² faces (n = 708: 999,698 faces, 501,264 vertices), written as binary STL (open3d),
binary PLY (float64, ours) and OBJ (ours). Seconds are the best of ``--repeat`` runs (imports not
timed: each library is imported once before).

Read: the arrays in memory as float64 vertices and int64 faces (STL: per-face copies unified —
pymeshlab does it while reading, open3d's read is followed by our numpy merge).
Check: what each offers towards the nominal checks (non-manifold edges/vertices, boundary loops,
duplicated vertices, degenerate faces, orientation):
  * numpy (ours, core.io.mesh.check_mesh): all of them;
  * "numpy before": the register step's edge counting before this work (non-manifold edges and
    boundary loops after merging coincident vertices with np.unique(axis=0));
  * pymeshlab: get_topological_measures (non-manifold edges/vertices, boundary loops) — no
    orientation, no duplicates, no degenerate faces — on a MeshSet already holding the mesh, plus
    the time to hand the arrays to it;
  * open3d: is_edge_manifold, is_vertex_manifold, is_orientable, get_non_manifold_edges (boundary).
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def height_field(n: int):
    from pointspro.core.io.mesh import grid_mesh

    xs = np.linspace(-100.0, 100.0, n)
    X, Y = np.meshgrid(xs, xs)
    Z = (X * X + Y * Y) / 4000.0 + 1e-3 * X + 2e-4 * np.sin(2 * np.pi * X / 17.0) * np.cos(np.pi * Y / 23.0)
    return grid_mesh(xs, xs, Z)


def best(fn, repeat):
    t = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        t.append(time.perf_counter() - t0)
    return min(t), out


def old_mesh_problems(vertices, triangles):
    """plugins/register's mesh_problems before this work (numpy edge counting), verbatim logic."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t = np.asarray(triangles, dtype=np.int64)
    _, inv = np.unique(np.asarray(vertices, dtype=np.float64), axis=0, return_inverse=True)
    t = inv.reshape(-1)[t]
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    e = e[e[:, 0] != e[:, 1]]
    edges, count = np.unique(e, axis=0, return_counts=True)
    b = edges[count == 1]
    nv = int(t.max()) + 1
    g = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(nv, nv))
    _, lab = connected_components(g, directed=False)
    return int((count > 2).sum()), len(np.unique(lab[np.unique(b)]))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=708)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    import open3d as o3d
    import pymeshlab

    from pointspro.core.io.mesh import (
        _read_open3d,
        _read_pymeshlab,
        check_mesh,
        merge_duplicate_vertices,
        read_mesh,
        write_mesh,
    )

    V, F = height_field(args.n)
    print(f"mesh: {len(V):,} vertices, {len(F):,} faces\n")
    tmp = Path(tempfile.mkdtemp(prefix="bench-mesh-"))
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    m.compute_triangle_normals()
    o3d.io.write_triangle_mesh(str(tmp / "m.stl"), m)
    write_mesh(tmp / "m.ply", V, F)
    write_mesh(tmp / "m.obj", V, F)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
    ms.save_current_mesh(str(tmp / "m.off"))

    s, _ = best(lambda: read_mesh(tmp / "m.stl"), 1)  # warm-up: imports, page cache
    print("| read | library | seconds | vertices | faces |\n|---|---|---:|---:|---:|")
    for fmt in ("stl", "ply", "obj", "off"):
        p = tmp / f"m.{fmt}"

        def ml_default():
            ms = pymeshlab.MeshSet()
            ms.load_new_mesh(str(p))
            mm = ms.current_mesh()
            return mm.vertex_matrix(), mm.face_matrix()
        s, (v, f) = best(ml_default, args.repeat)
        print(f"| {fmt} | pymeshlab{' (its own unify_vertices)' if fmt == 'stl' else ''} | {s:.3f} | "
              f"{len(v):,} | {len(f):,} |")
        if fmt == "stl":
            s, (v, f) = best(lambda: merge_duplicate_vertices(*_read_pymeshlab(p)), args.repeat)
            print(f"| {fmt} | pymeshlab (unify_vertices off) + numpy merge | {s:.3f} | {len(v):,} | {len(f):,} |")
            s, (v, f) = best(lambda: merge_duplicate_vertices(*_read_open3d(p)), args.repeat)
            label = "open3d + numpy merge"
        else:
            s, (v, f) = best(lambda: _read_open3d(p), args.repeat)
            label = "open3d"
        print(f"| {fmt} | {label} | {s:.3f} | {len(v):,} | {len(f):,} |")

    print("\n| check | seconds | what it finds |\n|---|---:|---|")
    s, c = best(lambda: check_mesh(V, F), args.repeat)
    print(f"| numpy (core.io.mesh.check_mesh) | {s:.3f} | all six: {c.problems() or 'no problem'}, "
          f"{c.boundary_loops} boundary loop |")
    s, r = best(lambda: old_mesh_problems(V, F), args.repeat)
    print(f"| numpy before (register's mesh_problems) | {s:.3f} | non-manifold edges, boundary loops: {r} |")

    def ml_check():
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
        return ms.get_topological_measures()
    s, r = best(ml_check, args.repeat)
    print(f"| pymeshlab get_topological_measures (incl. handing the arrays over) | {s:.3f} | "
          f"non-manifold edges {r['non_two_manifold_edges']}, vertices {r['non_two_manifold_vertices']}, "
          f"holes {r['number_holes']} |")

    def o3d_check():
        mm = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
        return (mm.is_edge_manifold(allow_boundary_edges=True), mm.is_vertex_manifold(),
                mm.is_orientable(), len(mm.get_non_manifold_edges(allow_boundary_edges=False)))
    s, r = best(o3d_check, 1)
    print(f"| open3d manifold + orientable + boundary edges | {s:.3f} | edge-manifold {r[0]}, "
          f"vertex-manifold {r[1]}, orientable {r[2]}, boundary edges {r[3]} (no loop count) |")

    print("\n| write | library | seconds | MB |\n|---|---|---:|---:|")
    for fmt in ("ply", "stl", "obj"):
        p = tmp / f"w.{fmt}"
        s, _ = best(lambda: write_mesh(p, V, F), args.repeat)
        print(f"| {fmt} | numpy (core.io.mesh.write_mesh) | {s:.3f} | {p.stat().st_size / 1e6:.1f} |")

        def ml_save():
            ms = pymeshlab.MeshSet()
            ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
            ms.save_current_mesh(str(p), **({"binary": True} if fmt in ("ply", "stl") else {}))
        s, _ = best(ml_save, args.repeat)
        print(f"| {fmt} | pymeshlab save_current_mesh | {s:.3f} | {p.stat().st_size / 1e6:.1f} |")

        def o3d_save():
            mm = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
            if fmt == "stl":
                mm.compute_triangle_normals()
            o3d.io.write_triangle_mesh(str(p), mm)
        s, _ = best(o3d_save, args.repeat)
        print(f"| {fmt} | open3d write_triangle_mesh | {s:.3f} | {p.stat().st_size / 1e6:.1f} |")


if __name__ == "__main__":
    main()
