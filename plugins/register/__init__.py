"""`register`: best-fit a measured cloud to a mesh nominal (parts with no equation: CAD STL/PLY).

1. Coarse: ICP, point-to-plane (Chen & Medioni 1992), measured points against points sampled on
   the mesh with its normals (a fixed seed), from the identity (the operator placed the part near
   nominal) or from matched centroids (``_icp``). With x = T p, q the nearest sample (scipy's
   cKDTree, exact) within dmax (max_distance) and n its normal, each iteration solves the
   point-to-plane step linearised for a small rotation ω about the matched points' centroid c (Low
   2004, "Linear least-squares optimization for point-to-plane ICP surface registration", UNC
   TR04-004):
        r = (x − q)·n,   J = [(x − c) × n, n],   (JᵀJ) (ω, t) = −Jᵀr,
   (a motion the samples do not fix gets no step), then T ← [R(ω) | c + t − R(ω)c] T with R(ω)
   exact (Rodrigues), re-orthonormalised; it stops when the fitness (share of the points matched)
   and their RMS distance to the match change by under 10⁻⁹ (open3d's registration_icp's criterion;
   open3d did this stage before: threaded, its sums came in a varying order and the pose changed
   run to run; on one thread it was slow — on a 200,000-point freeform 3.8 s, threaded 2.7 s, this
   one 1.6 s, the same pose to 10⁻¹¹), or after ``icp_iterations``. Float64; each point's search
   is its own (threads: core.parallel.thread_count), the sums are numpy's and BLAS's on one thread
   (the whole step runs in core.parallel.single_threaded_blas): the pose is the same bits on every
   run, whatever the threads.
2. Motions the nominal does not fix are found at the start or ICP pose (the SVD of J below): *free*
   (a symmetry — a plane's two slides and spin, a surface of revolution's spin, a sphere's three
   rotations) or *weak* (fixed only by the mesh's facets: a sphere's mesh; the singular value of J
   with the vertex normals interpolated is below FACET_FACTOR × ‖J_facets − J_smooth‖₂). They are held
   at the start pose — removed from ICP's motion (where ICP drifted 5–11 mm on a tilted plane) and
   from every least-squares step —, named in the report (``free_motions``, ``weak_motions``) and the
   warnings, and their parameter gets no uncertainty. (A review's 600 mm freeform — R 2000 mm with
   90 µm of astigmatism — on a 2.5 mm mesh: rotation about x weak; with points on the smooth surface,
   held it is 7″ off, fitted the facets set it 94″ off; with points on the facets themselves fitting
   would be exact. Real parts are smooth: held.)
3. The better of the start and ICP poses (exact distance RMS over every point) starts a
   Levenberg–Marquardt least squares of the exact signed point-to-triangle distances (float64, the
   BVH only finds the triangle), the motions not held as parameters,
        p' = R(ω) R₀ p + t,   ∂d/∂t = ∇d,   ∂d/∂ω = p' × ∇d   (small-rotation update),
   ∇d the face normal, or the direction to the foot on an edge; a step that raises the cost is
   refused and the damping raised. Standard uncertainties from the same scaled, truncated SVD:
   σ²(JᵀJ)⁻¹ over the fitted motions, σ² = Σd²/(N − fitted).
4. Refused in one line: fewer than MIN_FITNESS of the points with their foot inside the nominal (not
   on the mesh's boundary; a unit mismatch named from the bounding boxes: ×10³, ×10⁶, ×25.4), a cloud
   on a handful of a mesh's facets with such a size ratio, and a residual above RESIDUAL_FLOOR_MM and
   RATIO_LIMIT of the nominal's own departure from a plane (a local minimum).
Output: the cloud in the mesh (part) frame; ``residual`` = signed distance to the mesh (mm, positive
outside the part, on the side its faces face): the faces are oriented coherently (the two faces on
an edge run it in opposite directions), each connected piece as a whole facing +z (a sheet: the sum
of its area-weighted normals has z > 0) or outward (a closed piece: positive enclosed volume). On a
height field that is the +z side, as z − sag; on an undercut wall (a face facing −z out of the part)
and a closed solid's underside it is outside the part too (it was the +z side of each face, which
MeshSurface turns to +z: a point outside an undercut read negative). The residual includes the
mesh's chordal error (its facets against the surface they approximate); the report estimates it,
``chord_deviation_um`` (RMS over the points of the sagitta L²/(8R) = Lθ/8 of the triangle under
them, L an edge, θ the angle of its vertex normals) and warns when it reaches the residual's RMS.
The report gives the transform measuring → part as a 4 × 4 matrix, the rotation as angles about x,
y, z (deg, R = Rz·Ry·Rx), the RMS before and after, ``fitness`` (share of points over the nominal)
and ``start`` (which pose the least squares began at).

Mesh checks (core.io.mesh, read through pymeshlab — open3d for PLY): no faces, non-manifold edges
or vertices, holes (a sheet has one outer boundary, its outline; a solid none: other boundary loops
are holes), duplicated vertices, zero-area faces, inconsistent orientation. A broken mesh is refused
in one line naming the file and each problem with its count, unless ``repair: true`` — then
pymeshlab repairs it and the report lists what was repaired (``mesh_repaired``).
"""
from __future__ import annotations

