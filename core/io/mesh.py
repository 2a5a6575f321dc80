"""Triangle meshes: nominal meshes read, checked and repaired; map grids written as meshes.

Reading (STL, OBJ, OFF, PLY, 3MF) goes through pymeshlab — the one library here that reads all
five (open3d reads no 3MF, nor the OFF variants MeshLab writes) and keeps float64 vertices — except
where open3d was measured faster, and ASCII STL, parsed here (pymeshlab stores its text in float32). Figures from benchmarks/bench_mesh.py on a 10⁶-face mesh (table in
benchmarks/README.md; this 2-core machine is shared, so ±20 %): a binary PLY reads in 0.13 s through
open3d against 0.21 s through pymeshlab (the same float64 numbers), so PLY goes to open3d first
(pymeshlab when open3d finds no triangle). An STL lists its vertices once per face: pymeshlab's own
unification on reading takes 2.4 s; reading without it and merging exactly coincident vertices in
numpy 1.0 s (open3d + the same merge: 2.1 s). OBJ: pymeshlab 0.9 s, open3d 1.1 s.

Checks (:func:`check_mesh`) are numpy edge counting over the mesh with exactly coincident vertices
merged: 0.4 s for all six below on 10⁶ faces (the register step's previous edge counting took 3.3 s
for two of them), where pymeshlab's get_topological_measures takes 0.7 s for three (non-manifold
edges and vertices, boundary loops; no orientation, duplicates or zero-area faces) and open3d's
manifold and orientability tests 9.6 s. What counts as a problem:

* duplicated vertices — two vertex records at exactly the same coordinates (an indexed mesh whose
  faces do not share them has cracks); an STL lists every vertex per face, that is its format, and
  its copies are unified on reading, not reported;
* degenerate faces — a face using one vertex twice or of zero area;
* non-manifold edges — shared by three faces or more;
* non-manifold vertices — where two fans of faces meet at one vertex only (a "bow tie");
* inconsistent orientation — an edge whose two faces run it the same way (a face flipped against
  its neighbours: in a height field, a fold);
* holes — a nominal optical surface is an open sheet whose one boundary is its outline, a closed
  solid has none: boundary loops besides one (per connected piece of the mesh) are holes.

Repair (:func:`repair_mesh`, only when asked) is pymeshlab's, in this order: merge duplicated
vertices, remove duplicated and zero-area faces, remove the faces that make edges non-manifold (our
own choice of which: on each such edge the two faces that continue each other most smoothly stay),
split non-manifold vertices, re-orient faces coherently, close every hole except the outline (each
piece's boundary loop of largest extent), remove unreferenced vertices. The mesh is checked again after;
what was done is returned to be reported.

Writing (:func:`write_mesh`): binary PLY (float64 vertices), binary STL (float32, the format's
only precision) and OBJ (shortest round-trip decimals), in plain numpy: 10⁶ faces in 0.02 s (PLY)
and 0.16 s (STL), where pymeshlab's save takes 0.33 s and 0.38 s and open3d's 0.51 s and 0.54 s; OBJ
is text-bound either way (2.1 s; pymeshlab 1.7 s but 2.3× the size, with normals and 6 decimals).
:func:`grid_mesh` triangulates a map grid over its valid nodes: two triangles per cell whose four
nodes are valid, normals towards +z.
Units: mm, as everywhere in PointsPro (STL and OBJ carry no unit; the PLY says so in a comment).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

MESH_SUFFIXES = (".stl", ".obj", ".off", ".ply", ".3mf")
WRITE_MESH_SUFFIXES = (".ply", ".stl", ".obj")


# -- reading ------------------------------------------------------------------------------------------
def read_mesh(path, *, reader: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) float64 and triangles (m, 3) int64 of a mesh file. ``reader``: "auto" (by the
    benchmark: open3d for PLY, pymeshlab otherwise), "pymeshlab" or "open3d" (tests). An STL's
    per-face vertex copies are unified (exactly equal coordinates)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: mesh file not found")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise InputError(f"{path}: not a mesh file this reads ({', '.join(MESH_SUFFIXES)})")
    if reader == "auto":
        reader = "open3d" if suffix == ".ply" and _has_open3d() else "pymeshlab"
    parsed = _read_ascii_stl(path) if suffix == ".stl" and _is_ascii_stl(path) else None
    if parsed is not None:
        V, F = parsed
    elif reader == "open3d":
        V, F = _read_open3d(path)
        if len(F) == 0 and suffix == ".ply":  # a PLY layout open3d does not take: ask pymeshlab
            V, F = _read_pymeshlab(path)
    else:
        V, F = _read_pymeshlab(path)
    if suffix == ".stl":  # one vertex record per face corner: unify them (exactly equal ones)
        V, F = merge_duplicate_vertices(V, F)
    if suffix == ".3mf":
        scale = _3mf_unit_to_mm(path)
        if scale != 1.0:
            V = V * scale
    if len(V) >= 3 and not np.ptp(V, axis=0).any():
        # MeshLab reads a coordinate it cannot parse as 0 (`v np.float64(-20.0) …`): every vertex at one
        # point was "6560 duplicated vertices, 12800 degenerate faces" (a review)
        raise InputError(f"{path}: cannot read the mesh: all {len(V):,} vertices are at one point "
                         f"({V[0, 0]:g}, {V[0, 1]:g}, {V[0, 2]:g}) — its coordinates are not numbers the "
                         "reader takes?")
    return V, F


#: 3MF's units (3MF Core Specification §3.3, the model's ``unit`` attribute; millimetre by default)
_3MF_UNITS = {"micron": 1e-3, "millimeter": 1.0, "centimeter": 10.0, "inch": 25.4, "foot": 304.8,
              "meter": 1000.0}


def _3mf_unit_to_mm(path: Path) -> float:
    """mm per unit of a 3MF's model, which states its unit (pymeshlab reads the numbers as they are: a
    model in metres or inches was taken as mm — a review)."""
    import re
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            name = next((n for n in z.namelist() if n.lower().endswith(".model")), None)
            head = z.open(name).read(8192).decode("utf-8", "replace") if name else ""
    except (OSError, zipfile.BadZipFile, KeyError):
        return 1.0  # pymeshlab read it; its unit is the default
    m = re.search(r"<(?:\w+:)?model\b[^>]*?\sunit\s*=\s*[\"']([^\"']+)[\"']", head)
    if not m:
        return 1.0
    unit = m.group(1).strip().lower()
    if unit not in _3MF_UNITS:
        raise InputError(f"{path}: the 3MF model's unit {m.group(1)!r} is none of the standard's "
                         f"({', '.join(_3MF_UNITS)})")
    return _3MF_UNITS[unit]


def _is_ascii_stl(path: Path) -> bool:
    """An STL in text: it starts with ``solid`` (any case), its head holds no NUL byte, and its size
    is not the binary layout's (84 bytes and 50 a face, the count at byte 80 — a binary STL may
    begin its header with "solid" too)."""
    with open(path, "rb") as f:
        head = f.read(1024)
    if not head.lstrip(b"\xef\xbb\xbf \t\r\n").lower().startswith(b"solid") or b"\0" in head:
        return False
    size = path.stat().st_size
    return not (len(head) >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little"))


def _read_ascii_stl(path: Path):
    """An ASCII STL's ``vertex x y z`` records in float64, three a facet (pymeshlab's reader stores
    them in float32: a vertex near 500 mm written with 12 digits came back 19 nm off, and a part
    placed at (800, 600, 300) mm got 6–15 nm of residual error from its nominal alone — a review).
    None when the text holds no facet this parse reads (pymeshlab then reads the file as before)."""
    import re

    text = path.read_bytes().decode("latin-1")
    num = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
    found = re.findall(rf"(?im)^\s*vertex\s+{num}\s+{num}\s+{num}\s*$", text)
    records = len(re.findall(r"(?im)^\s*vertex\b", text))  # a vertex line at its start (not the solid's name)
    if not found:  # a whole STL on one line, or other line breaks: the records wherever they stand
        found = re.findall(rf"(?i)\bvertex\s+{num}\s+{num}\s+{num}(?![\w.])", text)
        records = len(found)
    if not found:
        return None
    if len(found) != records or len(found) % 3:
        what = (f"{records - len(found)} vertex record(s) are not three numbers" if len(found) != records
                else f"{len(found)} vertex records, not three a facet")
        raise InputError(f"{path}: cannot read the mesh: an ASCII STL whose {what} (damaged or truncated?)")
    V = np.array(found, dtype=np.float64)
    return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)


def _has_open3d() -> bool:
    import importlib.util

    return importlib.util.find_spec("open3d") is not None


def _read_pymeshlab(path: Path):
    import pymeshlab  # lazy: heavy

    ms = pymeshlab.MeshSet()
    kw = {"unify_vertices": False} if path.suffix.lower() == ".stl" else {}  # numpy merges faster
    import os

    cwd = os.getcwd()
    try:
        ms.load_new_mesh(str(path.resolve()), **kw)
    except pymeshlab.PyMeshLabException as e:
        # MeshLab's loader leaves the process in the file's folder when it fails: every relative
        # path after it (the next input of a batch) was read from there
        os.chdir(cwd)
        if path.stat().st_size == 0:
            raise InputError(f"{path}: the mesh file is empty") from None
        why = str(e).strip().splitlines()[0]
        if why.startswith("Unable to open file"):  # what it says of a file it opened but could not parse
            why = "the file is damaged or truncated, or not in the format its name says"
        raise InputError(f"{path}: cannot read the mesh: {why}") from None
    m = ms.current_mesh()
    V = np.ascontiguousarray(m.vertex_matrix(), dtype=np.float64)
    F = np.ascontiguousarray(m.face_matrix(), dtype=np.int64) if m.face_number() else \
        np.zeros((0, 3), np.int64)
    return V, F


def _read_open3d(path: Path):
    import open3d as o3d  # lazy: heavy

    # its warnings ("Read PLY failed", "appears to be a geometry::PointCloud") went to stdout under
    # --quiet (a review); a file it cannot read comes back empty and pymeshlab's error is the message
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        m = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.triangles, dtype=np.int64)


def merge_duplicate_vertices(vertices, faces):
    """Vertices at exactly equal coordinates merged (first record kept, order kept)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    rep = _coincident(V)
    keep = rep == np.arange(len(V))
    new = np.cumsum(keep) - 1
    return V[keep], new[rep][F]


