"""Issue 16 part 1: the volumetric GP's kernel chosen by an honest out-of-sample criterion.

Cases in the set-up of 000 §2.4 (core.calibration.fiducial_sim): 24 balls at random in 200 × 40 × 50 mm,
a random smooth field of 1.3 µm RMS |e| (two families, several seeds), 0.2 µm probing noise on each
probe point and 0.2 µm calibration noise on the reference centres, 3,000 workpiece points inside the
calibrated workspace that are not fiducials; `fiducials` then `volumetric {frame: reference}`; the
error is the RMS of |corrected − true| over the workpiece points (3-D, µm).
"""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.calibration.fiducial_sim import case_000
from pointspro.core.step import Context
from pointspro.plugins.fiducials import FiducialsStep
from pointspro.plugins.volumetric import VolumetricStep


def run_case(tmp_path, seed, kind):
    c = case_000(seed, kind)
    (tmp_path / "reference.csv").write_text(c.reference_csv(), encoding="utf-8")
    cloud = PointCloud.from_xyz(*c.points.T, fiducial=c.ids)
    res = FiducialsStep().run(cloud, FiducialsStep.Params(reference="reference.csv", monte_carlo_runs=0),
                              Context(base_dir=tmp_path))
    (tmp_path / "m.json").write_text(res.artifacts["volumetric_model.json"], encoding="utf-8")
    out = VolumetricStep().run(PointCloud(c.work_meas), VolumetricStep.Params(model="m.json", frame="reference"),
                               Context(base_dir=tmp_path))
    from pointspro.core.calibration import volumetric_model as vm
    from pointspro.core.calibration.fiducials import PARAMS, AffineFit

    t = vm.loads(res.artifacts["volumetric_model.json"], "m.json").transform
    fit = AffineFit(np.array([t["params"][n] for n in PARAMS]), np.zeros((12, 12)), 0, 0, 0, None)

    def rms(p):
        return float(np.sqrt(np.mean(np.sum((p - c.work_ref) ** 2, axis=1))) * 1e3)

    return rms(out.cloud.xyz), rms(fit.inverse(c.work_meas)), res.report


@pytest.mark.parametrize("seed, kind", [(0, "fourier"), (1, "fourier"), (2, "fourier"), (2, "kinematic"),
                                        (3, "kinematic")])
def test_workpiece_error_after_the_gp_over_seeds(tmp_path, seed, kind):
    """Measured (µm, GP / affine only, chosen), with the GP's noise bounded by the declared noise:
    fourier 0 0.53/0.86 rbf_0.5x, 1 0.41/0.64, 2 0.39/0.80, kinematic 2 0.33/0.83, kinematic 3
    0.405/0.405 none (goal of issue 16: ≤ 0.40 — met on 8 of 16 cases, benchmarks/bench_fiducials.py). The former in-sample choice took a spectral mixture
    that interpolated the fiducials and removed ~11 % of the error (issue 16). Fourier 0 was a strict
    xfail: its RBF's CV (0.720 µm) exceeded the affine transform's in-sample residual (0.690 µm) — with
    the transform re-fitted in each fold too, "no GP" cross-validates at 0.899 µm there and the GP
    wins honestly."""
    gp, affine, rep = run_case(tmp_path, seed, kind)
    print(f"{kind} seed {seed}: GP {gp:.3f} µm, affine only {affine:.3f} µm, {rep['gp_selection']['chosen']}")
    sel = rep["gp_selection"]
    assert sel["criterion"].startswith("6-fold cross-validation (the affine transform and")
    assert rep["gp_cv_rms_um"] == sel["cv_rms_um"][sel["chosen"]]
    assert sel["no_gp_rms_um"] == sel["cv_rms_um"]["none"]
    # held out, "no GP" is worse than at the fiducials the transform was fitted to
    assert sel["no_gp_rms_um"]["norm"] > sel["no_gp_in_sample_rms_um"]["norm"]
    pooled = {k: v["norm"] for k, v in sel["cv_rms_um"].items()}
    best = min(pooled, key=pooled.get)
    # the chosen one is the best, or "none" where the best GP does not win by one standard error
    assert sel["chosen"] in (best, "none")
    # the honest figure cannot be below the noise of a held-out fiducial (0.2 µm calibration noise per
    # axis: ≥ 0.35 µm in |e|), which the in-sample LOO of a spectral mixture is
    assert rep["gp_cv_rms_um"]["norm"] > 0.3
    if sel["chosen"] == "none":
        assert sel["kind"] == "none" and gp == pytest.approx(affine, abs=1e-9)
    else:
        assert rep["gp_cv_rms_um"]["norm"] < sel["no_gp_rms_um"]["norm"]
        assert gp < 0.95 * affine, (gp, affine)