from typing import Literal, NamedTuple

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
    """ICP target: points (M, 3) and their unit normals (M, 3) sampled densely on the nominal (a
    mesh's faces uniformly, each point with its face's normal; an analytic surface on a grid over the
    cloud's footprint, 10 % wider, inside its aperture)."""
    from pointspro.core.errors import DomainError
    from pointspro.core.surfaces.mesh import MeshSurface

    count = int(min(max(4 * n, 50_000), 500_000))
    if isinstance(surf, MeshSurface):
        # uniform over the area, with a fixed seed: the same input gives the same result (open3d's
        # sample_points_uniformly drew anew each run — a review: 1.26 then 1.44 mm on one input)
        V, F = surf.vertices, surf.triangles
        area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
        rng = np.random.default_rng(0)
        k = np.minimum(np.searchsorted(np.cumsum(area) / area.sum(), rng.random(count)), len(F) - 1)
        r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
        a, b, c = (V[F[k, j]] for j in range(3))
        pts = (1 - r1)[:, None] * a + (r1 * (1 - r2))[:, None] * b + (r1 * r2)[:, None] * c
        return pts, surf.face_normals[k]
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
    return np.column_stack([gx, gy, gz]), np.asarray(surf.normal(gx, gy), dtype=np.float64)


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
            # orientation: coherent as given (a sheet with undercut walls, which MeshSurface's turning
            # of each face to +z breaks) or once turned to +z (a height field wound both ways) will do
            faces = surf.triangles
            chk = check_mesh(surf.vertices, faces)
            if chk.inconsistent_edges:
                given = check_mesh(surf.vertices, surf.triangles_given)
                if given.inconsistent_edges < chk.inconsistent_edges:
                    faces, chk = surf.triangles_given, given
            probs = chk.problems()
            if not probs:
                return surf, name, []
            if not params.repair or chk.faces == 0:
                raise InputError(f"{name}: unusable nominal mesh: {', '.join(probs)}"
                                 + (" — fix the mesh or set repair: true" if chk.faces else ""))
            try:
                v, t, rep = repair_mesh(surf.vertices, faces, chk)
            except InputError as e:
                raise InputError(f"{name}: unusable nominal mesh: {e}") from None
            return MeshSurface(v, t, surf.aperture, surf.source), name, rep.done
        p = ctx.resolve(params.mesh, "mesh")  # relative to the recipe; only where it may reach
        if not p.is_file():
            raise InputError(f"{p}: nominal mesh file not found")
        surf = MeshSurface.from_file(p, repair=params.repair)
        return surf, str(p), list(surf.mesh_info.get("repaired", []))

    def run(self, cloud, params: RegisterParams, ctx: Context) -> StepResult:
        import scipy.spatial  # noqa: F401 — loads scipy's BLAS before it is pinned below (kept 1 thread)

        from pointspro.core.parallel import single_threaded_blas

        # BLAS on one thread: its calls here are narrow (N × 3 poses, 6 × 6 sums, N × 6 least
        # squares), where threads only synchronise (p @ R.T took 108 ms instead of 4 ms beside a busy
        # core) and split the sums in an order that depends on the thread count — the pose is the
        # same bits whatever the threads (core.parallel)
        with single_threaded_blas():
            return self._run(cloud, params, ctx)

    def _run(self, cloud, params: RegisterParams, ctx: Context) -> StepResult:
        surf, name, repaired = self._load(params, ctx)
        p = cloud.xyz
        if cloud.n < 6:
            raise StepError(f"{cloud.n} points cannot fix a rigid transform (6 parameters)")
        order = _locality_order(p)
        geo = _Geometry(surf, order)
        ctx.progress.update(0.05, "sampling the mesh")
        tp, tn = _target_points(surf, p, cloud.n)
        T0 = np.eye(4)
        if params.init == "centroid":
            T0[:3, 3] = tp.mean(axis=0) - p.mean(axis=0)
        extent = float(np.linalg.norm(np.ptp(p, axis=0)))
        scale = np.array([extent] * 3 + [1.0] * 3)  # rotations as the arc at the extent: all in mm
        dmax = params.max_distance or 0.05 * extent
        ctx.progress.update(0.15, "ICP")
        icp = _icp(p[order], tp, tn, T0, dmax, params.icp_iterations, extent, check=ctx.progress.check)
        T_icp = icp.T
        ctx.progress.check()
        # the motions the nominal leaves free (a plane's slides and spin, a surface of revolution's
        # spin) or fixes only by its facets (a sphere's mesh): point-to-plane ICP drifts along them
        # (a review: 5–11 mm on a tilted plane, the points off the mesh, residual 0.7–1.7 mm, exit 0).
        # They are found where more points lie over the nominal (start or ICP pose) and held at the
        # start pose: removed from ICP's motion and from every least-squares step.
        ev0, ev1 = geo.evaluate(_apply(T0, p)), geo.evaluate(_apply(T_icp, p))
        held, motions = _held_motions(ev1 if ev1.inside.sum() >= ev0.inside.sum() else ev0, extent)
        if held.shape[1]:  # nothing held: T_icp and ev1 stand
            T_icp = _hold(T_icp, T0, held, extent)
            ev1 = geo.evaluate(_apply(T_icp, p))
        # the better of the start and the (held) ICP pose, by the exact distance to the nominal over
        # every point (a point off the mesh counts with its distance to the mesh's edge)
        start = "ICP" if ev1.cost <= ev0.cost else "start"
        T, ev = (T_icp, ev1) if start == "ICP" else (T0, ev0)
        if not np.isfinite(ev.cost):
            raise StepError("the nominal is not defined where the points lie, from the start nor after "
                            "ICP: check the nominal, the start (init) and the units")
        rms_icp = float(np.sqrt(ev1.cost)) if np.isfinite(ev1.cost) else float("inf")
        B = _complement(held)
        it = accepted = 0
        lam = 0.0  # Levenberg–Marquardt: a step that raises the exact cost is refused, lam raised
        while it < params.refine_iterations and B.shape[1]:
            it += 1
            ctx.progress.check()
            ctx.progress.update(0.3 + 0.6 * it / max(params.refine_iterations, 1), "least squares")
            J = np.column_stack([np.cross(ev.x, ev.grad), ev.grad]) / scale @ B  # ∂d/∂(ω, t), scaled
            done = False
            for _ in range(12):
                if lam:
                    D = np.sqrt(lam * (np.einsum("ij,ij->j", J, J) + 1e-12 * np.max(J * J) * len(J)))
                    A, b = np.vstack([J, np.diag(D)]), np.concatenate([-ev.d, np.zeros(len(D))])
                else:
                    A, b = J, -ev.d
                z, *_ = np.linalg.lstsq(A, b, rcond=NULL_MOTION)
                step = (B @ z) / scale
                Tn = _compose(step, T)
                evn = geo.evaluate(_apply(Tn, p))
                tiny = np.max(np.abs(step[:3])) * extent < 1e-12 and np.max(np.abs(step[3:])) < 1e-12
                if evn.cost < ev.cost:
                    # converged: the step's gain is rounding (10⁻¹⁰ of the cost) or the step is
                    done = tiny or ev.cost - evn.cost <= 1e-10 * ev.cost
                    T, ev, accepted = Tn, evn, accepted + 1
                    lam = 0.0 if lam <= 1e-6 else lam / 10
                    break
                if tiny:
                    done = True
                    break
                lam = 1e-6 if not lam else lam * 10
            else:
                done = True  # no step lowers the cost: at the minimum (to rounding)
            if done:
                break
        q, d = ev.x, ev.d
        fitness = float(np.mean(ev.inside))
        hint = _unit_hint(surf, p)
        if fitness < MIN_FITNESS:
            raise StepError(
                f"only {fitness:.0%} of the points lie over the nominal after the fit (the rest fall "
                f"beyond its edge; residual {np.sqrt(ev.cost) * 1e3:.4g} µm RMS): "
                + (hint if hint else "the cloud does not match the nominal — check the start (init, "
                   "max_distance), the part's orientation and that the nominal covers the measured area"))
        if hint and ev.ids is not None and len(np.unique(ev.ids[ev.inside])) < 10:
            # over the mesh but on a few of its facets: a mesh 10³ times too large (µm read as mm)
            raise StepError(f"the points lie on {len(np.unique(ev.ids[ev.inside]))} of the mesh's "
                            f"{len(surf.triangles)} triangles: {hint}")
        rms = float(np.sqrt(np.mean(d * d)))
        shape = _shape_rms(q - d[:, None] * ev.grad)
        if rms > RESIDUAL_FLOOR_MM and rms > RATIO_LIMIT * shape:
            # a local minimum: ICP and the least squares start from near the nominal only (a review:
            # a freeform turned 90° about z, residual 1.07 mm RMS on 4 mm of sag, fitness 95 %)
            raise StepError(
                f"the fit left a residual of {rms:.4g} mm RMS, {rms / shape:.2g} × the nominal's own "
                f"departure from a plane over the points ({shape:.4g} mm RMS): a local minimum, not "
                "the part — ICP starts from the measured pose (init: identity) or the centroids: "
                "bring the cloud near the nominal's orientation first")
        warnings = []
        dof = max(cloud.n - B.shape[1], 1)
        s2 = float(d @ d) / dof
        J = np.column_stack([np.cross(q, ev.grad), ev.grad]) / scale
        sd, cond = _uncertainties(J, B, [m for m, _ in motions], s2, scale)
        free = [m for m, kind in motions if kind == "free"]
        weak = [m for m, kind in motions if kind == "weak"]
        if free:
            warnings.append(f"the shape does not fix {' and '.join(free)} (a symmetric surface): held "
                            "at the start pose, no uncertainty given for it")
        if weak:
            warnings.append(f"only the mesh's facets fix {' and '.join(weak)} (the surface it approximates "
                            f"leaves {'it' if len(weak) == 1 else 'them'} free or nearly): held at the "
                            "start pose, no uncertainty given for it — the part's own motion along "
                            f"{'it' if len(weak) == 1 else 'them'} stays in the residual")
        if cond > 1e6:
            warnings.append(f"the shape barely fixes every rigid motion (condition {cond:.3g}): a nearly "
                            "symmetric surface leaves a rotation or a slide weakly determined")
        if fitness < 0.99:
            warnings.append(f"{1 - fitness:.1%} of the points lie beyond the nominal's edge: their "
                            "residual is the distance to the edge")
        chord = geo.chord(ev)
        if chord is not None and chord[0] >= rms > 0:
            warnings.append(f"the mesh's facets depart from the surface they approximate by about "
                            f"{chord[0] * 1e3:.3g} µm (chordal error, up to {chord[1] * 1e3:.3g} µm), "
                            f"comparable to the residual ({rms * 1e3:.3g} µm RMS), which includes it: "
                            "a finer mesh would measure the part, not its tessellation")
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
            "free_motions": free, "weak_motions": weak, "start": start,
            "icp_fitness": float(icp.fitness), "icp_rms_um": rms_icp * 1e3, "fitness": fitness,
            "refine_iterations": it, "condition_number": cond,
            "residual_rms_um": rms * 1e3,
            "residual_pv_um": float(np.ptp(d) * 1e3), "warnings": warnings,
        }
        if chord is not None:
            report["chord_deviation_um"] = chord[0] * 1e3
            report["chord_deviation_max_um"] = chord[1] * 1e3
        out = cloud.replace(xyz=q, channels={"residual": d}, meta={"frame": "part"})
        return StepResult(out, report)

    @classmethod
    def example_params(cls) -> dict:
        return {}