def _coincident(V: np.ndarray) -> np.ndarray:
    """For each vertex, the index of the first vertex at exactly the same coordinates."""
    n = len(V)
    if n == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort((V[:, 2], V[:, 1], V[:, 0]))
    s = V[order]
    start = np.empty(n, bool)
    start[0] = True
    np.any(s[1:] != s[:-1], axis=1, out=start[1:])
    group = np.cumsum(start) - 1
    first = np.minimum.reduceat(order, np.flatnonzero(start))  # lowest index in each group
    rep = np.empty(n, np.int64)
    rep[order] = first[group]
    return rep


# -- checks -------------------------------------------------------------------------------------------
def _plural(n: int, one: str, many: str | None = None) -> str:
    return f"{n} {one if n == 1 else (many or one + 's')}"


@dataclass
class MeshCheck:
    """Counts of what makes a mesh unusable as a nominal (all zero: a good mesh)."""

    vertices: int = 0
    faces: int = 0
    duplicated_vertices: int = 0
    degenerate_faces: int = 0
    non_manifold_edges: int = 0
    non_manifold_vertices: int = 0
    inconsistent_edges: int = 0
    boundary_loops: int = 0
    holes: int = 0

    def problems(self) -> list[str]:
        if self.faces == 0:
            return ["it has no faces"]
        p = []
        if self.non_manifold_edges:
            p.append(_plural(self.non_manifold_edges, "non-manifold edge")
                     + " (three or more faces on one edge)")
        if self.non_manifold_vertices:
            p.append(_plural(self.non_manifold_vertices, "non-manifold vertex", "non-manifold vertices")
                     + " (separate fans of faces meeting at a vertex)")
        if self.holes:
            p.append(_plural(self.holes, "hole") + " (boundary loops besides the outline)")
        if self.duplicated_vertices:
            p.append(_plural(self.duplicated_vertices, "duplicated vertex", "duplicated vertices")
                     + " (same coordinates, not shared by the faces)")
        if self.degenerate_faces:
            p.append(_plural(self.degenerate_faces, "degenerate face") + " (zero area)")
        if self.inconsistent_edges:
            p.append(_plural(self.inconsistent_edges, "edge") + " with inconsistent orientation "
                     "(a face flipped against its neighbour)")
        return p

    def as_dict(self) -> dict:
        return asdict(self)


