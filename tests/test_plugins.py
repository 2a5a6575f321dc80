"""The foundation steps do what their names say, in numbers."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.geometry import Pose
from pointspro.core.pipeline import run_pipeline
from pointspro.core.recipe import parse_recipe
from pointspro.core.step import Context
from pointspro.plugins.aperture import ApertureStep, points_in_polygon
from pointspro.plugins.transform import TransformStep


def _grid():
    g = np.arange(-10.0, 10.5, 0.5)
    x, y = np.meshgrid(g, g)
    return PointCloud.from_xyz(x.ravel(), y.ravel(), np.zeros(x.size))


def _run(step, cloud, surface=None, **params):
    return step().run(cloud, step.Params.model_validate(params), Context(surface=surface))


def test_aperture_circle_annulus_polygon():
    c = _grid()
    r = np.hypot(c.x, c.y)
    res = _run(ApertureStep, c, diameter=10)
    assert res.cloud.n == int(np.sum(r <= 5)) and res.report["removed"] == c.n - res.cloud.n
    res = _run(ApertureStep, c, shape="annulus", diameter=10, inner_diameter=4)
    assert res.cloud.n == int(np.sum((r <= 5) & (r >= 2)))
    res = _run(ApertureStep, c, diameter=4, center_x=5, center_y=-5)
    assert np.all(np.hypot(res.cloud.x - 5, res.cloud.y + 5) <= 2)
    tri = [(0, 0), (8, 0), (0, 8)]
    res = _run(ApertureStep, c, shape="polygon", vertices=tri)
    inside = (c.x > 0) & (c.y > 0) & (c.x + c.y < 8)
    assert set(res.cloud.index) >= set(c.index[inside])
    assert np.all((res.cloud.x >= 0) & (res.cloud.y >= 0) & (res.cloud.x + res.cloud.y <= 8))
    assert res.report["warnings"]  # more than half removed


def test_point_in_polygon_concave():
    # an L shape
    poly = np.array([(0, 0), (4, 0), (4, 1), (1, 1), (1, 4), (0, 4)], float)
    x = np.array([0.5, 3.0, 3.0, 0.5, 2.0])
    y = np.array([0.5, 0.5, 3.0, 3.0, 2.0])
    assert points_in_polygon(x, y, poly).tolist() == [True, True, False, True, False]


def test_aperture_defaults_to_surface_aperture(asphere_002):
    c = PointCloud.from_xyz([0, 600, 660], [0, 0, 0], [0, 0, 0])
    res = _run(ApertureStep, c, surface=asphere_002)
    assert res.cloud.index.tolist() == [0, 1] and res.report["diameter"] == 1300


def test_aperture_param_rules():
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="at least 3 vertices"):
        ApertureStep.Params(shape="polygon", vertices=[(0, 0), (1, 1)])
    with pytest.raises(ValidationError, match="inner_diameter must be smaller"):
        ApertureStep.Params(shape="annulus", diameter=5, inner_diameter=6)


def test_manual_edit_removes_by_index_after_other_steps():
    c = _grid()
    r = parse_recipe({"pointspro": 1, "steps": [{"aperture": {"diameter": 10}},
                                                 {"manual_edit": {"remove": [0, 840, 841, 10**6]}}]})
    res = run_pipeline(c, r)
    assert 840 not in res.cloud.index and 841 not in res.cloud.index and 842 in res.cloud.index
    rep = res.steps[1].report
    assert rep["removed"] == 2 and rep["not_found"] == [0, 10**6] and rep["warnings"]


def test_transform_pose_round_trip_and_frame():
    rng = np.random.default_rng(2)
    part = PointCloud(rng.uniform(-100, 100, (50, 3)), meta={"frame": "part"})
    pose = {"alpha_deg": 0.17, "beta_deg": -0.01, "dx": 0.8, "dy": 4.0, "dz": 12.5}
    meas = _run(TransformStep, part, pose=pose, direction="to_measuring").cloud
    assert meas.frame == "measuring"
    assert np.allclose(meas.xyz, Pose(**pose).to_measuring(part.xyz), atol=0)
    back = _run(TransformStep, meas, pose=pose, direction="to_part").cloud
    assert back.frame == "part" and np.max(np.abs(back.xyz - part.xyz)) < 1e-12


def test_transform_matrix_and_its_checks():
    from pydantic import ValidationError

    c = _grid()
    m = [[1, 0, 0, 5], [0, 1, 0, -2], [0, 0, 1, 0.5], [0, 0, 0, 1]]
    res = _run(TransformStep, c, matrix=m)
    assert np.allclose(res.cloud.xyz, c.xyz + [5, -2, 0.5]) and not res.report["warnings"]
    scaled = _run(TransformStep, c, matrix=[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
    assert "not rigid" in scaled.report["warnings"][0]
    with pytest.raises(ValidationError, match="exactly one of pose and matrix"):
        TransformStep.Params()
    with pytest.raises(ValidationError, match="4 × 4 or 3 × 4"):
        TransformStep.Params(matrix=[[1, 0], [0, 1]])
    with pytest.raises(ValidationError, match="last row"):
        TransformStep.Params(matrix=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]])
    # singular relative to its scale (a review: |det| < 1e-12 passed a flattening matrix of scale 1e3,
    # det 1e-4 but condition number 3e13, which puts every point on a plane)
    with pytest.raises(ValidationError, match="singular .*condition number is 3e\\+13"):
        TransformStep.Params(matrix=[[1e3, 0, 0, 0], [0, 1e3, 0, 0], [1e3, 1e3, 1e-10, 0]])
    with pytest.raises(ValidationError, match="singular"):
        TransformStep.Params(matrix=[[1, 2, 3, 0], [2, 4, 6, 0], [0, 0, 1, 0]])
    tiny = _run(TransformStep, c, matrix=[[1e-3, 0, 0, 0], [0, 1e-3, 0, 0], [0, 0, 1e-3, 0]])  # µm → mm
    assert np.allclose(tiny.cloud.xyz, c.xyz * 1e-3, rtol=1e-15)
    mirror = _run(TransformStep, c, matrix=[[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 1, 0]])
    assert any("mirrors the points" in w for w in mirror.report["warnings"])


def test_runner_writes_step_artifacts(tmp_path):
    """Artifacts returned by a step land in the input's output folder."""
    from pointspro.core import batch
    from pointspro.core.registry import Registry
    from pointspro.core.step import Params as NoParams
    from pointspro.core.step import Step, StepResult

    class MapStep(Step):
        id, title, Params = "map_test", "Map test", NoParams

        def run(self, cloud, params, ctx):
            ctx.progress.check()
            return StepResult(cloud, {"n": cloud.n}, {"map.txt": "1 2\n3 4\n",
                                                      "blob.bin": b"\x00\x01",
                                                      "called.txt": lambda p: p.write_text("ok", encoding="utf-8")})

    src = tmp_path / "in.csv"
    src.write_text("1 2 3\n4 5 6\n", encoding="utf-8")
    r = parse_recipe({"pointspro": 1, "steps": ["map_test"]}, registry=Registry(extra={"m": MapStep}))
    out = batch.process_input(src, r, tmp_path, "in")
    assert out.ok
    folder = tmp_path / "in"
    assert (folder / "map.txt").read_text(encoding="utf-8") == "1 2\n3 4\n"
    assert (folder / "blob.bin").read_bytes() == b"\x00\x01" and (folder / "called.txt").read_text(encoding="utf-8") == "ok"


def test_a_polygon_aperture_keeps_the_points_on_all_its_edges_as_a_circle_keeps_its_rim():
    """Grid points on a square's, a triangle's and a rotated square's edges are kept on every side
    (the even-odd rule alone dropped those on the right and top edges: 38 of 49 on the square)."""
    g = np.arange(-5, 5.001, 1.0)
    X, Y = np.meshgrid(g, g)
    c = PointCloud.from_xyz(X.ravel(), Y.ravel(), np.zeros(X.size))
    for verts, n in (([[-3, -3], [3, -3], [3, 3], [-3, 3]], 49), ([[0, 0], [4, 0], [0, 4]], 15),
                     ([[0, -3], [3, 0], [0, 3], [-3, 0]], 25)):
        assert _run(ApertureStep, c, shape="polygon", vertices=verts).cloud.n == n
        assert points_in_polygon(c.x, c.y, np.asarray(verts, float)).sum() < n  # the lasso's open rule