#: singular values below this fraction of the largest (columns in mm) are motions the shape does not fix
NULL_MOTION = 1e-9
_MOTIONS = ("rotation about x", "rotation about y", "rotation about z", "a slide along x",
            "a slide along y", "a slide along z")
#: a motion whose singular value (smooth normals) is below this many times the facets' share of J
#: (‖J_facets − J_smooth‖₂) is fixed by the tessellation rather than by the surface: weak, held
FACET_FACTOR = 0.1
#: the least share of points whose foot lies over the nominal (not on its edge) for a result
MIN_FITNESS = 0.9
#: the vertex-normal angle (rad) above which an edge is a feature of the part (a crease), not curvature
_CREASE = np.radians(30.0)
#: a residual above RESIDUAL_FLOOR_MM and RATIO_LIMIT of the nominal's own departure from a plane over
#: the points is a local minimum, refused (the rule of core.geometry.nominal_check for misalignment)
RESIDUAL_FLOOR_MM = 0.1
RATIO_LIMIT = 0.25
_AXES = "xyz"


def _apply(T, p):
    return p @ T[:3, :3].T + T[:3, 3]


def _compose(step, T):
    """The update p' = R(ω)·(T p) + t of step (ω, t) composed with T."""
    R = _rot(step[:3])
    return np.vstack([np.column_stack([R @ T[:3, :3], R @ T[:3, 3] + step[3:]]), [0, 0, 0, 1]])