def _edge_groups(F: np.ndarray, nv: int):
    """The half-edges grouped by edge: (s, t, order, starts, count) — half-edge h = 3f + k runs from
    s[h] (corner k of face f) to t[h] (corner k + 1); order[starts[i] : starts[i] + count[i]] are the
    half-edges of the i-th edge (a boundary edge has one, an interior one two, a non-manifold one
    more)."""
    s = F.ravel()
    t = F[:, [1, 2, 0]].ravel()
    key = np.minimum(s, t) * nv + np.maximum(s, t)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.empty(len(ks), bool)
    first[0] = True
    np.not_equal(ks[1:], ks[:-1], out=first[1:])
    starts = np.flatnonzero(first)
    return s, t, order, starts, np.diff(np.append(starts, len(ks)))


def check_mesh(vertices, faces, *, merge: bool = True) -> MeshCheck:
    """Count the mesh's problems (module docstring). ``merge``: topology with coincident vertices
    merged (their count is reported as duplicated vertices; the other counts are then those of the
    mesh the faces describe)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if F.ndim != 2 or F.shape[1:] != (3,) or len(F) == 0:
        return MeshCheck(vertices=len(V), faces=0)
    if V.ndim != 2 or V.shape[1:] != (3,) or F.min() < 0 or F.max() >= len(V):
        raise InputError("a face refers to a vertex that is not in the mesh")
    out = MeshCheck(vertices=len(V), faces=len(F))
    nv = len(V)
    used = np.zeros(nv, bool)
    used[F.ravel()] = True
    rep = _coincident(V)
    out.duplicated_vertices = int(used.sum() - np.count_nonzero(np.bincount(rep[used], minlength=nv)))
    if merge:
        F = rep[F]
    # degenerate: one vertex twice, or zero area (exactly, as pymeshlab's null faces)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(b - a, c - a)
    deg = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0]) | ~np.any(cross != 0, axis=1)
    out.degenerate_faces = int(deg.sum())
    F = F[~deg]
    m = len(F)
    if m == 0:
        return out
    s, t, order, starts, count = _edge_groups(F, nv)
    out.non_manifold_edges = int((count > 2).sum())
    # orientation: the two half-edges of an interior edge run it in opposite directions
    two = starts[count == 2]
    h1, h2 = order[two], order[two + 1]
    same = s[h1] == s[h2]
    out.inconsistent_edges = int(same.sum())
    # boundary loops: connected components of the boundary edges; holes: the loops of each
    # connected piece of the mesh besides one (its outline)
    bh = order[starts[count == 1]]
    if len(bh):
        loop, piece = _boundary_loops(s, t, bh, order[starts], nv)
        out.boundary_loops = len(loop)
        out.holes = int(len(loop) - len(np.unique(piece)))
    out.non_manifold_vertices = _non_manifold_vertices(s, h1, h2, same, nv, m)
    return out


def _boundary_loops(s, t, bh, eh, nv):
    """Boundary loops (components of the boundary half-edges ``bh``) and, for each loop, the
    connected piece of the mesh it bounds (components over all edges ``eh``). Returns
    (label of each loop's component in the boundary graph, piece of each loop)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(len(bh), np.int8), (s[bh], t[bh])), shape=(nv, nv))
    _, lab = connected_components(g, directed=False)
    g = coo_matrix((np.ones(len(eh), np.int8), (s[eh], t[eh])), shape=(nv, nv))
    _, piece = connected_components(g, directed=False)
    loops, at = np.unique(lab[s[bh]], return_index=True)
    return loops, piece[s[bh][at]]


def _non_manifold_vertices(s, h1, h2, same, nv, m) -> int:
    """Vertices around which the faces form more than one fan (faces joined across interior,
    two-face edges). Nodes are face corners 3f + k; a half-edge h starts at corner h and ends at
    corner next(h)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    def nxt(h):
        return h - h % 3 + (h % 3 + 1) % 3

    # corners of the edge's first vertex in both faces, then of its second vertex
    u1, v1 = h1, nxt(h1)
    u2 = np.where(same, h2, nxt(h2))
    v2 = np.where(same, nxt(h2), h2)
    rows = np.concatenate([u1, v1])
    cols = np.concatenate([u2, v2])
    n = 3 * m
    g = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(n, n))
    nfans, lab = connected_components(g, directed=False)
    # a component only joins corners of one vertex: fans per vertex = components per vertex
    owner = np.empty(nfans, np.int64)
    owner[lab] = s
    fans = np.bincount(owner, minlength=nv)
    return int((fans > 1).sum())


# -- repair -------------------------------------------------------------------------------------------
@dataclass
class MeshRepair:
    before: MeshCheck
    after: MeshCheck
    done: list[str] = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"repaired": list(self.done), "before": self.before.as_dict(), "after": self.after.as_dict()}


def repair_mesh(vertices, faces, before: MeshCheck | None = None):
    """Repair with pymeshlab (module docstring). Returns (vertices, faces, MeshRepair); raises
    InputError when a problem is left after the repair (or the mesh has no faces)."""
    import pymeshlab  # lazy: heavy

    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    before = before or check_mesh(V, F)
    if before.faces == 0:
        raise InputError("it has no faces: nothing to repair")
    done: list[str] = []
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))

    def nf():
        return ms.current_mesh().face_number()

    if before.duplicated_vertices:
        ms.meshing_remove_duplicate_vertices()
        n = before.duplicated_vertices
        done.append(f"merged {_plural(n, 'duplicated vertex', 'duplicated vertices')}")
    n0 = nf()
    ms.meshing_remove_duplicate_faces()
    ms.meshing_remove_null_faces()
    if n0 - nf():
        done.append(f"removed {_plural(n0 - nf(), 'degenerate or duplicated face')}")
    if before.non_manifold_edges:
        m = ms.current_mesh()
        Vc, Fc = m.vertex_matrix(), m.face_matrix().astype(np.int64)
        off = _faces_off_the_sheet(Vc, Fc)
        ms.clear()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=Vc, face_matrix=Fc[~off].astype(np.int32)))
        done.append(f"removed {_plural(int(off.sum()), 'face')} on "
                    f"{_plural(before.non_manifold_edges, 'non-manifold edge')}")
    mid = _check_ms(ms)
    if mid.non_manifold_vertices:
        ms.meshing_repair_non_manifold_vertices()
        n = mid.non_manifold_vertices
        done.append(f"split {_plural(n, 'non-manifold vertex', 'non-manifold vertices')}")
    mid = _check_ms(ms, merge=False)
    if mid.inconsistent_edges:
        ms.meshing_re_orient_faces_coherently()
        done.append("re-oriented the faces coherently (inconsistent on "
                    f"{_plural(mid.inconsistent_edges, 'edge')})")
    mid = _check_ms(ms, merge=False)
    if mid.holes:
        n0 = nf()
        _close_holes(ms)
        done.append(f"closed {_plural(mid.holes, 'hole')} with {_plural(nf() - n0, 'new face')}")
    ms.meshing_remove_unreferenced_vertices()
    m = ms.current_mesh()
    V2 = np.ascontiguousarray(m.vertex_matrix(), dtype=np.float64)
    F2 = np.ascontiguousarray(m.face_matrix(), dtype=np.int64)
    # split vertices keep their coordinates on purpose: check the topology as repaired
    after = check_mesh(V2, F2, merge=False)
    left = [p for p in after.problems() if "duplicated" not in p]
    if left:
        raise InputError(f"could not repair it: {', '.join(left)} remain after {'; '.join(done) or 'repair'}")
    return V2, F2, MeshRepair(before, after, done)


def _faces_off_the_sheet(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The faces to remove on non-manifold edges (three faces or more on one edge): on each such edge
    the two faces that continue each other most smoothly (normals most nearly parallel, either
    orientation) stay, the others go. pymeshlab's "Remove Faces" kept a stray fin on a sheet's edge
    and removed a face of the sheet, whose hole was then closed into a tent 1 mm high — 117 µm of
    false residual, repaired without a word (a review)."""
    _, _, order, starts, counts = _edge_groups(F, len(V))
    face = order // 3  # the face of each half-edge, in edge order
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    off = np.zeros(len(F), bool)
    for s0, c in zip(starts[counts > 2], counts[counts > 2]):
        fs = face[s0:s0 + c]
        dots = np.abs(n[fs] @ n[fs].T)
        np.fill_diagonal(dots, -1.0)
        i, j = np.unravel_index(int(np.argmax(dots)), dots.shape)
        off[np.delete(fs, [i, j])] = True
    return off


def _check_ms(ms, merge: bool = True) -> MeshCheck:
    m = ms.current_mesh()
    return check_mesh(m.vertex_matrix(), m.face_matrix(), merge=merge)


def _close_holes(ms) -> None:
    """Close every boundary loop except each piece's outline (its loop of largest extent): the
    faces on the other loops are selected (through a per-face scalar) and pymeshlab closes the
    holes that touch the selection."""
    import pymeshlab
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = ms.current_mesh()
    V = m.vertex_matrix()
    F = m.face_matrix().astype(np.int64)
    nv = len(V)
    s, t = F.ravel(), F[:, [1, 2, 0]].ravel()
    key = np.minimum(s, t) * nv + np.maximum(s, t)
    _, first, inv, cnt = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    bh = np.flatnonzero(cnt[inv] == 1)
    g = coo_matrix((np.ones(len(bh), np.int8), (s[bh], t[bh])), shape=(nv, nv))
    _, lab = connected_components(g, directed=False)
    g = coo_matrix((np.ones(len(first), np.int8), (s[first], t[first])), shape=(nv, nv))
    _, piece = connected_components(g, directed=False)
    loop = lab[s[bh]]
    hole_faces = []
    for P in np.unique(piece[s[bh]]):
        mine = piece[s[bh]] == P
        loops = np.unique(loop[mine])
        ext = [np.linalg.norm(np.ptp(V[s[bh][loop == L]], axis=0)) for L in loops]
        outline = loops[int(np.argmax(ext))]
        hole_faces.append(bh[mine & (loop != outline)] // 3)
    q = np.zeros(len(F))
    q[np.concatenate(hole_faces)] = 1.0
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32), f_scalar_array=q))
    ms.compute_selection_by_scalar_per_face(minq=0.5, maxq=1.5)
    ms.meshing_close_holes(maxholesize=int(len(bh)) + 1, selected=True, newfaceselected=False,
                           selfintersection=False)
    ms.meshing_remove_null_faces()  # collinear boundary vertices make zero-area ears


