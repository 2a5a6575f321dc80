"""`register`: best-fit a measured cloud to a mesh nominal (parts with no equation: CAD STL/PLY).

1. Coarse: open3d ICP, point-to-plane (Chen & Medioni 1992; open3d's registration_icp works in
   float64), measured points against points sampled densely on the mesh with its normals, from the
   identity (the operator placed the part near nominal) or from matched centroids.
2. Fine: Gauss–Newton least squares of the exact signed point-to-triangle distances (float64,
   core.surfaces.mesh: the BVH only finds the triangle), 6 rigid parameters
        p' = R(ω) R₀ p + t,   ∂d/∂t = n̂,   ∂d/∂ω = p' × n̂   (small-rotation update),
   with the parameters' standard uncertainties σ²(JᵀJ)⁻¹, σ² = Σd²/(N − 6), and a warning when a
   motion is undetermined by the shape (condition number — a surface of revolution cannot fix its
   own rotation about its axis).
Output: the cloud in the mesh (part) frame; ``residual`` = signed distance to the mesh (mm, positive
on the +z side). The report gives the transform measuring → part as a 4 × 4 matrix, the rotation
as angles about x, y, z (deg, R = Rz·Ry·Rx) and the RMS before and after.

Mesh checks (core.io.mesh, read through pymeshlab — open3d for PLY): no faces, non-manifold edges
or vertices, holes (a sheet has one outer boundary, its outline; a solid none: other boundary loops
are holes), duplicated vertices, zero-area faces, inconsistent orientation. A broken mesh is refused
in one line naming the file and each problem with its count, unless ``repair: true`` — then
pymeshlab repairs it and the report lists what was repaired (``mesh_repaired``).
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context, Params, Step, StepResult, param


class RegisterParams(Params):
    mesh: str | None = param(None, file=True, help="nominal mesh (STL, OBJ, OFF, PLY, 3MF) relative to "
                             "the recipe; empty: the recipe's `surface:` (a mesh, or any analytic nominal)")
    repair: bool = param(False, help="repair a broken mesh (non-manifold edges or vertices, holes, "
                         "duplicated vertices, zero-area faces, inconsistent orientation) instead "
                         "of refusing it; the report says what was repaired")
    init: Literal["identity", "centroid"] = param(
        "identity", help="start of ICP: as measured, or with the centroids matched")
    max_distance: float | None = param(
        None, unit="mm", gt=0, help="ICP correspondence distance; empty: 5 % of the cloud's extent")
    icp_iterations: int = param(60, ge=1, le=10000, help="ICP iterations at most")
    refine_iterations: int = param(30, ge=0, le=1000,
                                   help="least-squares refinement iterations at most (0: ICP only)")


def mesh_problems(vertices, triangles) -> list[str]:
    """What makes a mesh unusable as a nominal (core.io.mesh.check_mesh): no faces, non-manifold
    edges or vertices, holes — a sheet (the optical surface) has one outer boundary, a closed solid
    none; more boundary loops are holes —, duplicated vertices, zero-area faces, inconsistent
    orientation. Each entry names a problem with its count."""
    from pointspro.core.io.mesh import check_mesh

    return check_mesh(vertices, triangles).problems()


def _target_points(surf, p, n):
    """ICP target: points with normals sampled densely on the nominal (a mesh's faces uniformly; an
    analytic surface on a grid over the cloud's footprint, 10 % wider, inside its aperture)."""
    import open3d as o3d

    from pointspro.core.errors import DomainError
    from pointspro.core.surfaces.mesh import MeshSurface

    count = int(min(max(4 * n, 50_000), 500_000))
    if isinstance(surf, MeshSurface):
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(surf.vertices),
                                         o3d.utility.Vector3iVector(surf.triangles))
        mesh.compute_triangle_normals()
        return mesh.sample_points_uniformly(number_of_points=count, use_triangle_normal=True)
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    pad = 0.1 * (hi - lo)
    k = int(np.sqrt(count))
    gx, gy = np.meshgrid(np.linspace(lo[0] - pad[0], hi[0] + pad[0], k),
                         np.linspace(lo[1] - pad[1], hi[1] + pad[1], k))
    gx, gy = gx.ravel(), gy.ravel()
    if surf.aperture:
        inside = np.hypot(gx, gy) <= surf.aperture / 2
        gx, gy = gx[inside], gy[inside]
    try:
        gz = surf.sag(gx, gy)
    except DomainError as e:
        raise StepError(f"the nominal is not defined over the cloud's footprint: {e}") from None
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([gx, gy, gz])))
    pc.normals = o3d.utility.Vector3dVector(surf.normal(gx, gy))
    return pc