#: ICP's normal equations: eigenvalues of JᵀJ (scaled) below this fraction of the largest are motions
#: the sampled nominal does not fix (singular value < 10⁻⁵): no step along them — ICP drifted 5–11 mm
#: along a plane's free slides; stage 3 fits what ICP leaves, with its own, finer threshold
ICP_NULL = 1e-10
#: ICP stops when neither the fitness nor the correspondences' RMS distance changes by this much
ICP_RELATIVE = 1e-9


class _ICPResult(NamedTuple):
    T: np.ndarray        # 4 × 4, measuring → part
    fitness: float       # share of the points with a correspondence within dmax
    rmse: float          # RMS distance of the points to their correspondence (mm)
    iterations: int


def _locality_order(p):
    """A permutation of the points that keeps neighbours together (the leaf order of a k-d tree on
    them): neighbour searches in that order reuse the search tree in cache — a 200,000-point query
    took 0.14 s instead of 0.39 s (k-d tree), a closest-triangle search 0.17 s instead of 0.31 s."""
    from scipy.spatial import cKDTree

    return np.asarray(cKDTree(p, balanced_tree=False, compact_nodes=False).indices, dtype=np.int64)


def _icp(p, tp, tn, T0, dmax, iterations, extent, workers=None, check=None) -> _ICPResult:
    """Stage 1, point-to-plane ICP (Chen & Medioni 1992) of the points p (best in a spatially coherent
    order: ``_locality_order``) to the target points tp with unit normals tn, from the pose T0.

    Each iteration, with x_i = T p_i: q_i the nearest target point (scipy's cKDTree, exact, built once;
    the points searched on ``workers`` threads, default core.parallel.thread_count — each search on its
    own, the answer the same for any count), kept where ‖x_i − q_i‖ ≤ dmax; then the rigid step about
    their centroid c that minimises the point-to-plane distances, linearised for a small rotation ω
    (Low 2004, "Linear least-squares optimization for point-to-plane ICP surface registration",
    TR04-004, UNC; R(ω) ≈ I + [ω]×):
        r_i = (x_i − q_i)·n_i,   J_i = [(x_i − c) × n_i, n_i],   (JᵀJ) (ω, t) = −Jᵀr,
    columns scaled (ω × extent, mm), solved by the eigen-decomposition of the 6 × 6 with eigenvalues
    below ICP_NULL of the largest left out (no step along a motion the samples do not fix); then
        T ← [R(ω) | c + t − R(ω) c] T,   R(ω) exact (Rodrigues), T's rotation re-orthonormalised
    (U Vᵀ of its SVD). Stops after ``iterations`` or when the fitness (share of the points with a
    correspondence) and the RMSE (RMS of ‖x_i − q_i‖ over them) — open3d's registration_icp's
    definitions and criterion — both change by less than ICP_RELATIVE. Float64 throughout; the sums
    are numpy's and BLAS's on one thread (the caller's core.parallel.single_threaded_blas, and here):
    the same bits on every run, whatever the thread count."""
    from scipy.spatial import cKDTree

    from pointspro.core.parallel import single_threaded_blas, thread_count, threaded_query

    workers = max(1, int(workers or thread_count()))
    tree = cKDTree(tp, balanced_tree=False)
    scale = np.array([extent] * 3 + [1.0] * 3)
    n = len(p)

    def match(T):
        x = _apply(T, p)
        dist, idx = threaded_query(tree, x, k=1, distance_upper_bound=dmax, workers=workers)
        ok = idx < len(tp)  # none within dmax: idx = len(tp), dist = inf
        k = int(np.count_nonzero(ok))
        dk = dist[ok]
        return x, idx, ok, k / n, (float(np.sqrt(dk @ dk / k)) if k else 0.0)

    with single_threaded_blas():
        T = np.array(T0, dtype=np.float64)
        x, idx, ok, fitness, rmse = match(T)
        it = 0
        while it < iterations and fitness > 0:
            it += 1
            if check is not None:
                check()
            xs, j = x[ok], idx[ok]
            q, nn = tp[j], tn[j]
            c = xs.mean(axis=0)
            r = np.einsum("ij,ij->i", xs - q, nn)
            J = np.column_stack([np.cross(xs - c, nn), nn]) / scale
            w, V = np.linalg.eigh(J.T @ J)
            keep = w > ICP_NULL * w[-1]
            z = -(V[:, keep] @ ((V[:, keep].T @ (J.T @ r)) / w[keep])) / scale
            R = _rot(z[:3])
            U = np.eye(4)
            U[:3, :3], U[:3, 3] = R, c + z[3:] - R @ c
            T = U @ T
            u, _, vt = np.linalg.svd(T[:3, :3])
            T[:3, :3] = u @ vt
            f0, e0 = fitness, rmse
            x, idx, ok, fitness, rmse = match(T)
            if abs(fitness - f0) < ICP_RELATIVE and abs(rmse - e0) < ICP_RELATIVE:
                break
    return _ICPResult(T, fitness, rmse, it)