def load_mesh(path, *, repair: bool = False, what: str = "nominal mesh"):
    """Read and check a mesh file. Problems: refused by name (one line: the file, each problem with
    its count and the fix) unless ``repair``; then repaired. Returns (vertices, faces, info) with
    info = {"check": counts as read, "repaired": [what was done]} ("repaired" only when it was)."""
    path = Path(path)
    V, F = read_mesh(path)
    if len(F) == 0:
        raise InputError(f"{path}: unusable {what}: it has no faces (no triangles read — is it an "
                         "STL/OBJ/OFF/PLY/3MF triangle mesh?)")
    chk = check_mesh(V, F)
    info: dict = {"check": chk.as_dict()}
    probs = chk.problems()
    if probs and not repair:
        raise InputError(f"{path}: unusable {what}: {', '.join(probs)} — fix the mesh or set repair: true")
    if probs:
        try:
            V, F, rep = repair_mesh(V, F, chk)
        except InputError as e:
            raise InputError(f"{path}: unusable {what}: {e}") from None
        info["repaired"] = rep.done
    return V, F, info


# -- map grids as meshes ----------------------------------------------------------------------------
def grid_mesh(xs, ys, z) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a grid (z: (len(ys), len(xs)), NaN = no node) over its valid nodes: vertices
    (x, y, z) y-major, two triangles per cell whose four nodes are valid, counter-clockwise seen
    from +z."""
    xs = np.asarray(xs, dtype=np.float64)
    ys = np.asarray(ys, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    ok = np.isfinite(z)
    idx = np.full(z.shape, -1, np.int64)
    idx[ok] = np.arange(int(ok.sum()))
    iy, ix = np.nonzero(ok)
    V = np.column_stack([xs[ix], ys[iy], z[ok]])
    cell = ok[:-1, :-1] & ok[:-1, 1:] & ok[1:, :-1] & ok[1:, 1:]
    a = idx[:-1, :-1][cell]
    b = idx[:-1, 1:][cell]
    c = idx[1:, :-1][cell]
    d = idx[1:, 1:][cell]
    F = np.empty((2 * len(a), 3), np.int64)
    F[0::2] = np.column_stack([a, b, d])
    F[1::2] = np.column_stack([a, d, c])
    return V, F


def write_mesh(path, vertices, faces, fmt: str | None = None) -> None:
    """Write a triangle mesh (mm): ``fmt`` "ply" (binary, float64), "stl" (binary, float32) or
    "obj" (text); default: by the path's suffix."""
    path = Path(path)
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if fmt == "ply":
        _write_ply(path, V, F)
    elif fmt == "stl":
        _write_stl(path, V, F)
    elif fmt == "obj":
        _write_obj(path, V, F)
    else:
        raise InputError(f"{path}: a mesh is written as {', '.join(WRITE_MESH_SUFFIXES)}")


