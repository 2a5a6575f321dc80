"""Findings of an out-of-sample review of the core chain (probe_radius → misalignment), each a test
that fails on the code before: a few spikes pulled the least-squares pose along the tilt/decentre
valley (the README's own example: dy 92 µm off, 44 nm of false coma), a wrong probe side on a steep
part passed silently, and a degenerate direction got a near-zero uncertainty."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import StepError
from pointspro.core.geometry import Pose
from pointspro.core.pipeline import run_pipeline
from pointspro.core.recipe import load_recipe, load_yaml, parse_recipe
from pointspro.core.step import Context
from pointspro.core.surfaces import EvenAsphere
from pointspro.plugins.misalignment import MisalignmentStep
from pointspro.plugins.probe_radius import ProbeRadiusStep

from .conftest import EXAMPLE
from .paper002 import DATA2_SURFACE, astigmatism, measured, star


def _example(**pose_params):
    from pointspro.core.io import read_cloud

    data = load_yaml((EXAMPLE / "recipe.yaml").read_text(encoding="utf-8"), "recipe")
    for st in data["steps"]:
        for sid in ("probe_radius", "misalignment"):
            if sid in st:
                st[sid] = {**st[sid], **pose_params}
    res = run_pipeline(read_cloud(EXAMPLE / "asphere_cmm.csv"), parse_recipe(data, base=EXAMPLE))
    return {s.id: s.report for s in res.steps}


def test_the_examples_spikes_no_longer_pull_the_pose_nor_make_coma():
    truth = json.loads((EXAMPLE / "truth.json").read_text(encoding="utf-8"))["pose"]
    robust, plain = _example(), _example(exclude_beyond=None)
    mis = robust["misalignment"]
    assert mis["excluded_from_pose"] == 5 and sorted(mis["excluded_from_pose_rows"]) == [447, 801, 2338, 2599, 4073]
    assert abs(mis["dy"] - truth["dy"]) < 0.02 and abs(mis["dx"] - truth["dx"]) < 0.02  # mm (u ≈ 0.009)
    assert abs(mis["alpha_deg"] - truth["alpha_deg"]) < 5e-4
    assert abs(plain["misalignment"]["dy"] - truth["dy"]) > 0.05  # least squares: 92 µm off
    coma = {c["name"]: c["coefficient_nm"] for c in robust["zernike"]["coefficients"]}
    coma_plain = {c["name"]: c["coefficient_nm"] for c in plain["zernike"]["coefficients"]}
    assert abs(coma["coma y"]) < 12 and abs(coma_plain["coma y"]) > 30  # the truth has none
    assert robust["probe_radius"]["excluded_from_pose"] == 5


@pytest.mark.parametrize("seed", range(4))
def test_spikes_leave_the_pose_where_the_clean_points_put_it(seed):
    """Star scans of paper 002's data-2 asphere with astigmatism and noise, 3–8 spikes of 10–40 µm:
    the pose with the spikes equals the pose of the same points without them (to 0.3 u)."""
    rng = np.random.default_rng(seed)
    x, y = star(1000.0, lines=12, pitch=10.0)
    pose = Pose(0.2 + 0.1 * seed, -0.1, 0.3, -0.2, 1.0)
    form = astigmatism(x, y, 1000.0, pv_um=0.8) + rng.normal(0, 1e-4, x.size)
    q = measured(DATA2_SURFACE, pose, x, y, form)
    spikes = rng.choice(x.size, rng.integers(3, 9), replace=False)
    q_spiked = q.copy()
    q_spiked[spikes, 2] += rng.choice([-1, 1], spikes.size) * rng.uniform(0.01, 0.04, spikes.size)
    ctx = Context(surface=DATA2_SURFACE)
    step = MisalignmentStep()
    clean = step.run(PointCloud(np.delete(q, spikes, 0)), step.Params(), ctx).report
    got = step.run(PointCloud(q_spiked), step.Params(), ctx).report
    assert got["excluded_from_pose"] >= spikes.size
    assert set(spikes) <= set(got["excluded_from_pose_rows"])
    for key in ("alpha_deg", "beta_deg", "dx", "dy", "dz"):
        assert abs(got[key] - clean[key]) < 0.3 * clean["uncertainty"][key], key


@pytest.mark.parametrize("seed", range(3))
def test_clean_data_and_large_form_keep_the_least_squares_pose(seed):
    """No point beyond 8 robust σ: the plain fit, exactly. A turned-down edge over 5 % of the points
    (form, not outliers): nothing left out, and a warning says why."""
    rng = np.random.default_rng(10 + seed)
    x, y = star(1000.0, lines=12, pitch=10.0)
    pose = Pose(0.2, -0.1, 0.3, -0.2, 1.0)
    q = measured(DATA2_SURFACE, pose, x, y, astigmatism(x, y, 1000.0, pv_um=0.8) + rng.normal(0, 1e-4, x.size))
    ctx = Context(surface=DATA2_SURFACE)
    step = MisalignmentStep()
    a = step.run(PointCloud(q), step.Params(), ctx)
    b = step.run(PointCloud(q), step.Params(exclude_beyond=None), ctx)
    assert a.report["excluded_from_pose"] == 0 and np.array_equal(a.cloud["residual"], b.cloud["residual"])
    r = np.hypot(x, y)
    edge = np.where(r > 450.0, -0.02 * ((r - 450.0) / 50.0) ** 2, 0.0)  # a 20 µm roll-off, 10 % of r
    q2 = measured(DATA2_SURFACE, pose, x, y, edge + rng.normal(0, 1e-4, x.size))
    out = step.run(PointCloud(q2), step.Params(), ctx).report
    assert out["excluded_from_pose"] == 0 and any("more than 2%" in w for w in out["warnings"])


def test_a_wrong_probe_side_on_a_steep_part_is_refused():
    """A paraboloid R 10 mm to 56° slope, ball 1 mm touching from +z, recipe side −1: the pose took
    most of the 2ρ offset and 219.6 µm of smooth "form error" remained, exit 0."""
    surf = EvenAsphere(1 / 10.0, -1.0, aperture=30.0)
    g = np.arange(-14.0, 14.01, 0.4)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = np.hypot(x, y) <= 14.0
    x, y = x[keep], y[keep]
    contact = np.column_stack([x, y, surf.sag(x, y)])
    centres = contact + 1.0 * surf.normal(x, y)
    centres[:, 2] += np.random.default_rng(0).normal(0, 2e-5, len(x))
    ctx = Context(surface=surf)
    step = ProbeRadiusStep()
    with pytest.raises(StepError, match=r"with side \+1 the centres fit .* better.*check `side`"):
        step.run(PointCloud(centres), step.Params(radius=1.0, side=-1), ctx)
    ok = step.run(PointCloud(centres), step.Params(radius=1.0, side=1), ctx).report
    assert ok["distance_residual_rms_um"] < 0.05 and not any("side" in w for w in ok["warnings"])


def test_a_direction_the_points_do_not_determine_gets_a_huge_uncertainty():
    """A sphere fitted with 5 DOF: tilt and decentre are the same motion. The pseudo-inverse dropped
    that direction and reported u(α) 4.6e-6° for an α 0.1° off."""
    surf = EvenAsphere(1 / 20.0, 0.0, aperture=30.0)
    rng = np.random.default_rng(1)
    t = np.linspace(0, 40 * np.pi, 6000)
    r = 13.0 * t / t[-1]
    x, y = r * np.cos(t), r * np.sin(t)
    contact = np.column_stack([x, y, surf.sag(x, y) + rng.normal(0, 5e-5, x.size)])
    centres = Pose(0.1, 0.05, 0.02, -0.03, 2.0).to_measuring(contact + 1.0 * surf.normal(x, y))
    rep = ProbeRadiusStep().run(PointCloud(centres), ProbeRadiusStep.Params(radius=1.0), Context(surface=surf)).report
    assert rep["condition_number"] > 1e6
    assert rep["uncertainty"]["alpha_deg"] > 1.0 and rep["uncertainty"]["dy"] > 0.1  # not determined
    assert any("trade off" in w for w in rep["warnings"])


def test_the_recipe_key_is_validated():
    with pytest.raises(Exception, match="exclude_beyond"):
        MisalignmentStep.Params.model_validate({"exclude_beyond": 1.0})
    recipe = load_recipe(EXAMPLE / "recipe.yaml")  # no key in the example: the default applies
    assert next(s for s in recipe.steps if s.id == "misalignment").params.exclude_beyond == 8.0