class _Eval:
    """The points x (part frame) against the nominal: signed distance d, its gradient ``grad`` (the
    face normal over a face, the direction to the foot on an edge), the facet and smooth (vertex
    normals interpolated) normals at the foot, whether the foot lies over the nominal (``inside``:
    not on the mesh's boundary, inside an analytic nominal's aperture), the triangle (mesh)."""

    def __init__(self, x, d, grad, nf, ns, inside, ids=None):
        self.x, self.d, self.grad, self.nf, self.ns, self.inside, self.ids = x, d, grad, nf, ns, inside, ids
        self.cost = float(np.mean(d * d)) if np.all(np.isfinite(d)) else float("inf")


def _edge_dihedral(fn, key, srt, count) -> np.ndarray:
    """For each (triangle, edge) of the flattened (T·3) edge list: the angle (rad) between the normals
    of the two faces on the edge (oriented coherently), 0 on a boundary or non-manifold edge."""
    out = np.zeros(len(key))
    ks = key[srt]
    pair = np.flatnonzero((ks[1:] == ks[:-1]) & (count[srt[1:]] == 2))
    i, j = srt[pair], srt[pair + 1]
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", fn[i // 3], fn[j // 3]), -1.0, 1.0))
    out[i], out[j] = ang, ang
    return out


