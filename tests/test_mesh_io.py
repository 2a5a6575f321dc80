"""core.io.mesh: nominal meshes in STL/OBJ/OFF/PLY/3MF read (pymeshlab; open3d for PLY), checked,
refused by name or repaired; map grids exported as meshes and read back."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import InputError, StepError
from pointspro.core.io.mesh import (
    MeshArtifact,
    check_mesh,
    grid_mesh,
    load_mesh,
    map_mesh_of,
    read_mesh,
    repair_mesh,
    write_mesh,
)
from pointspro.core.step import Context


def sheet(n=11, h=1.0, off=(0.0, 0.0), f=lambda x, y: 0.01 * x * x - 0.02 * y * y + 0.1 * x):
    """An n × n height-field sheet at spacing h (vertices y-major, normals +z)."""
    xs = off[0] + h * np.arange(n)
    ys = off[1] + h * np.arange(n)
    X, Y = np.meshgrid(xs, ys)
    return grid_mesh(xs, ys, f(X, Y))


def save_pymeshlab(path, V, F):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
    ms.save_current_mesh(str(path))


@pytest.mark.parametrize("fmt", ["stl", "obj", "off", "ply", "3mf"])
def test_each_format_loads_as_float64(tmp_path, fmt):
    V, F = sheet(off=(1000.0, -800.0))  # far from the origin: float32 would show
    save_pymeshlab(tmp_path / f"m.{fmt}", V, F)
    v, f, info = load_mesh(tmp_path / f"m.{fmt}")
    assert v.dtype == np.float64 and f.dtype == np.int64
    assert len(v) == len(V) and len(f) == len(F)
    assert info["check"]["holes"] == 0 and "repaired" not in info
    # same surface: every face's vertex set found among the originals (order may differ)
    tol = {"stl": 1e-4, "3mf": 1e-3}.get(fmt, 1e-9)  # STL is float32; MeshLab's 3MF writes 7 digits
    key = {tuple(np.round(p, 2)) for p in V}
    assert all(tuple(np.round(p, 2)) in key for p in v)
    if fmt in ("obj", "off", "ply"):
        assert np.allclose(v, V, rtol=0, atol=tol)
        assert {tuple(sorted(t)) for t in f.tolist()} == {tuple(sorted(t)) for t in F.tolist()}


def test_ply_open3d_and_pymeshlab_read_the_same_numbers(tmp_path):
    V, F = sheet(off=(123.456789012345, 0.1))
    write_mesh(tmp_path / "m.ply", V, F)
    a = read_mesh(tmp_path / "m.ply", reader="open3d")
    b = read_mesh(tmp_path / "m.ply", reader="pymeshlab")
    assert np.array_equal(a[0], V) and np.array_equal(b[0], V)
    assert np.array_equal(a[1], F) and np.array_equal(b[1], F)


def test_stl_copies_are_unified_not_reported(tmp_path):
    V, F = sheet()
    write_mesh(tmp_path / "m.stl", V, F)
    v, f, info = load_mesh(tmp_path / "m.stl")
    assert len(v) == len(V) and info["check"]["duplicated_vertices"] == 0
    assert check_mesh(v, f).problems() == []


def _ascii_stl(V, F, digits=None) -> str:
    fmt = (lambda v: repr(float(v))) if digits is None else (lambda v: f"{v:.{digits}e}")
    lines = ["solid part"]
    for t in F:
        lines += ["  facet normal 0 0 1", "    outer loop"]
        lines += [f"      vertex {fmt(V[i, 0])} {fmt(V[i, 1])} {fmt(V[i, 2])}" for i in t]
        lines += ["    endloop", "  endfacet"]
    return "\n".join(lines + ["endsolid part", ""])


def test_ascii_stl_is_read_in_float64(tmp_path):
    """pymeshlab stores an ASCII STL's vertices in float32: a vertex near 500 mm written with 12
    digits came back 19 nm off (a review). They are parsed here in float64; a binary STL whose header
    starts with "solid" is still read as binary."""
    V, F = sheet(off=(523.456789012345, -800.123456789012))
    (tmp_path / "a.stl").write_text(_ascii_stl(V, F), encoding="ascii")
    v, f = read_mesh(tmp_path / "a.stl")  # vertices unified in the order the facets name them

    def corners(V, F):
        return sorted(tuple(sorted(map(tuple, V[t].tolist()))) for t in F)
    assert len(v) == len(V) and corners(v, f) == corners(V, F)  # the very same float64 numbers
    write_mesh(tmp_path / "b.stl", V, F)
    data = bytearray((tmp_path / "b.stl").read_bytes())
    data[:5] = b"solid"
    (tmp_path / "b.stl").write_bytes(bytes(data))
    v, f = read_mesh(tmp_path / "b.stl")
    assert len(f) == len(F) and np.allclose(np.array(corners(v, f)), np.array(corners(V, F)), atol=1e-3)
    assert corners(v, f) != corners(V, F)  # float32, as the binary format stores
    # a review of the change: trailing bytes after a binary STL whose header says "solid"; an ASCII STL
    # in capitals, or named "vertex cloud" — each read as before
    (tmp_path / "b2.stl").write_bytes(bytes(data) + b"\n\n")
    assert len(read_mesh(tmp_path / "b2.stl")[1]) == len(F)
    text = _ascii_stl(V, F)
    (tmp_path / "upper.stl").write_text(text.upper(), encoding="ascii")
    assert corners(*read_mesh(tmp_path / "upper.stl")) == corners(V, F)
    (tmp_path / "named.stl").write_text(text.replace("solid part", "solid vertex cloud"), encoding="ascii")
    assert corners(*read_mesh(tmp_path / "named.stl")) == corners(V, F)
    (tmp_path / "cut.stl").write_text(text[: text.index("vertex", len(text) // 2) + 20], encoding="ascii")
    with pytest.raises(InputError, match=r"cut.stl: cannot read the mesh: .*ASCII STL"):
        read_mesh(tmp_path / "cut.stl")


def test_read_errors(tmp_path):
    with pytest.raises(InputError, match="mesh file not found"):
        read_mesh(tmp_path / "nope.obj")
    (tmp_path / "bad.obj").write_text("this is not an obj\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"bad.obj: cannot read the mesh: "):
        load_mesh(tmp_path / "bad.obj")
    V, F = sheet()
    write_mesh(tmp_path / "cut.stl", V, F)
    data = (tmp_path / "cut.stl").read_bytes()
    (tmp_path / "cut.stl").write_bytes(data[: len(data) // 2])  # truncated
    with pytest.raises(InputError, match=r"cut.stl: "):
        load_mesh(tmp_path / "cut.stl")
    write_mesh(tmp_path / "pts.ply", V, np.zeros((0, 3), int))
    with pytest.raises(InputError, match=r"pts.ply: unusable nominal mesh: it has no faces"):
        load_mesh(tmp_path / "pts.ply")
    V, F = sheet()  # coordinates MeshLab cannot parse read as 0: named, not "duplicated vertices" (a review)
    (tmp_path / "repr.obj").write_text("".join(f"v np.float64({a}) {b} {c}\n".replace(f" {b} {c}", f" np.float64({b}) np.float64({c})")
                                               for a, b, c in V.tolist()) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F.tolist()),
                                       encoding="utf-8")
    with pytest.raises(InputError, match=r"repr.obj: cannot read the mesh: all 121 vertices are at one point"):
        read_mesh(tmp_path / "repr.obj")
    (tmp_path / "m.xyz").write_text("0 0 0\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"m.xyz: not a mesh file"):
        read_mesh(tmp_path / "m.xyz")


def _without_faces_at(F, *verts):
    return F[[not (set(verts) & set(t)) for t in F.tolist()]]


def test_checks_count_each_problem():
    V, F = sheet()
    n = 11
    good = check_mesh(V, F)
    assert good.problems() == [] and good.boundary_loops == 1 and good.holes == 0
    # an open sheet's one outline is no hole; two sheets apart: one outline each
    V2, F2 = sheet(off=(20.0, 0.0))
    assert check_mesh(np.vstack([V, V2]), np.vstack([F, F2 + len(V)])).problems() == []
    # holes: the faces round two interior vertices removed
    c = check_mesh(V, _without_faces_at(F, 2 * n + 2, 7 * n + 7))
    assert c.holes == 2 and c.boundary_loops == 3
    assert c.problems() == ["2 holes (boundary loops besides the outline)"]
    # duplicated vertex used by one face: counted, and the topology is read merged (no crack)
    Vd = np.vstack([V, V[5 * n + 5]])
    Fd = F.copy()
    k = int(np.flatnonzero((Fd == 5 * n + 5).any(axis=1))[0])
    Fd[k][Fd[k] == 5 * n + 5] = len(V)
    assert check_mesh(Vd, Fd).problems() == ["1 duplicated vertex (same coordinates, not shared by the faces)"]
    # non-manifold edge: a third face on an interior diagonal
    Vn = np.vstack([V, V[4 * n + 4] + [0.1, 0, 0.1]])
    c = check_mesh(Vn, np.vstack([F, [4 * n + 4, 5 * n + 5, len(V)]]))
    assert c.non_manifold_edges == 1
    # degenerate faces: one vertex twice; three collinear vertices
    Vz = np.vstack([V, [[0.0, -5, 0], [1.0, -5, 0], [3.0, -5, 0]]])
    c = check_mesh(Vz, np.vstack([F, [0, 0, 1], [len(V), len(V) + 1, len(V) + 2]]))
    assert c.degenerate_faces == 2 and c.holes == 0
    # a flipped face: its three interior edges run the same way as the neighbours'
    Ff = F.copy()
    Ff[50] = Ff[50][[0, 2, 1]]
    assert check_mesh(V, Ff).inconsistent_edges == 3
    # bow tie: two flat sheets sharing one corner vertex
    Va, Fa = sheet(f=lambda x, y: 0 * x)
    Vb, Fb = sheet(f=lambda x, y: 0 * x, off=(10.0, 10.0))
    c = check_mesh(np.vstack([Va, Vb]), np.vstack([Fa, Fb + len(Va)]))
    assert c.non_manifold_vertices == 1 and c.duplicated_vertices == 1
    assert check_mesh(V, np.zeros((0, 3), int)).problems() == ["it has no faces"]


def test_broken_file_refused_by_name_then_repaired(tmp_path):
    V, F = sheet()
    n = 11
    Fb = _without_faces_at(F, 2 * n + 2, 7 * n + 7)
    V = np.vstack([V, [[0.0, -5, 0], [1.0, -5, 0], [3.0, -5, 0]]])
    Fb = np.vstack([Fb, [len(V) - 3, len(V) - 2, len(V) - 1]])  # and a zero-area face
    Fb[60] = Fb[60][[0, 2, 1]]                                   # and a flipped one
    path = tmp_path / "part.obj"
    write_mesh(path, V, Fb)
    with pytest.raises(InputError) as e:
        load_mesh(path)
    msg = str(e.value)
    assert msg == (f"{path}: unusable nominal mesh: 2 holes (boundary loops besides the outline), "
                   "1 degenerate face (zero area), 3 edges with inconsistent orientation (a face flipped "
                   "against its neighbour) — fix the mesh or set repair: true")
    v, f, info = load_mesh(path, repair=True)
    assert check_mesh(v, f).problems() == []
    assert info["check"]["holes"] == 2
    done = " / ".join(info["repaired"])
    assert "removed 1 degenerate or duplicated face" in done
    assert "re-oriented the faces coherently" in done and "closed 2 holes" in done
    # the outline stays open: a sheet, not a closed bag
    assert check_mesh(v, f).boundary_loops == 1
    # the repaired mesh is a usable nominal: its sag equals the sheet's at the nodes
    from pointspro.core.surfaces import MeshSurface

    surf = MeshSurface.from_file(path, repair=True)
    assert surf.describe()["repaired"] == info["repaired"]
    inner = (V[:, 0] > 0.5) & (V[:, 0] < 9.5) & (V[:, 1] > 0.5) & (V[:, 1] < 9.5)
    inner &= ~np.isin(np.arange(len(V)), [2 * n + 2, 7 * n + 7])  # the holes' centres are gone
    assert np.allclose(surf.sag(V[inner, 0], V[inner, 1]), V[inner, 2], atol=1e-12)


def test_repair_of_duplicates_non_manifold_and_bow_tie():
    V, F = sheet()
    n = 11
    Vn = np.vstack([V, V[4 * n + 4] + [0.05, 0, 0.01]])
    Fn = np.vstack([F, [4 * n + 4, 5 * n + 5, len(V)]])
    v, f, rep = repair_mesh(Vn, Fn)
    assert rep.before.non_manifold_edges == 1 and rep.after.non_manifold_edges == 0
    assert any("non-manifold edge" in d for d in rep.done)
    # the stray face goes and the sheet stays whole (pymeshlab removed a face of the sheet and closed
    # its hole into a tent up to the stray apex — a review)
    def corners(V, F):
        return {tuple(sorted(map(tuple, V[t].tolist()))) for t in F}
    edges = [tuple(sorted(e)) for t in F.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))]
    inner = [k for k in range(len(F)) if edges.count(tuple(sorted(F[k, :2]))) == 2]
    for k in inner[::9]:  # a fin 1 mm high on an inner edge of face k, diagonals and sides
        a, b = F[k, 0], F[k, 1]
        Vn = np.vstack([V, (V[a] + V[b]) / 2 + [0.0, 0.1, 1.0]])
        v, f, rep = repair_mesh(Vn, np.vstack([F, [a, b, len(V)]]))
        assert rep.done == ["removed 1 face on 1 non-manifold edge"] and corners(v, f) == corners(V, F), k
    Va, Fa = sheet(f=lambda x, y: 0 * x)
    Vb, Fb = sheet(f=lambda x, y: 0 * x, off=(10.0, 10.0))
    v, f, rep = repair_mesh(np.vstack([Va, Vb]), np.vstack([Fa, Fb + len(Va)]))
    assert rep.done == ["merged 1 duplicated vertex", "split 1 non-manifold vertex"]
    assert rep.after.non_manifold_vertices == 0 and len(f) == 2 * len(F)
    with pytest.raises(InputError, match="no faces"):
        repair_mesh(V, np.zeros((0, 3), int))


def test_grid_mesh_triangulates_valid_cells():
    xs = np.array([0.0, 1.0, 2.0, 3.0])
    ys = np.array([10.0, 11.0, 12.0])
    z = np.arange(12.0).reshape(3, 4) * 1e-3
    z[0, 0] = np.nan   # kills cell (0, 0)
    z[2, 3] = np.nan   # kills cell (1, 2)
    V, F = grid_mesh(xs, ys, z)
    assert len(V) == 10 and len(F) == 2 * 4
    assert np.array_equal(V[:, 2], z[np.isfinite(z)])
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert (n[:, 2] > 0).all()
    assert check_mesh(V, F).problems() == []


def _map_run(tmp_path, surface=None, **params):
    from pointspro.plugins.bspline_map import BSplineMapStep

    rng = np.random.default_rng(2)
    x, y = rng.uniform(-20, 20, (2, 4000))
    z = 1e-3 * np.sin(x / 6) * np.cos(y / 9)
    cloud = PointCloud.from_xyz(x, y, np.zeros_like(z), residual=z)
    p = BSplineMapStep.Params.model_validate({"spacing": 1.0, "diameter": 36.0, "centre": [0.0, 0.0],
                                              **params})
    return BSplineMapStep().run(cloud, p, Context(surface=surface))


@pytest.mark.parametrize("fmt", ["ply", "stl", "obj"])
def test_bspline_map_mesh_reads_back(tmp_path, fmt):
    res = _map_run(tmp_path, mesh=fmt)
    grid = res.artifacts["map.csv"].__self__
    name = f"map_mesh.{fmt}"
    res.artifacts[name](tmp_path / name)
    v, f = read_mesh(tmp_path / name)
    ok = np.isfinite(grid.z)
    cells = (ok[:-1, :-1] & ok[:-1, 1:] & ok[1:, :-1] & ok[1:, 1:]).sum()
    assert res.report["mesh"] == {"file": name, "z": "residual map (mm)", "vertices": int(ok.sum()),
                                  "faces": int(2 * cells)}
    assert len(f) == 2 * cells
    X, Y = np.meshgrid(grid.xs, grid.ys)
    if fmt == "stl":  # float32 by the format; nodes that no cell uses are not in an STL
        assert len(v) <= ok.sum()
        assert np.abs(v[:, 2]).max() <= np.nanmax(np.abs(grid.z)) * (1 + 1e-6)
        return
    assert len(v) == ok.sum()
    assert np.abs(v[:, 0] - X[ok]).max() <= 1e-12 and np.abs(v[:, 1] - Y[ok]).max() <= 1e-12
    assert np.abs(v[:, 2] - grid.z[ok]).max() <= 1e-12


def test_bspline_map_mesh_of_the_measured_surface(tmp_path):
    from pointspro.core.surfaces import EvenAsphere

    surf = EvenAsphere(c=1 / 200.0, k=-1.0, A={}, aperture=40.0)
    res = _map_run(tmp_path, surface=surf, mesh="ply", mesh_z="surface")
    grid = res.artifacts["map.csv"].__self__
    res.artifacts["map_mesh.ply"](tmp_path / "m.ply")
    v, f = read_mesh(tmp_path / "m.ply")
    ok = np.isfinite(grid.z)
    X, Y = np.meshgrid(grid.xs, grid.ys)
    assert np.abs(v[:, 2] - (surf.sag(X[ok], Y[ok]) + grid.z[ok])).max() <= 1e-12
    assert res.report["mesh"]["z"] == "nominal sag + residual map (mm)"
    with pytest.raises(StepError, match="mesh_z: surface needs the recipe's nominal"):
        _map_run(tmp_path, mesh="stl", mesh_z="surface")
    # default: no mesh written by the step
    assert not any(n.startswith("map_mesh") for n in _map_run(tmp_path).artifacts)


def test_map_mesh_of_a_run_for_the_window(tmp_path):
    res = _map_run(tmp_path)  # mesh: none — the window still triangulates the grid on demand
    art = map_mesh_of(res.artifacts)
    grid = res.artifacts["map.csv"].__self__
    art(tmp_path / "x.partial", "ply")  # the window writes to a temporary name, then renames
    (tmp_path / "x.partial").rename(tmp_path / "x.ply")
    v, f = read_mesh(tmp_path / "x.ply")
    assert np.array_equal(v[:, 2], grid.z[np.isfinite(grid.z)])
    res = _map_run(tmp_path, mesh="obj")
    assert map_mesh_of(res.artifacts) is res.artifacts["map_mesh.obj"]
    assert isinstance(res.artifacts["map_mesh.obj"], MeshArtifact)
    assert map_mesh_of({}) is None


def test_a_mesh_that_fails_to_read_leaves_the_working_folder_alone(tmp_path, monkeypatch):
    """MeshLab's loader left the process in the file's folder when it failed (a review): the next
    relative path of a batch was read from there. And it said "Unable to open file" of a file it
    opened."""
    import os

    V, F = sheet()
    sub = tmp_path / "sub"
    sub.mkdir()
    write_mesh(sub / "whole.ply", V, F)
    raw = (sub / "whole.ply").read_bytes()
    (sub / "cut.ply").write_bytes(raw[: len(raw) // 2])
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match=r"cut\.ply: cannot read the mesh: the file is damaged or truncated"):
        read_mesh("sub/cut.ply", reader="pymeshlab")
    assert os.getcwd() == str(tmp_path)


def test_simulate_never_writes_over_the_models_nominal_mesh(run_cli, tmp_path):
    """A review: `simulate m.yaml --out part.ply` replaced the model's nominal mesh with a point cloud."""
    V, F = sheet(n=21, off=(-10.0, -10.0), f=lambda x, y: 0.001 * (x * x + y * y))
    write_mesh(tmp_path / "part.ply", V, F)
    before = (tmp_path / "part.ply").read_bytes()
    (tmp_path / "m.yaml").write_text("pointspro_model: 1\nsurface: {type: mesh, path: part.ply}\n"
                                     "scan: {type: raster, radius: 5.0}\n", encoding="utf-8")
    code, _, err = run_cli("simulate", tmp_path / "m.yaml", "--out", tmp_path / "part.ply")
    assert code == 2 and "is the model's nominal mesh (part.ply)" in err
    assert (tmp_path / "part.ply").read_bytes() == before