def _rot(w):
    """Rotation matrix of the rotation vector w (rad), Rodrigues."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(w).as_matrix()


class RegisterStep(Step):
    id = "register"
    title = "Register to mesh nominal"
    makes_residual = True
    summary = "ICP (point-to-plane) then least squares to a CAD mesh; signed distance → residual."
    Params = RegisterParams

    def _load(self, params, ctx):
        """The nominal, its name, and what was repaired of its mesh (a list; empty: nothing)."""
        from pointspro.core.io.mesh import check_mesh, repair_mesh
        from pointspro.core.surfaces.mesh import MeshSurface

        if params.mesh is None:
            surf = ctx.surface
            if surf is None:
                raise StepError("no mesh given and the recipe has no nominal `surface:`")
            name = getattr(surf, "source", None) or surf.kind
            if not isinstance(surf, MeshSurface):
                return surf, name, []
            if surf.mesh_info is not None:  # read from a file: checked (and repaired) then
                return surf, name, list(surf.mesh_info.get("repaired", []))
            chk = check_mesh(surf.vertices, surf.triangles)
            probs = chk.problems()
            if not probs:
                return surf, name, []
            if not params.repair or chk.faces == 0:
                raise InputError(f"{name}: unusable nominal mesh: {', '.join(probs)}"
                                 + (" — fix the mesh or set repair: true" if chk.faces else ""))
            try:
                v, t, rep = repair_mesh(surf.vertices, surf.triangles, chk)
            except InputError as e:
                raise InputError(f"{name}: unusable nominal mesh: {e}") from None
            return MeshSurface(v, t, surf.aperture, surf.source), name, rep.done
        p = ctx.resolve(params.mesh, "mesh")  # relative to the recipe; only where it may reach
        if not p.is_file():
            raise InputError(f"{p}: nominal mesh file not found")
        surf = MeshSurface.from_file(p, repair=params.repair)
        return surf, str(p), list(surf.mesh_info.get("repaired", []))

    def run(self, cloud, params: RegisterParams, ctx: Context) -> StepResult:
        import open3d as o3d

        surf, name, repaired = self._load(params, ctx)
        p = cloud.xyz
        if cloud.n < 6:
            raise StepError(f"{cloud.n} points cannot fix a rigid transform (6 parameters)")
        ctx.progress.update(0.05, "sampling the mesh")
        target = _target_points(surf, p, cloud.n)
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p.copy()))
        T0 = np.eye(4)
        if params.init == "centroid":
            T0[:3, 3] = np.asarray(target.get_center()) - p.mean(axis=0)
        extent = float(np.linalg.norm(np.ptp(p, axis=0)))
        dmax = params.max_distance or 0.05 * extent
        ctx.progress.update(0.15, "ICP")
        icp = o3d.pipelines.registration.registration_icp(
            src, target, dmax, T0, o3d.pipelines.registration.TransformationEstimationPointToPlane(),
            o3d.pipelines.registration.ICPConvergenceCriteria(relative_fitness=1e-9, relative_rmse=1e-9,
                                                              max_iteration=params.icp_iterations))
        T = np.asarray(icp.transformation, dtype=np.float64).copy()
        ctx.progress.check()
        q = p @ T[:3, :3].T + T[:3, 3]
        d = surf.foot_point(q)[2]
        rms_icp = float(np.sqrt(np.mean(d * d)))
        warnings = []
        if icp.fitness < 0.9:
            warnings.append(f"ICP matched only {icp.fitness:.0%} of the points within {dmax:g} mm: "
                            "check the start (init) or max_distance")
        it = 0
        JtJ = None
        for it in range(1, params.refine_iterations + 1):
            ctx.progress.check()
            ctx.progress.update(0.3 + 0.6 * it / max(params.refine_iterations, 1), "least squares")
            _, n, d = surf.foot_point(q)
            J = np.column_stack([np.cross(q, n), n])  # ∂d/∂(ω, t)
            # columns in the same unit (a rotation as the arc it moves a point at the extent, mm), not
            # each scaled to unit norm: on a surface of revolution ∂d/∂ω_z is rounding noise, which
            # unit scaling blew up to rotation steps of 10¹¹° (residual 0.1 → 286 µm, issue 16's
            # review); here the null direction's singular value is cut and that motion held
            scale = np.array([extent] * 3 + [1.0] * 3)
            step, *_ = np.linalg.lstsq(J / scale, -d, rcond=NULL_MOTION)
            step /= scale
            R = _rot(step[:3])
            T = np.vstack([np.column_stack([R @ T[:3, :3], R @ T[:3, 3] + step[3:]]), [0, 0, 0, 1]])
            q = p @ T[:3, :3].T + T[:3, 3]
            if np.max(np.abs(step[:3])) * extent < 1e-12 and np.max(np.abs(step[3:])) < 1e-12:
                break
        foot, n, d = surf.foot_point(q)
        J = np.column_stack([np.cross(q, n), n])
        JtJ = J.T @ J
        dof = max(cloud.n - 6, 1)
        s2 = float(d @ d) / dof
        scale = np.sqrt(np.diag(JtJ))
        scale[scale == 0] = 1.0
        cond = float(np.linalg.cond(JtJ / np.outer(scale, scale)))
        free = _free_motions(J, extent)
        cov = np.linalg.pinv(JtJ, rcond=NULL_MOTION ** 2) * s2
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        if free:
            warnings.append(f"the shape does not fix {' and '.join(free)} (a symmetric surface): held "
                            "where ICP left it, its uncertainty not given")
            sd[[_MOTIONS.index(m) for m in free]] = np.nan
        elif cond > 1e6:
            warnings.append(f"the shape barely fixes every rigid motion (condition {cond:.3g}): a nearly "
                            "symmetric surface leaves a rotation or a slide weakly determined")
        from scipy.spatial.transform import Rotation

        rz, ry, rx = Rotation.from_matrix(T[:3, :3]).as_euler("ZYX", degrees=True)
        report = {
            "nominal": name, "triangles": int(len(getattr(surf, "triangles", ()))),
            "mesh_repaired": repaired,
            "rx_deg": float(rx), "ry_deg": float(ry), "rz_deg": float(rz),
            "tx": float(T[0, 3]), "ty": float(T[1, 3]), "tz": float(T[2, 3]),
            "transform": T.tolist(),
            "uncertainty": {k: (None if not np.isfinite(v) else float(v)) for k, v in zip(
                ("rx_deg", "ry_deg", "rz_deg", "tx", "ty", "tz"),
                (np.degrees(sd[0]), np.degrees(sd[1]), np.degrees(sd[2]), sd[3], sd[4], sd[5]))},
            "icp_fitness": float(icp.fitness), "icp_rms_um": rms_icp * 1e3,
            "refine_iterations": it, "condition_number": cond,
            "residual_rms_um": float(np.sqrt(np.mean(d * d)) * 1e3),
            "residual_pv_um": float(np.ptp(d) * 1e3), "warnings": warnings,
        }
        out = cloud.replace(xyz=q, channels={"residual": d}, meta={"frame": "part"})
        return StepResult(out, report)

    @classmethod
    def example_params(cls) -> dict:
        return {}


#: singular values below this fraction of the largest (columns in mm) are motions the shape does not fix
NULL_MOTION = 1e-9
_MOTIONS = ("rotation about x", "rotation about y", "rotation about z", "a slide along x",
            "a slide along y", "a slide along z")


def _free_motions(J, extent) -> list[str]:
    """The rigid motions (of ``_MOTIONS``) the surface leaves free: the dominant parameter of each
    right-singular vector of J (rotation columns × extent, all in mm) whose singular value is below
    NULL_MOTION of the largest — rotation about z on a surface of revolution, a slide on a plane."""
    sv, vt = np.linalg.svd(J / np.array([extent] * 3 + [1.0] * 3), full_matrices=False)[1:]
    null = vt[sv < NULL_MOTION * sv[0]]
    return sorted({_MOTIONS[int(np.argmax(np.abs(v)))] for v in null}, key=_MOTIONS.index)