class _Geometry:
    """What register needs of the nominal beyond ``foot_point``: for a mesh the boundary edges and
    vertices (a foot on them lies beyond the nominal), vertex normals (the smooth surface the facets
    approximate) and each triangle's chordal deviation."""

    def __init__(self, surf, order=None):
        from pointspro.core.surfaces.mesh import MeshSurface

        self.surf = surf
        self.order = order  # the points' search order (_locality_order): the same answers, faster
        self.mesh = isinstance(surf, MeshSurface)
        if not self.mesh:
            return
        V, F = surf.vertices, surf.triangles
        nv = len(V)
        # edge opposite vertex k of each triangle: (1, 2), (2, 0), (0, 1)
        e = np.stack([F[:, [1, 2]], F[:, [2, 0]], F[:, [0, 1]]], axis=1)  # (T, 3, 2)
        key = (np.min(e, axis=2) * nv + np.max(e, axis=2)).ravel()
        srt = np.argsort(key, kind="stable")
        ks = key[srt]
        grp = np.cumsum(np.concatenate([[True], ks[1:] != ks[:-1]])) - 1
        count = np.empty(len(key), np.int64)
        count[srt] = np.bincount(grp)[grp]  # faces on each triangle's edge
        self.bedge = (count == 1).reshape(F.shape)
        self.bvert = np.zeros(nv, bool)
        self.bvert[e[self.bedge].ravel()] = True
        cr = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])  # area-weighted, +z (MeshSurface)
        # the faces' sides: +z each (MeshSurface), turned where that breaks the mesh's coherent
        # orientation (an undercut, a closed solid's underside, a wall's facets at n_z ≈ 0)
        side = _coherent_sides(V, F, e, key, srt, count, cr)
        self.fn = surf.face_normals
        if side is not None:
            self.fn = surf.face_normals * side[:, None]
            cr = cr * side[:, None]
        vn = np.zeros_like(V)
        for k in range(3):
            np.add.at(vn, F[:, k], cr)
        norm = np.linalg.norm(vn, axis=1)
        norm[norm == 0] = 1.0
        self.vn = vn / norm[:, None]
        # chordal deviation (sagitta) of each triangle: along each edge of length L whose end normals
        # differ by θ, the surface bends by radius R ≈ L/θ and its chord departs by L²/(8R) = Lθ/8;
        # an edge whose normals differ by more than _CREASE is a crease of the part, not a curvature
        a, b = self.vn[e[..., 0]], self.vn[e[..., 1]]
        theta = np.arccos(np.clip(np.einsum("ijk,ijk->ij", a, b), -1.0, 1.0))
        # at a crease the vertex normals mix the faces on both sides (a box's rim: top and wall), which
        # split a 90° edge into "curvature" below the crease limit — flat walls read sagittas of 372 µm
        # and a chordal error of 125 µm for 0.06 µm (a review): on the edges of a crease's vertices
        # the angle between the two faces on the edge is taken instead
        dihedral = _edge_dihedral(self.fn, key, srt, count).reshape(F.shape)
        on_crease = np.zeros(nv, bool)
        on_crease[e[dihedral > _CREASE].ravel()] = True
        near = on_crease[e[..., 0]] | on_crease[e[..., 1]]
        theta = np.where(near, dihedral, theta)
        L = np.linalg.norm(V[e[..., 0]] - V[e[..., 1]], axis=2)
        self.sagitta = np.max(np.where(theta <= _CREASE, L * theta / 8, 0.0), axis=1)

    def evaluate(self, x) -> _Eval:
        from pointspro.core.errors import DomainError

        if not self.mesh:
            try:
                foot, n, d = self.surf.foot_point(x)
            except DomainError:
                nan = np.full(len(x), np.nan)
                return _Eval(x, nan, np.zeros_like(x), np.zeros_like(x), np.zeros_like(x),
                             np.zeros(len(x), bool))
            ap = getattr(self.surf, "aperture", None)
            inside = (np.hypot(foot[:, 0], foot[:, 1]) <= ap / 2 * (1 + 1e-12)) if ap else \
                np.ones(len(x), bool)
            return _Eval(x, d, n, n, n, inside & np.isfinite(d))
        import open3d as o3d

        from pointspro.core.surfaces.mesh import closest_point_on_triangles

        surf = self.surf
        o = self.order if self.order is not None and len(self.order) == len(x) else slice(None)
        q32 = o3d.core.Tensor((x[o] - surf._origin).astype(np.float32))
        ids = np.empty(len(x), np.int64)
        ids[o] = surf._raycasting().compute_closest_points(q32)["primitive_ids"].numpy()
        tri = surf.triangles[ids]
        a, b, c = (surf.vertices[tri[:, k]] for k in range(3))
        foot = closest_point_on_triangles(x, a, b, c)
        diff = x - foot
        dist = np.linalg.norm(diff, axis=1)
        nf = self.fn[ids]
        s = np.sign(np.einsum("ij,ij->i", diff, nf))
        s[s == 0] = 1.0
        d = dist * s
        # the exact gradient of the signed distance: toward the foot on an edge or a vertex
        off = dist > 1e-12 * (1.0 + np.abs(x).max())
        grad = nf.copy()
        grad[off] = diff[off] * (s[off] / dist[off])[:, None]
        # barycentric coordinates of the foot: on the mesh's boundary when it lies on a boundary
        # edge or at a boundary vertex
        v0, v1, v2 = b - a, c - a, foot - a
        d00, d01, d11 = (np.einsum("ij,ij->i", u, w) for u, w in ((v0, v0), (v0, v1), (v1, v1)))
        d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
        den = d00 * d11 - d01 * d01
        bv = (d11 * d20 - d01 * d21) / den
        bw = (d00 * d21 - d01 * d20) / den
        bary = np.column_stack([1.0 - bv - bw, bv, bw])
        eps = 1e-9
        edge = np.any((bary <= eps) & self.bedge[ids], axis=1)
        vert = np.any((bary >= 1 - eps) & self.bvert[tri], axis=1)
        ns = np.einsum("ik,ikj->ij", np.clip(bary, 0, 1), self.vn[tri])
        ns /= np.linalg.norm(ns, axis=1)[:, None]
        return _Eval(x, d, grad, nf, ns, ~(edge | vert), ids)

    def chord(self, ev):
        """(RMS, max) over the points over the mesh of the chordal deviation of the triangle under
        them (mm); None for an analytic nominal."""
        if not self.mesh:
            return None
        s = self.sagitta[ev.ids[ev.inside]] if np.any(ev.inside) else self.sagitta
        return float(np.sqrt(np.mean(s * s))), float(np.max(s))