@pytest.mark.parametrize("unit, mm", [("millimeter", 1.0), ("meter", 1000.0), ("inch", 25.4), ("micron", 1e-3)])
def test_a_3mf_is_read_in_its_stated_unit(tmp_path, unit, mm):
    """A 3MF states its unit on its model (millimetre by default); a model in metres or inches was read
    as mm (a review)."""
    import zipfile

    V, F = sheet(h=0.01)
    verts = "".join(f'<vertex x="{a!r}" y="{b!r}" z="{c!r}"/>' for a, b, c in V.tolist())
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in F.tolist())
    model = (f'<?xml version="1.0" encoding="UTF-8"?><model unit="{unit}" xml:lang="en-US" '
             'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02"><resources><object id="1" '
             f'type="model"><mesh><vertices>{verts}</vertices><triangles>{tris}</triangles></mesh></object>'
             '</resources><build><item objectid="1"/></build></model>')
    with zipfile.ZipFile(tmp_path / "m.3mf", "w") as z:
        z.writestr("[Content_Types].xml", '<?xml version="1.0" encoding="UTF-8"?><Types xmlns="http://schemas.'
                   'openxmlformats.org/package/2006/content-types"><Default Extension="rels" ContentType='
                   '"application/vnd.openxmlformats-package.relationships+xml"/><Default Extension="model" '
                   'ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/></Types>')
        z.writestr("_rels/.rels", '<?xml version="1.0" encoding="UTF-8"?><Relationships xmlns="http://schemas.'
                   'openxmlformats.org/package/2006/relationships"><Relationship Target="/3D/3dmodel.model" '
                   'Id="rel0" Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>')
        z.writestr("3D/3dmodel.model", model)
    v, f = read_mesh(tmp_path / "m.3mf")
    assert np.allclose(np.ptp(v, axis=0), np.ptp(V, axis=0) * mm, rtol=1e-6)
