"""z-scale calibration (seed 000 §2.6): a simulated four-step artefact with amplification 0.9754 and
0.1 µm non-linearity is recovered to 1e-4 and 20 nm."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import StepError
from pointspro.core.step import Context
from pointspro.plugins.z_scale import ZScaleStep

HEIGHTS_UM = np.array([0.2, 2.0, 5.0, 11.0])
AMP = 0.9754


def artefact(tmp_path, repeats=5, noise_um=0.002, seed=0):
    """Staircase of the four steps (rises every 2 mm), tilted 1e-4 rad, heights as the axis reads them:
    m·h + δ(h) with δ orthogonal to (1, h) and max |δ| = 0.1 µm (so the true linearity is 0.1 µm)."""
    h = HEIGHTS_UM
    A = np.column_stack([np.ones(4), h])
    v = np.array([1.0, -2.0, 1.5, -0.4])
    d = v - A @ np.linalg.lstsq(A, v, rcond=None)[0]
    d *= 0.1 / np.abs(d).max()
    seen = AMP * h + d                                     # µm
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, 10.0, 0.001)                        # mm, 1 µm sampling
    rows = []
    for s in range(repeats):
        z = 1e-4 * x + 0.5e-3 * s
        for k, e in enumerate([2.0, 4.0, 6.0, 8.0]):
            z = z + (x > e) * seen[k] * 1e-3
        z = z + rng.normal(0, noise_um * 1e-3, x.size)
        rows.append(np.column_stack([x, z, np.full(x.size, s)]))
    np.savetxt(tmp_path / "steps.csv", np.vstack(rows), delimiter=",", header="x,z,scan", comments="",
               fmt="%.10g")
    return seen


def test_amplification_and_linearity_recovered(tmp_path):
    seen = artefact(tmp_path)
    cloud = PointCloud.from_xyz(np.zeros(3), np.zeros(3), np.array([0.0, 0.01, 0.02]), residual=np.array([0, 1e-3, 2e-3]))
    res = ZScaleStep().run(cloud, ZScaleStep.Params(calibration="steps.csv", heights=HEIGHTS_UM.tolist()),
                           Context(base_dir=tmp_path))
    rep = res.report
    assert rep["amplification"] == pytest.approx(AMP, abs=1e-4)
    assert rep["linearity_um"] == pytest.approx(0.1, abs=0.02)
    assert np.allclose(rep["measured_um"], seen, atol=0.01)
    assert all(r < 0.01 for r in rep["repeatability_um"])
    # heights about the mean are divided by the amplification
    assert np.allclose(np.diff(res.cloud.z), np.diff(cloud.z) / rep["amplification"])
    assert np.allclose(np.diff(res.cloud["residual"]), 1e-3 / rep["amplification"])
    assert "z_scale.json" in res.artifacts


def test_bad_calibrations(tmp_path):
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="heights go with a calibration file"):
        ZScaleStep.Params(amplification=1.02, heights=[2.0, 5.0])
    assert ZScaleStep.Params(amplification=1.02).heights == []
    with pytest.raises(ValidationError, match="exactly one of calibration and amplification"):
        ZScaleStep.Params()
    with pytest.raises(ValidationError, match="at least two calibrated heights"):
        ZScaleStep.Params(calibration="x.csv", heights=[1.0])
    x = np.arange(0.0, 10.0, 0.001)
    np.savetxt(tmp_path / "flat.csv", np.column_stack([x, 1e-6 * np.sin(x * 50)]), delimiter=",",
               header="x,z", comments="")
    cloud = PointCloud.from_xyz(np.zeros(3), np.zeros(3), np.zeros(3))
    with pytest.raises(StepError, match="found 0 step"):
        ZScaleStep().run(cloud, ZScaleStep.Params(calibration="flat.csv", heights=[0.2, 2.0]),
                         Context(base_dir=tmp_path))


@pytest.mark.parametrize("heights, pattern", [
    ([200.0, 2000.0, 5000.0, 11000.0], r"amplification 0\.0009754, outside 0\.5…2"),   # nm taken for µm
    ([11.0, 5.0, 2.0, 0.2], r"amplification -0\.\d+, outside 0\.5…2"),                # reversed
    ([2.0, 5.0, 11.0], r"found more than 3 steps where 3 calibrated heights were given"),
])
def test_calibrations_a_review_found_accepted(tmp_path, heights, pattern):
    """Heights in the wrong unit or order gave amplifications of 975 or −0.85, three heights for a
    four-step artefact were matched to its three tallest steps — all with exit 0 (a review)."""
    artefact(tmp_path)
    cloud = PointCloud.from_xyz(np.zeros(3), np.zeros(3), np.zeros(3))
    with pytest.raises(StepError, match=pattern):
        ZScaleStep().run(cloud, ZScaleStep.Params(calibration="steps.csv", heights=heights),
                         Context(base_dir=tmp_path))


def test_after_the_pose_of_a_curved_part_is_refused():
    """In the part frame a curved part's heights are its sag: scaled about their mean they no longer
    match the residual (a review: z − sag − residual 7 µm PV). Heights of a flat or a map still scale."""
    from pointspro.core.surfaces import surface_from_spec

    cloud = PointCloud.from_xyz(np.zeros(3), np.zeros(3), np.array([0.0, 0.01, 0.02]), residual=np.zeros(3))
    sphere = surface_from_spec({"type": "even_asphere", "c": 0.01, "k": 0})
    with pytest.raises(StepError, match="put it before misalignment"):
        ZScaleStep().run(cloud, ZScaleStep.Params(amplification=0.98), Context(surface=sphere))
    ZScaleStep().run(cloud, ZScaleStep.Params(amplification=0.98), Context())