def _coherent_sides(V, F, e, key, srt, count, cr):
    """±1 per face: the side of each (+z-oriented, MeshSurface) face that faces out of the part, so
    that the faces are coherently oriented — the two faces on each edge run it in opposite directions
    —, and each connected piece as a whole faces +z (a sheet: the sum of its area-weighted normals has
    z > 0) or outward (a closed piece: its enclosed volume, Σ a·(b × c)/6, is positive). None when
    the +z faces already are coherent (a height field: every face +z, nothing turned). e: the
    triangles' edges (T, 3, 2), key their vertex pairs (3T), srt key's sort, count the faces on each."""
    ks = key[srt]
    pair = np.flatnonzero((ks[1:] == ks[:-1]) & (count[srt[:-1]] == 2))
    a, b = srt[pair], srt[pair + 1]  # the two sides (face·3 + edge) of each interior edge
    start = e[..., 0].ravel()
    same = start[a] == start[b]  # both faces run the edge the same way: one of them is turned
    if not np.any(same):
        return None
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    # each face in its two orientations (f, f + T): coherent neighbours join the same orientations,
    # incoherent ones the opposite; a connected piece becomes two components, one per orientation
    T = len(F)
    f, g = a // 3, b // 3
    gs = np.where(same, g + T, g)
    rows = np.concatenate([f, f + T])
    cols = np.concatenate([gs, np.where(same, g, g + T)])
    graph = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(2 * T, 2 * T)).tocsr()
    lab = connected_components(graph, directed=False)[1]
    lab0, lab1 = lab[:T], lab[T:]
    side = np.where(lab0 > lab1, -1.0, 1.0)  # each piece's faces as its smaller-labelled orientation
    piece = np.minimum(lab0, lab1)
    closed = np.bincount(piece, weights=(count.reshape(F.shape) == 1).sum(axis=1)) == 0
    c = V - V.mean(axis=0)
    vol = np.einsum("ij,ij->i", c[F[:, 0]], np.cross(c[F[:, 1]], c[F[:, 2]]))
    facing = np.where(closed[piece], np.bincount(piece, weights=side * vol)[piece],
                      np.bincount(piece, weights=side * cr[:, 2])[piece])
    side = np.where(facing < 0, -side, side)
    side[lab0 == lab1] = 1.0  # a non-orientable piece (refused by the mesh check): +z as it is
    return side


def _held_motions(ev, extent):
    """The rigid motions to hold: an orthonormal basis (6 × k, scaled parameters: rotations × extent,
    mm) and their names with "free" (the surface's symmetry: a singular value below NULL_MOTION of
    the largest) or "weak" (a singular value of the smooth surface's J below FACET_FACTOR times what
    the facets add to J: fixed by the tessellation, not by the part — a sphere's mesh). Judged over
    the points whose foot lies over the nominal."""
    m = ev.inside if ev.inside.sum() >= 6 else np.ones(len(ev.d), bool)
    x, nf, ns = ev.x[m], ev.nf[m], ev.ns[m]
    scale = np.array([extent] * 3 + [1.0] * 3)
    Jf = np.column_stack([np.cross(x, nf), nf]) / scale
    Js = np.column_stack([np.cross(x, ns), ns]) / scale
    sv, vt = np.linalg.svd(Js, full_matrices=False)[1:]
    facets = float(np.linalg.norm(Jf - Js, 2)) if ev.ids is not None else 0.0
    free = sv < NULL_MOTION * sv[0]
    weak = ~free & (sv < FACET_FACTOR * facets)
    held = free | weak
    N = vt[held].T
    kinds = ["free" if f else "weak" for f in free[held]]
    return N, _name_motions(N, kinds)


