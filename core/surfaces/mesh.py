"""Triangle-mesh nominal loaded from STL/OBJ/OFF/PLY/3MF (a freeform given as a CAD tessellation).

core.io.mesh reads the file (pymeshlab; open3d for PLY, where it was measured faster), checks it
(non-manifold edges and vertices, holes besides the outline, duplicated vertices, zero-area faces,
inconsistent orientation) and refuses a broken mesh by name unless repair is asked for. open3d's ``RaycastingScene`` (a BVH) finds, for each point, the triangle under it
(vertical ray) or the closest triangle. open3d's scene works in float32, which loses ~0.1 µm at 1 m,
so it is used only to *find* the triangle: the sag, slope and distance are then computed from that
triangle's vertices in float64 (plane of the triangle; exact closest point on a triangle after
Ericson, *Real-Time Collision Detection* §5.1.5). Coordinates are also re-centred on the mesh before
they enter float32, so the candidate search stays good far from the origin.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DomainError, InputError
from .base import NominalSurface

# open3d's RaycastingScene accepts float32 only: used to *find* triangles, never for the numbers.
_BVH_FLOAT = np.float32


def closest_point_on_triangles(p, a, b, c):
    """Closest points q on triangles (a, b, c) to points p; all (N, 3) float64 (Ericson 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        v = vb * denom
        w = vc * denom
        q = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        # edge regions
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    q[m] = a[m] + ab[m] * t_ab[m, None]
    m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    q[m] = a[m] + ac[m] * t_ac[m, None]
    m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    q[m] = b[m] + (c[m] - b[m]) * t_bc[m, None]
    # vertex regions (checked last so they win)
    m = (d1 <= 0) & (d2 <= 0)
    q[m] = a[m]
    m = (d3 >= 0) & (d4 <= d3)
    q[m] = b[m]
    m = (d6 >= 0) & (d5 <= d6)
    q[m] = c[m]
    return q


class MeshSurface(NominalSurface):
    kind = "mesh"

    def __init__(self, vertices, triangles, aperture: float | None = None, source: str | None = None):
        v = np.asarray(vertices, dtype=np.float64)
        t = np.asarray(triangles, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3 or len(t) == 0:
            raise InputError(f"{source or 'mesh'}: a nominal mesh needs vertices and triangles")
        n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        flip = n[:, 2] < 0  # orient every face so its normal has positive z (docs/conventions.md "Frames and signs")
        given = t
        t = t.copy()
        t[flip] = t[flip][:, [0, 2, 1]]
        n[flip] *= -1
        norm = np.linalg.norm(n, axis=1)
        keep = norm > 0
        if not np.all(keep):
            t, n, norm, given = t[keep], n[keep], norm[keep], given[keep]  # (fancy indexing: copies)
        else:
            given = given.copy()  # not the caller's array
        self.vertices, self.triangles = v, t
        #: the faces in their own winding (the zero-area ones dropped, as from ``triangles``): a sheet
        #: with undercut walls is coherent as given and reads "inconsistent" once each face is turned
        #: to +z — register checks an in-memory nominal both ways (plugins/register)
        self.triangles_given = given
        self.face_normals = n / norm[:, None]
        self.aperture = None if aperture is None else float(aperture)
        self.source = source
        self._origin = v.mean(axis=0)
        self._scene = None
        #: set by from_file: {"check": counts as read, "repaired": [...] when it was}
        self.mesh_info: dict | None = None

    @classmethod
    def from_file(cls, path, aperture: float | None = None, repair: bool = False) -> "MeshSurface":
        """Read (STL, OBJ, OFF, PLY, 3MF) and check the mesh (core.io.mesh): a mesh with problems
        is refused by name unless ``repair``, then repaired; ``mesh_info`` keeps the counts as read
        and what was repaired."""
        from ..io.mesh import load_mesh

        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: nominal mesh file not found")
        V, F, info = load_mesh(path, repair=repair)
        surf = cls(V, F, aperture, str(path))
        surf.mesh_info = info
        return surf

    def _raycasting(self):
        if self._scene is None:
            import open3d as o3d

            scene = o3d.t.geometry.RaycastingScene()
            vf = (self.vertices - self._origin).astype(_BVH_FLOAT)
            scene.add_triangles(vf, self.triangles.astype(np.uint32))
            self._scene = scene
        return self._scene

    def _triangles_under(self, x, y) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        ztop = self.vertices[:, 2].max() - self._origin[2] + 1.0
        rays = np.column_stack([x - self._origin[0], y - self._origin[1], np.full(x.shape, ztop),
                                np.zeros(x.shape), np.zeros(x.shape), -np.ones(x.shape)])
        import open3d as o3d

        ans = self._raycasting().cast_rays(o3d.core.Tensor(rays.astype(_BVH_FLOAT)))
        ids = ans["primitive_ids"].numpy().astype(np.int64)
        miss = ids == np.iinfo(np.uint32).max
        if np.any(miss):
            raise DomainError(f"mesh nominal {self.source or ''}: {int(miss.sum())} point(s) lie outside "
                              "the mesh's footprint in x, y (no triangle under them)")
        return ids

    def sag(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        ids = self._triangles_under(x.ravel(), y.ravel())
        n = self.face_normals[ids]
        a = self.vertices[self.triangles[ids, 0]]
        # plane n·(p − a) = 0 solved for z (float64)
        z = a[:, 2] - (n[:, 0] * (x.ravel() - a[:, 0]) + n[:, 1] * (y.ravel() - a[:, 1])) / n[:, 2]
        return z.reshape(x.shape)

    def gradient(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        n = self.face_normals[self._triangles_under(x.ravel(), y.ravel())]
        return (-n[:, 0] / n[:, 2]).reshape(x.shape), (-n[:, 1] / n[:, 2]).reshape(x.shape)

    def foot_point(self, xyz):
        """Closest point of the mesh, the face normal there and the signed distance (+z side +)."""
        p = np.asarray(xyz, dtype=np.float64)
        import open3d as o3d

        q32 = o3d.core.Tensor((p - self._origin).astype(_BVH_FLOAT))
        ids = self._raycasting().compute_closest_points(q32)["primitive_ids"].numpy().astype(np.int64)
        tri = self.triangles[ids]
        q = closest_point_on_triangles(p, self.vertices[tri[:, 0]], self.vertices[tri[:, 1]],
                                       self.vertices[tri[:, 2]])
        d = p - q
        dist = np.linalg.norm(d, axis=1)
        n = self.face_normals[ids]
        s = np.sign(np.einsum("ij,ij->i", d, n))
        s[s == 0] = 1.0
        return q, n, dist * s

    def describe(self) -> dict:
        d = {"type": self.kind, "path": self.source, "triangles": int(len(self.triangles))}
        if self.aperture is not None:
            d["aperture"] = self.aperture
        if self.mesh_info and self.mesh_info.get("repaired"):
            d["repaired"] = list(self.mesh_info["repaired"])
        return d