def test_no_gp_where_the_field_is_below_the_noise(tmp_path):
    """A field of 1 pm (nothing the balls can resolve): the model applies no GP — the workpiece gets
    exactly the affine transform — and its uncertainty keeps the held-out error left (not zero)."""
    from pointspro.core.calibration import volumetric_model as vm

    for seed in (0, 2, 3):
        c = case_000(seed, "fourier", rms_um=1e-6)
        d = tmp_path / str(seed)
        d.mkdir()
        (d / "reference.csv").write_text(c.reference_csv(), encoding="utf-8")
        cloud = PointCloud.from_xyz(*c.points.T, fiducial=c.ids)
        res = FiducialsStep().run(cloud, FiducialsStep.Params(reference="reference.csv", monte_carlo_runs=0),
                                  Context(base_dir=d))
        sel = res.report["gp_selection"]
        assert sel["chosen"] == "none" and sel["kind"] == "none", sel["cv_rms_um"]
        text = res.artifacts["volumetric_model.json"]
        spec = vm.loads(text, "m.json")
        assert {g.kind for g in spec.gp.values()} == {"none"}
        (d / "m.json").write_text(text, encoding="utf-8")
        out = VolumetricStep().run(PointCloud(c.work_meas), VolumetricStep.Params(model="m.json"),
                                   Context(base_dir=d))
        np.testing.assert_array_equal(out.cloud.xyz, c.work_meas)      # machine frame: no correction
        u = np.column_stack([out.cloud["u_x"], out.cloud["u_y"], out.cloud["u_z"]])
        # u = the cross-validated σ of "none", with the blocked cross-validation's distance term
        # (u² = σ² + τ²·d, docs/uncertainty.md) where held-out blocks showed more error than σ
        sigma = np.array([sel["no_gp_rms_um"][k] for k in ("ex", "ey", "ez")])
        tau2 = spec.u_calibration.excess_variance_um2_per_mm
        dist = out.report["u_inflation"]
        assert np.all(u * 1e3 >= sigma - 1e-9)
        if tau2 == 0:
            np.testing.assert_allclose(u[0] * 1e3, sigma)
        else:
            assert np.max(u * 1e3 / sigma) == pytest.approx(dist["ratio_max"], rel=1e-6)
        assert out.report["kernels"] == {"ex": "none", "ey": "none", "ez": "none"}


def test_in_sample_loo_is_biased_and_cross_validation_is_not(monkeypatch):
    """A 10-component spectral mixture fitted to all 24 fiducials: its closed-form LOO is far below the
    noise it was given, its cross-validated RMS (hyperparameters re-fitted without the held-out balls)
    is not — and the honest choice does not take it. (Every mixture is tried here: the early stop
    SM_BEHIND would leave the larger ones out, which is what the comparison needs.)"""
    from pointspro.core.calibration import gp as G
    from pointspro.core.calibration.gp import select_gps

    monkeypatch.setattr(G, "SM_BEHIND", np.inf)

    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-100, 100, 24), rng.uniform(-20, 20, 24), rng.uniform(0, 50, 24)])
    y = 5e-4 * np.sin(X[:, 0] / 60) + 3e-4 * np.cos(X[:, 2] / 30) + rng.normal(0, 2e-4, 24)
    gps, info = select_gps(X, y, Q=10)
    assert info["chosen"] in info["cv_rms"] and not info["chosen"].startswith("spectral_mixture_Q10")
    for name, cv in info["cv_rms"].items():
        assert cv[0] > 1.2e-4, (name, cv)          # noise 2e-4: nothing predicts held-out balls better
    sm = [n for n in info["loo_rms"] if n.startswith("spectral_mixture")]
    assert any(info["loo_rms"][n][0] < 0.5 * info["cv_rms"][n][0] for n in sm), info


def test_model_file_records_the_selection(tmp_path):
    from pointspro.core.calibration import volumetric_model as vm

    _, _, rep = run_case(tmp_path, 0, "kinematic")
    spec = vm.loads((tmp_path / "m.json").read_text(encoding="utf-8"), "m.json")
    assert spec.gp_selection["chosen"] == rep["gp_selection"]["chosen"]
    assert spec.gp["ex"].kind == rep["gp_selection"]["kind"]


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_mixtures_stop_once_far_behind_the_best_kernel(seed, monkeypatch):
    """Balls on two planes and a smooth field an RBF predicts well: no mixture with more components is
    tried after one that predicts the held-out balls SM_BEHIND × worse than the best candidate so far
    (Q = 1 … 10 all ran at ~2 × an RBF's error and took a step to 13 s); the choice is the same."""
    from pointspro.core.calibration import gp as G

    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-100, 100, 24), rng.uniform(-20, 20, 24), np.where(np.arange(24) % 2, 50.0, 0.0)])
    Y = np.column_stack([4e-4 * np.sin(X[:, 0] / 70 + k) + 2e-4 * (X[:, 2] / 50) ** 2 for k in range(3)])
    Y = Y + rng.normal(0, 1e-4, Y.shape)
    _, info = G.select_gps(X, Y, Q=10)
    pooled = {n: float(np.sum(np.square(v))) for n, v in info["cv_rms"].items()}
    order = list(pooled)  # in the order they were tried
    sm = [n for n in order if n.startswith("spectral_mixture")]
    for n in sm[:-1]:  # a mixture followed by a larger one was not far behind the best before it
        before = order[:order.index(n)]
        assert pooled[n] < G.SM_BEHIND * min(pooled[k] for k in before), (n, pooled)
    monkeypatch.setattr(G, "SM_BEHIND", np.inf)
    _, every = G.select_gps(X, Y, Q=10)
    assert len(every["cv_rms"]) > len(info["cv_rms"])  # the rule skipped mixtures here
    assert every["chosen"] == info["chosen"]