def _name_motions(N, kinds):
    """Names of the motions spanned by N (scaled): its rotations by their axis ("rotation about z"),
    the motions with no rotation by their direction ("a slide along x"); each with its kind."""
    if not N.shape[1]:
        return []
    U, S, Wt = np.linalg.svd(N[:3], full_matrices=True)
    W = Wt.T
    S = np.concatenate([S, np.zeros(N.shape[1] - len(S))])
    names = []
    for i in range(N.shape[1]):
        # the kind of the held direction closest to this combination
        kind = kinds[int(np.argmax(np.abs(W[:, i])))]
        if S[i] > 0.1:
            names.append((f"rotation about {_AXES[int(np.argmax(np.abs(U[:, i])))]}", kind))
        else:
            v = (N @ W[:, i])[3:]
            names.append((f"a slide along {_AXES[int(np.argmax(np.abs(v)))]}", kind))
    rank = {n: k for k, n in enumerate(f"rotation about {a}" for a in _AXES)}
    rank.update({f"a slide along {a}": 3 + k for k, a in enumerate(_AXES)})
    out = []
    for n, k in sorted(names, key=lambda nk: rank[nk[0]]):
        if (n, k) not in out:
            out.append((n, k))
    return out


def _hold(T, T0, N, extent):
    """T with its motion from T0 along the held motions N (scaled) removed."""
    if not N.shape[1]:
        return T
    from scipy.spatial.transform import Rotation

    Rd = T[:3, :3] @ T0[:3, :3].T
    xi = np.concatenate([Rotation.from_matrix(Rd).as_rotvec() * extent, T[:3, 3] - Rd @ T0[:3, 3]])
    xi = xi - N @ (N.T @ xi)
    return _compose(np.concatenate([xi[:3] / extent, xi[3:]]), T0)


def _complement(N):
    """An orthonormal basis (6 × (6 − k)) of the motions not held."""
    if not N.shape[1]:
        return np.eye(6)
    Q = np.linalg.qr(N, mode="complete")[0]
    return Q[:, N.shape[1]:]


def _uncertainties(J, B, held_names, s2, scale):
    """Standard uncertainties of (ω, t) and the condition number (of JᵀJ, scaled), from the same
    scaled, truncated SVD as the fit: σ²(JᵀJ)⁻¹ over the motions fitted (B), the held ones held (the
    parameters' uncertainty at the held pose); none (NaN) for the parameter each held motion is named
    by — its value is a convention (the start pose), not a measurement."""
    sv, vt = np.linalg.svd(J @ B, full_matrices=False)[1:]
    keep = sv > NULL_MOTION * sv[0]
    Vk = B @ vt[keep].T
    cov = (Vk / sv[keep] ** 2) @ Vk.T * s2 / np.outer(scale, scale)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    sd[[_MOTIONS.index(m) for m in held_names]] = np.nan
    cond = float((sv[0] / sv[keep][-1]) ** 2)
    return sd, cond


def _shape_rms(feet) -> float:
    """RMS distance of the feet (points on the nominal) from their best-fit plane (mm)."""
    c = feet - feet.mean(axis=0)
    return float(np.linalg.svd(c, compute_uv=False)[-1] / np.sqrt(len(c)))


def _unit_hint(surf, p) -> str:
    """A likely unit mismatch between the cloud and a mesh, from their bounding boxes ("" if none)."""
    V = getattr(surf, "vertices", None)
    if V is None:
        return ""
    a, b = float(np.linalg.norm(np.ptp(V, axis=0))), float(np.linalg.norm(np.ptp(p, axis=0)))
    if a <= 0 or b <= 0:
        return ""
    r = a / b
    cases = [(1e6, "the mesh in µm and the points in m"), (1e3, "the mesh in µm and the points in mm, "
             "or the mesh in mm and the points in m"), (25.4, "the mesh in mm and the points in inches"),
             (1 / 25.4, "the mesh in inches and the points in mm"),
             (1e-3, "the mesh in m and the points in mm, or the mesh in mm and the points in µm"),
             (1e-6, "the mesh in m and the points in µm")]
    for f, what in cases:
        if abs(np.log(r / f)) < np.log(2.5):
            return (f"the mesh is {r:.4g}× the size of the cloud (bounding-box diagonals "
                    f"{a:.4g} and {b:.4g}): a unit mismatch — {what}? Scale one of them")
    return ""