def _write_ply(path, V, F) -> None:
    head = ("ply\nformat binary_little_endian 1.0\ncomment PointsPro mesh, units mm\n"
            f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
            f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
    rec = np.empty(len(F), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rec["n"] = 3
    rec["i"] = F
    with open(path, "wb") as f:
        f.write(head.encode("ascii"))
        f.write(np.ascontiguousarray(V, dtype="<f8").tobytes())
        f.write(rec.tobytes())


def _write_stl(path, V, F) -> None:
    """Binary STL (float32, as the format stores), in blocks of 65,536 faces so the corners, the
    normals and the records stay in cache (2·10⁶ faces: 0.9 s whole → 0.3 s, the same bytes)."""
    block = 1 << 16
    rec = np.zeros(min(len(F), block), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    with open(path, "wb") as f:
        f.write(b"PointsPro mesh, units mm".ljust(80, b" "))
        f.write(np.uint32(len(F)).tobytes())
        for start in range(0, len(F), block):
            Fb = F[start:start + block]
            r = rec[:len(Fb)]
            a, b, c = V[Fb[:, 0]], V[Fb[:, 1]], V[Fb[:, 2]]
            n = np.cross(b - a, c - a)
            ln = np.sqrt(np.einsum("ij,ij->i", n, n))
            n = np.divide(n, ln[:, None], out=np.zeros_like(n), where=ln[:, None] > 0)
            r["n"] = n
            r["v"][:, 0], r["v"][:, 1], r["v"][:, 2] = a, b, c
            f.write(r.tobytes())


def _write_obj(path, V, F) -> None:
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write("# PointsPro mesh, units mm\n")
        for start in range(0, len(V), 100_000):
            f.writelines(f"v {a!r} {b!r} {c!r}\n" for a, b, c in V[start:start + 100_000].tolist())
        for start in range(0, len(F), 100_000):
            f.writelines(f"f {a} {b} {c}\n" for a, b, c in (F[start:start + 100_000] + 1).tolist())


class MeshArtifact:
    """A triangle mesh waiting to be written (a step's artifact): ``art(path)`` writes it in
    ``fmt``, ``art(path, "stl")`` in another format (the window exports to a temporary name)."""

    def __init__(self, vertices, faces, fmt: str = "ply"):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.fmt = fmt

    def __call__(self, path, fmt: str | None = None) -> None:
        write_mesh(path, self.vertices, self.faces, fmt or self.fmt)


def map_mesh_of(artifacts: dict) -> MeshArtifact | None:
    """The mesh of a run's `bspline_map` map: its ``map_mesh.*`` artifact when the step wrote one
    (with the recipe's choice of z), else the error map triangulated from the grid behind its
    ``map.csv`` (a bound MapGrid.write_csv); None when the run made no map."""
    for name, art in artifacts.items():
        if name.startswith("map_mesh.") and isinstance(art, MeshArtifact):
            return art
    grid = getattr(artifacts.get("map.csv"), "__self__", None)
    if grid is None or not all(hasattr(grid, a) for a in ("xs", "ys", "z")):
        return None
    return MeshArtifact(*grid_mesh(grid.xs, grid.ys, grid.z))
