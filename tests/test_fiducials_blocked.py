"""Issue 16 part 1: the volumetric step's u far from the balls, calibrated by the fiducials' blocked
cross-validation (spatial blocks of balls held out whole; u_k² = s_k² + τ²·d, core.calibration.gp.
distance_term). Simulated as 000 §2.4 (fiducial_sim's field and frame), fixed seeds."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.calibration import volumetric_model as vm
from pointspro.core.calibration.fiducial_sim import EXTENT, LOW, machine_frame, smooth_field
from pointspro.core.calibration.fiducials import ball_points
from pointspro.core.calibration.gp import distance_term, spatial_blocks
from pointspro.core.errors import InputError
from pointspro.core.step import Context
from pointspro.plugins.fiducials import FiducialsStep
from pointspro.plugins.volumetric import VolumetricStep


def calibrate(tmp_path, ref, seed, kind):
    """(fiducials' result, the field): 24 balls at ``ref``, a 1.3 µm smooth field, 0.2 µm noise."""
    rng = np.random.default_rng(77 + seed)
    f = smooth_field(seed, kind, 1.3, EXTENT, machine_frame(LOW))
    true_c = machine_frame(ref)
    pts, ids = ball_points(true_c - f(true_c), noise=0.2e-3, seed=seed)
    given = ref + rng.normal(0, 0.2e-3, ref.shape)
    (tmp_path / "reference.csv").write_text("fiducial,x,y,z\n" + "".join(
        f"{i + 1},{float(r[0])!r},{float(r[1])!r},{float(r[2])!r}\n" for i, r in enumerate(given)))
    res = FiducialsStep().run(PointCloud.from_xyz(*pts.T, fiducial=ids),
                              FiducialsStep.Params(reference="reference.csv", monte_carlo_runs=0),
                              Context(base_dir=tmp_path))
    return res, f


def apply(tmp_path, text, W, f):
    """(volumetric's result, |true error left| (n, 3) mm, u (n, 3) mm) on workpiece points W (reference)."""
    (tmp_path / "m.json").write_text(text)
    TW = machine_frame(W)
    out = VolumetricStep().run(PointCloud(TW - f(TW)), VolumetricStep.Params(model="m.json", frame="reference"),
                               Context(base_dir=tmp_path))
    u = np.column_stack([out.cloud[c] for c in ("u_x", "u_y", "u_z")])
    return out, np.abs(out.cloud.xyz - W), u


def two_planes(rng):
    ref = LOW + rng.uniform(0, 1, (24, 3)) * EXTENT
    ref[:, 2] = np.where(np.arange(24) % 2, 50.0, 0.0)
    return ref


def without_calibration(text: str) -> str:
    """The model file as written before the blocked cross-validation (no u_calibration), re-sealed."""
    d = json.loads(text)
    d.pop("u_calibration")
    d.pop("sha256")
    d.pop("pointspro_volumetric_model")
    return vm.dumps(d)


def test_distance_term_recovers_a_linear_excess_variance():
    rng = np.random.default_rng(0)
    d = rng.uniform(5, 60, 2000)
    s = np.full((3, d.size), 0.3e-3)
    tau2 = 4e-9  # mm²/mm: 0.2 µm at 10 mm
    r = rng.normal(0, 1, s.shape) * np.sqrt(s**2 + tau2 * d)
    assert distance_term(r, s, d) == pytest.approx(tau2, rel=0.1)
    # residuals the GP's σ covers: no term (never below the GP's own σ)
    assert distance_term(0.5 * r, s + 1e-3, d) == 0.0
    # one component whose σ the GP over-states does not cancel the others' excess (a review: a plate
    # of balls, held-out RMS / σ 1.12, 0.50, 1.29 per component, gave τ² = 0)
    s_over = s.copy()
    s_over[1] *= 4.0
    assert distance_term(r, s_over, d) == pytest.approx(2 / 3 * tau2, rel=0.15)


def test_a_plate_of_balls_keeps_the_gap_warning_honest(tmp_path):
    """24 balls on a plate (z 0–2 mm) and two at z = 50, the workpiece through the whole box: the blocks
    hold out balls beside each other on the plate, not across the 50 mm above it. u grows (τ² > 0: one
    over-stated component no longer cancels it) and the warning still says u may be too small there."""
    rng = np.random.default_rng(1)
    ref = LOW + rng.uniform(0, 1, (24, 3)) * EXTENT
    ref[:, 2] = rng.uniform(0, 2, 24)
    ref[:2, 2] = 50.0
    res, f = calibrate(tmp_path, ref, 1, "fourier")
    assert res.report["blocked_cv"]["excess_variance_um2_per_mm"] > 0
    W = ref.min(0) + rng.uniform(0, 1, (1500, 3)) * np.ptp(ref, axis=0)
    out, err, u = apply(tmp_path, res.artifacts["volumetric_model.json"], W, f)
    gap = [w for w in out.report["warnings"] if "from every ball" in w]
    assert len(gap) == 1 and "may still be too small" in gap[0], out.report["warnings"]
    # a model whose distance term is 0 says nothing of it
    d = json.loads(res.artifacts["volumetric_model.json"])
    d["u_calibration"]["excess_variance_um2_per_mm"] = 0.0
    for k in ("sha256", "pointspro_volumetric_model"):
        d.pop(k)
    out0, _, _ = apply(tmp_path, vm.dumps(d), W, f)
    gap0 = [w for w in out0.report["warnings"] if "from every ball" in w]
    assert len(gap0) == 1 and "distance term" not in gap0[0] and "u may be too small" in gap0[0]


def test_blocks_are_compact_and_leave_the_transform_determined():
    rng = np.random.default_rng(3)
    ref = two_planes(rng)
    A = np.column_stack([ref, np.ones(24)])
    blocks = spatial_blocks(ref, A)
    assert 4 <= len(blocks) <= 8 and sum(map(len, blocks)) >= 20
    assert len(np.unique(np.concatenate(blocks))) == sum(map(len, blocks))  # disjoint
    for b in blocks:  # a block is a neighbourhood: smaller than the layout
        assert np.max(np.ptp(ref[b], axis=0)[:1]) < 0.8 * EXTENT[0]


def test_two_planes_coverage_over_seeds(tmp_path):
    # the review's layout: 12 balls on z = 0, 12 on z = 50, the workpiece between. Measured here (seeds
    # 0–3): 2u held 0.84, 0.94, 0.75, 1.00 of the workpiece's per-axis errors with the GP's σ alone, 0.90,
    # 0.94, 0.78, 1.00 with the distance term (mean 0.88 → 0.90); on benchmarks/bench_fiducials.py
    # --coverage's 8 seeds 0.88 → 0.96. Where the field between the planes differs from what the balls'
    # lateral blocks show (the third seed) no cross-validation over these balls can see it
    before, after = [], []
    for seed in range(4):
        rng = np.random.default_rng(500 + seed)
        ref = two_planes(rng)
        res, f = calibrate(tmp_path, ref, seed, ("fourier", "kinematic")[seed % 2])
        b = res.report["blocked_cv"]
        assert b["blocks"] >= 4 and b["held_out"] >= 16 and b["excess_variance_um2_per_mm"] >= 0
        W = ref.min(0) + rng.uniform(0, 1, (1500, 3)) * np.ptp(ref, axis=0)
        text = res.artifacts["volumetric_model.json"]
        out, err, u = apply(tmp_path, text, W, f)
        _, err0, u0 = apply(tmp_path, without_calibration(text), W, f)
        np.testing.assert_array_equal(err, err0)  # the correction is the same; only u changes
        assert np.all(u >= u0 - 1e-12)             # never below the GP's own σ
        infl = out.report["u_inflation"]
        assert infl["ratio_max"] >= infl["ratio_median"] >= 1.0
        before.append(np.mean(err0 <= 2 * u0))
        after.append(np.mean(err <= 2 * u))
    assert np.all(np.array(after) >= np.array(before)), (before, after)
    assert np.mean(after) >= 0.89, (before, after)
    assert np.mean(after) >= np.mean(before) + 0.015, (before, after)


def test_ordinary_layout_u_does_not_blow_up(tmp_path):
    # 24 balls at random through the volume (000 §2.4): the GP's σ already covers (~0.97); the term may
    # add a little, not make u absurd (measured on 8 seeds: median u × 1.0–1.3, coverage 0.97 → 0.99)
    for seed in (0, 1):
        rng = np.random.default_rng(900 + seed)
        ref = LOW + rng.uniform(0, 1, (24, 3)) * EXTENT
        res, f = calibrate(tmp_path, ref, seed, ("fourier", "kinematic")[seed % 2])
        W = ref.min(0) + rng.uniform(0, 1, (1500, 3)) * np.ptp(ref, axis=0)
        out, err, u = apply(tmp_path, res.artifacts["volumetric_model.json"], W, f)
        assert out.report["u_inflation"]["ratio_median"] < 1.5
        assert 0.9 <= np.mean(err <= 2 * u) <= 1.0


def test_old_model_file_reads_as_before_and_a_negative_term_is_refused(tmp_path):
    rng = np.random.default_rng(501)
    ref = two_planes(rng)
    res, f = calibrate(tmp_path, ref, 1, "kinematic")
    text = res.artifacts["volumetric_model.json"]
    spec = vm.loads(text, "m.json")
    assert spec.u_calibration is not None and spec.u_calibration.blocks >= 4
    W = ref.min(0) + rng.uniform(0, 1, (200, 3)) * np.ptp(ref, axis=0)
    out, _, _ = apply(tmp_path, without_calibration(text), W, f)
    assert out.report["u_inflation"] is None
    d = json.loads(text)
    d["u_calibration"]["excess_variance_um2_per_mm"] = -1.0
    for k in ("sha256", "pointspro_volumetric_model"):
        d.pop(k)
    with pytest.raises(InputError, match="u_calibration"):
        vm.loads(vm.dumps(d), "m.json")


def test_a_mixture_that_fails_the_blocks_is_set_aside(tmp_path):
    """Balls on the edges of the box (a 6 × 2 × 2 grid), a smooth field, the workpiece inside: the K-fold
    folds pick a spectral mixture (Q4, 0.59 µm against Matérn's 0.68), which predicts whole blocks of
    balls worse than Matérn (0.70 against 0.68 µm) and oscillates across the box — the workpiece was left
    with 1.53 µm, worse than the affine transform alone (1.41 µm). The mixture is set aside, the block
    test is reported (`spectral_mixture_block_test`, its "chosen" the selection's), and the workpiece's
    error falls below the transform's (bench_fiducials --coverage box_grid, seed 2)."""
    import zlib

    from pointspro.core.calibration.fiducials import PARAMS, AffineFit

    seed, n = 2, 24
    rng = np.random.default_rng(1000 * seed + zlib.crc32(b"box_grid") % 997)
    g = np.array([[x, y, z] for x in np.linspace(0, 1, 6) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    g[:, 0] = np.clip(g[:, 0] + rng.uniform(-0.03, 0.03, n), 0, 1)
    ref = LOW + g * EXTENT
    lo, hi = ref.min(0), ref.max(0)
    f = smooth_field(seed, "fourier", 1.3, EXTENT, machine_frame(LOW))
    true_c = machine_frame(ref)
    pts, ids = ball_points(true_c - f(true_c), noise=0.2e-3, seed=seed)
    given = ref + rng.normal(0, 0.2e-3, ref.shape)
    W = lo + rng.uniform(0, 1, (3000, 3)) * (hi - lo)
    (tmp_path / "reference.csv").write_text("fiducial,x,y,z\n" + "".join(
        f"{i + 1},{float(r[0])!r},{float(r[1])!r},{float(r[2])!r}\n" for i, r in enumerate(given)))
    res = FiducialsStep().run(PointCloud.from_xyz(*pts.T, fiducial=ids),
                              FiducialsStep.Params(reference="reference.csv", monte_carlo_runs=0),
                              Context(base_dir=tmp_path))
    sel = res.report["gp_selection"]
    test = sel["spectral_mixture_block_test"]
    assert test["chosen_by_k_fold"].startswith("spectral_mixture") and not test["mixture_kept"]
    assert test["compared_with"] == [sel["chosen"], "none"] and test["chosen"] == sel["chosen"] != "none"
    rms = test["blocked_rms_um"]
    assert rms[test["chosen_by_k_fold"]] > rms[sel["chosen"]] <= rms["none"]
    assert test["balls_compared"] >= 8
    _, err, _ = apply(tmp_path, res.artifacts["volumetric_model.json"], W, f)
    tr = vm.loads(res.artifacts["volumetric_model.json"], "m.json").transform
    affine = AffineFit(np.array([tr["params"][p] for p in PARAMS]), np.zeros((12, 12)), 0, 0, 0, None)
    TW = machine_frame(W)
    rms_gp = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    rms_affine = float(np.sqrt(np.mean(np.sum((affine.inverse(TW - f(TW)) - W) ** 2, axis=1))))
    assert rms_gp < 0.98 * rms_affine, (rms_gp, rms_affine)
