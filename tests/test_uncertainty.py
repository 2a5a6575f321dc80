"""Issue 23 (part 1): the uncertainty: block, the noise estimate, the Monte Carlo through the steps
(docs/uncertainty.md). Coverage over repeated simulations: test_uncertainty_coverage.py."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core.errors import Cancelled, RecipeError
from pointspro.core.pipeline import run_pipeline
from pointspro.core.progress import Progress
from pointspro.core.recipe import parse_recipe
from pointspro.core.uncertainty import propagate
from pointspro.core.uncertainty.noise import estimate_sigma
from pointspro.core.yamlio import load_yaml

from .paper002 import machining_marks, radial, raster, star
from .test_uncertainty_sim import CASES

HEAD = ("pointspro: 1\nsurface: {type: even_asphere, c: 3.3e-4, k: -0.98, aperture: 1300}\n"
        "steps:\n  - misalignment: {}\n  - zernike: {terms: 36, remove: [piston, tilt]}\n")


def parse(text):
    return parse_recipe(load_yaml(text, "r.yaml"), "r.yaml")


# -- the block ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("block, words", [
    ("uncertainty:\n  samples: 3\n", ["r.yaml, line 7", "'samples'", "JCGM 101", "at least 50"]),
    ("uncertainty:\n  sources:\n    z_scale: 50\n", ["r.yaml, line 8", "'sources.z_scale'", "no unit", "ppm"]),
    ("uncertainty:\n  noise: 0.05\n", ["line 7", "'noise'", "no unit", "nm", "um"]),
    ("uncertainty:\n  noise: 50 furlongs\n", ["line 7", "'noise'", "'furlongs'", "nm"]),
    ("uncertainty:\n  sources:\n    probe_radius: 0.5 um\n", ["line 8", "'sources.probe_radius'",
                                                             "no enabled 'probe_radius' step"]),
    ("uncertainty:\n  sources:\n    wind: 3 um\n", ["line 8", "unknown source", "probe_radius"]),
    ("uncertainty:\n  sampels: 200\n", ["line 7", "unknown key 'sampels'"]),
    ("uncertainty:\n  sources:\n    temperature: 0.2 K\n", ["line 8", "cte"]),
    ("uncertainty:\n  sources:\n    temperature: {u: 0.2, cte: 2.6 ppm/K}\n", ["'sources.temperature.u'",
                                                                            "no unit", "K"]),
    ("uncertainty:\n  samples: 200.5\n", ["'samples'", "integer"]),
    ("uncertainty:\n  noise: 0 nm\n", ["line 7", "'noise'", "σ = 0", "repeatability"]),
    ("uncertainty:\n", ["line 6", "uncertainty: is empty"]),  # was silently no uncertainty at all
    ("tolerance:\n", ["line 6", "tolerance: is empty"]),
])
def test_bad_blocks_are_one_line_naming_line_and_key(block, words):
    with pytest.raises(RecipeError) as e:
        parse(HEAD + block)
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


def test_a_good_block_round_trips_with_its_units():
    r = parse(HEAD.replace("  - misalignment: {}", "  - probe_radius: {radius: 2.0}")
              + "uncertainty:\n  samples: 80\n  seed: 5\n  noise: 40 nm\n  sources:\n"
              "    probe_radius: 0.5 um\n    z_scale: 50 ppm\n    temperature: {u: 0.2 K, cte: 2.6 ppm/K}\n")
    u = r.uncertainty
    assert (u.samples, u.seed) == (80, 5)
    assert u.noise == pytest.approx(40e-6)
    by = {s.name: s for s in u.sources}
    assert by["probe_radius"].u == pytest.approx(0.5e-3)
    assert by["z_scale"].relative == pytest.approx(50e-6)
    assert by["temperature"].relative == pytest.approx(0.2 * 2.6e-6)
    d = r.to_dict()["uncertainty"]
    assert d["noise"] == "40 nm" and d["sources"]["temperature"] == {"u": "0.2 K", "cte": "2.6 ppm/K"}
    again = parse(r.to_yaml())
    assert again.uncertainty.to_dict() == d
    # a glass ceramic's negative coefficient (Zerodur, ULE) is a coefficient, not a negative uncertainty
    neg = parse(HEAD + "uncertainty:\n  noise: 40 nm\n  sources:\n    temperature: {u: 0.5 K, cte: -0.03 ppm/K}\n")
    t = neg.uncertainty.sources[0]
    assert t.relative == pytest.approx(0.5 * 0.03e-6) and neg.uncertainty.to_dict()["sources"]["temperature"]["cte"] == "-0.03 ppm/K"
    with pytest.raises(RecipeError, match="key 'sources.temperature.u': a standard uncertainty is a finite number ≥ 0"):
        parse(HEAD + "uncertainty:\n  noise: 40 nm\n  sources:\n    temperature: {u: -0.5 K, cte: 2.6 ppm/K}\n")


# -- the noise estimate ---------------------------------------------------------------------------------

def _smooth(x, y, d):
    r = np.hypot(x, y) / (d / 2)
    t = np.arctan2(y, x)
    return 1e-3 * (0.4 * r ** 2 * np.cos(2 * t) + 0.2 * r ** 3 * np.cos(3 * t + 1) - 0.1 * r ** 4)


@pytest.mark.parametrize("pattern", ["raster", "star", "radial", "random"])
def test_noise_sigma_is_within_a_few_percent_on_smooth_forms(pattern):
    """Several patterns and densities, five seeds each, two noise levels: each estimate within 10 %,
    their mean within 4 % of the true σ."""
    if pattern == "raster":
        x, y = raster(600, 12.0)
    elif pattern == "star":
        x, y = star(1300, 18, 5.0)
    elif pattern == "radial":
        x, y = radial(1000, 36, 2000)
    else:
        x, y = np.random.default_rng(3).uniform(-300, 300, (2, 3000))
    d = float(np.ptp(x))
    for sigma in (20e-6, 300e-6):
        est = [estimate_sigma(x, y, _smooth(x, y, d) + np.random.default_rng(s).normal(0, sigma, x.size)) / sigma
               for s in range(5)]
        assert np.all(np.abs(np.array(est) - 1) < 0.10), est
        assert abs(np.mean(est) - 1) < 0.04, est


def test_noise_sigma_is_conservative_where_the_form_has_structure_at_the_neighbour_scale():
    x, y = raster(600, 12.0)
    v = machining_marks(x, y, 600) + np.random.default_rng(0).normal(0, 50e-6, x.size)
    assert estimate_sigma(x, y, v) > 1.5 * 50e-6


# -- the Monte Carlo ------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def issue_run():
    case = CASES["issue"]
    noisy, _ = case.measure(11)
    r = case.recipe("{samples: 60, seed: 3, workers: 2}")
    return case, noisy, r, run_pipeline(noisy, r)


def test_block_has_every_figure_with_value_u_and_interval(issue_run):
    _, _, _, res = issue_run
    s = res.summary()
    b = s["uncertainty"]
    for key in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad", "zernike.Z4_nm", "zernike.Z9_nm",
                "pose.alpha_deg", "pose.dx_mm"):
        e = b[key]
        assert set(e) >= {"value", "measured", "bias", "u", "U95", "interval95", "k", "method"}, key
        lo, hi = e["interval95"]
        assert lo <= e["value"] <= hi and e["u"] > 0 and e["U95"] > 0, key
    for key in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad"):  # the plain figure beside the corrected
        assert b[key]["measured"] == s[key]
        assert b[key]["bias"] > 0  # noise inflates them
    zern = next(st for st in res.steps if st.id == "zernike").report["coefficients"]
    assert b["zernike.Z9_nm"]["measured"] == pytest.approx(zern[8]["coefficient_nm"], abs=1e-9)
    assert b["zernike.Z9_nm"]["bias"] == 0
    m = b["_meta"]
    assert m["samples"] == 60 and m["samples_failed"] == 0 and "warnings" not in m
    assert 40 < m["noise_sigma_um"] * 1e3 < 60  # the case's 50 nm
    assert "aperture" in m["reuse"] and "conditional" in m["reuse"]
    assert "outlier" in m["not_included"]


def test_results_are_the_same_for_one_and_two_workers(issue_run):
    case, noisy, r, res = issue_run
    one = propagate(r, res, workers=1)
    two = res.uncertainty
    assert np.array_equal(one.samples, two.samples, equal_nan=True)
    b1, b2 = one.block(), two.block()
    for key in b1:
        if key != "_meta":
            assert b1[key] == b2[key], key


def test_artifacts_are_a_histogram_and_the_samples_csv(issue_run, tmp_path):
    _, _, _, res = issue_run
    arts = res.artifacts
    csv = arts["uncertainty_samples.csv"]
    lines = [ln for ln in csv.splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    assert head[:3] == ["sample", "rms_um", "pv_um"] and "zernike.Z4_nm" in head
    assert len(lines) == 61
    rms = np.array([float(ln.split(",")[1]) for ln in lines[1:]])
    assert np.array_equal(rms, res.uncertainty.samples[:, 0])
    p = tmp_path / "uncertainty.png"
    arts["uncertainty.png"](p)
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_histograms_read_like_their_titles(issue_run):
    """The figures named for people ("RMS", not "rms_um"), a length's axis in its title's unit (it
    ran 0.566 … 0.590 µm under "577 nm"), whole sample counts (ticks read 2.5, 7.5)."""
    from pointspro.core.statement import with_uncertainty
    from pointspro.core.uncertainty.artifacts import histogram_figure

    _, _, _, res = issue_run
    fig = histogram_figure(res.uncertainty)
    ax = fig.axes[0]
    e = res.uncertainty.entries["rms_um"]
    assert ax.get_title() == "RMS: " + with_uncertainty(e["value"], e["U95"], "µm", e.get("k") or 2.0,
                                                        e.get("interval95"))
    unit = "nm" if max(e["value"], e["U95"]) < 1.0 else "µm"
    assert unit in ax.get_title() and ax.get_xlabel() == f"RMS ({unit})"
    scale = 1e3 if unit == "nm" else 1.0
    green = [ln for ln in ax.get_lines() if ln.get_color() == "#1b5e20"][0]
    assert green.get_xdata()[0] == pytest.approx(e["value"] * scale)
    for a in fig.axes:
        ticks = a.yaxis.get_majorticklocs()
        assert np.all(ticks == np.round(ticks)), a.get_title()
        assert "_um" not in a.get_title() and "_urad" not in a.get_xlabel()


def test_a_type_b_source_adds_what_its_sensitivity_predicts():
    """z_scale: the power term's sensitivity to ε by a finite difference times u(ε) is the budget's
    share, and u² grows by its square."""
    case = CASES["issue"]
    noisy, _ = case.measure(12)
    plain = case.recipe()
    base = run_pipeline(noisy, plain)
    eps = 1e-5
    scaled = noisy.replace(xyz=noisy.xyz * np.array([1.0, 1.0, 1.0 + eps]))

    def z4(res):
        return next(st for st in res.steps if st.id == "zernike").report["coefficients"][3]["coefficient_nm"]

    sens = (z4(run_pipeline(scaled, plain)) - z4(base)) / eps  # nm per unit ε
    u_eps = 20e-6
    with_src = run_pipeline(noisy, case.recipe("{samples: 100, seed: 2, noise: 50 nm, sources: {z_scale: 20 ppm}}"))
    without = run_pipeline(noisy, case.recipe("{samples: 100, seed: 2, noise: 50 nm}"))
    e = with_src.summary()["uncertainty"]["zernike.Z4_nm"]
    e0 = without.summary()["uncertainty"]["zernike.Z4_nm"]
    predicted = abs(sens) * u_eps
    assert predicted > 2 * e0["u"]  # the source dominates: the test can see it
    assert e["u"] == pytest.approx(np.hypot(e0["u"], predicted), rel=0.15)
    share = e["budget"]
    assert share["z_scale"] == pytest.approx(predicted, rel=0.15)
    assert share["noise"] == pytest.approx(e0["u"], rel=0.25)
    rms = with_src.summary()["uncertainty"]["rms_um"]
    assert "z_scale" in rms["budget"] and "noise" in rms["budget"]
    for entry in (e, rms):  # the shares add up to u (root sum of squares)
        assert np.sqrt(sum(v * v for v in entry["budget"].values())) == pytest.approx(entry["u"], rel=0.1)


@pytest.mark.parametrize("seed", range(5))
def test_the_budget_adds_up_to_the_samples_spread(seed):
    """Each source's share counts its quadratic action too (Var = b² + 2c² for a standard normal
    draw): the shares' root sum of squares is the samples' standard deviation. With only the linear
    slope, a source acting through Z² (z_scale on an RMS) got ~0 and the budget named the noise."""
    from pointspro.core.uncertainty.estimate import budget

    rng = np.random.default_rng(seed)
    Z = rng.standard_normal((400, 3))
    F = 1.0 + 0.3 * Z[:, 0] + 0.5 * Z[:, 1] ** 2 + 0.05 * Z[:, 2] + rng.normal(0, 0.1, 400)
    share = budget(F, Z, ["linear", "quadratic", "small"])
    assert share["linear"] == pytest.approx(0.3, rel=0.15)
    assert share["quadratic"] == pytest.approx(0.5 * np.sqrt(2.0), rel=0.3)  # Var Z² = 2 in expectation
    assert share["noise"] == pytest.approx(0.1, rel=0.2)
    assert np.sqrt(sum(v * v for v in share.values())) == pytest.approx(F.std(ddof=1), rel=0.05)


def test_cancel_stops_the_samples(issue_run):
    _, _, r, res = issue_run
    p = Progress()
    p.token.cancel()
    with pytest.raises(Cancelled):
        propagate(r, res, progress=p, workers=2)


def test_the_example_recipe_gets_its_uncertainty():
    from pointspro.core.io import read_cloud

    from .conftest import EXAMPLE

    text = (EXAMPLE / "recipe.yaml").read_text(encoding="utf-8")
    r = parse(text + "uncertainty: {samples: 50, seed: 1, sources: {probe_radius: 0.5 um}}\n")
    res = run_pipeline(read_cloud(EXAMPLE / "asphere_cmm.csv"), r)
    b = res.summary()["uncertainty"]
    m = b["_meta"]
    assert "warnings" not in m, m.get("warnings")
    assert abs(m["noise_sigma_um"] - 0.3) < 0.03  # make_example.py's 0.3 µm
    for name in ("manual_edit", "knn_denoise", "aperture"):
        assert name in m["reuse"].split("skipped")[0]
    assert "skipped bspline_map" in m["reuse"]
    assert b["rms_um"]["value"] < b["rms_um"]["measured"]
    assert "probe_radius" in b["rms_um"]["budget"]


def test_extra_figures_get_their_entries_corrected_by_their_kind(issue_run):
    """The tolerance's quantities (core/assessment.py passes them as extra_figures): an
    irregularity-like PV and an RMS computed like pv_um and rms_um get the same entries as those."""
    _, _, r, res = issue_run

    def extra(cloud, surface):
        v = np.asarray(cloud["residual"])
        return {"irr_um": float(np.ptp(v)) * 1e3, "rmsi_um": float(np.std(v)) * 1e3}

    extra.kinds = {"irr_um": "extreme", "rmsi_um": "quadratic"}
    out = propagate(r, res, extra_figures=extra, workers=2)
    b = out.block()
    for mine, theirs in (("irr_um", "pv_um"), ("rmsi_um", "rms_um")):
        for key in ("value", "measured", "u", "U95"):
            assert b[mine][key] == pytest.approx(b[theirs][key], rel=1e-9), (mine, key)
    assert "SIMEX" in b["irr_um"]["method"] and "budget" in b["rmsi_um"]


@pytest.mark.parametrize("kind", ["extreme", "smooth"])
def test_a_figure_that_cannot_be_negative_is_floored_at_zero_below_the_noise(kind):
    """PV, irregularity B, C, a fit's PV: a bias correction that overshoots zero (samples far above
    the measured value: the form is below the noise) gives value 0, below_noise, an interval from 0
    — irregularity B read −0.03 µm on a low-signal part (issue 16's review). A linear figure (a
    Zernike coefficient, A) keeps its sign."""
    from pointspro.core.uncertainty.estimate import estimate

    rng = np.random.default_rng(3)
    F = 0.10 + 0.01 * rng.standard_normal(200)  # samples of a figure measured at 0.02
    e = estimate("irr_um", kind, 0.02, F, None)
    assert e["value"] == 0.0 and e.get("below_noise") is True
    assert e["interval95"][0] == 0.0 and e["interval95"][1] > 0.0
    lin = estimate("sag_um", "linear", -0.02, -0.02 + 0.01 * rng.standard_normal(200), None)
    assert lin["value"] == -0.02 and lin["interval95"][0] < -0.02


def test_an_infinite_standard_uncertainty_says_finite():
    """`probe_radius: "1e999 um"` (inf) said "a standard uncertainty is ≥ 0"."""
    from pointspro.core.errors import RecipeError
    from pointspro.core.uncertainty.spec import parse_uncertainty

    with pytest.raises(RecipeError, match=r"a standard uncertainty is a finite number ≥ 0 \(got '1e999 um'\)"):
        parse_uncertainty({"samples": 200, "sources": {"probe_radius": "1e999 um"}}, "recipe.yaml", "recipe.yaml",
                          steps=["probe_radius"])


def test_a_given_noise_larger_than_the_residual_itself_is_warned_of():
    """σ 5 µm on a form of ~0.2 µm RMS: "RMS 0 ± …", all below the noise, with no word of why. The
    residual holds its noise (RMS² ≈ form² + σ²): a σ above its spread is a unit slip."""
    case = CASES["issue"]
    noisy, _ = case.measure(12)
    res = run_pipeline(noisy, case.recipe("{samples: 50, seed: 2, noise: 5 um}"))
    meta = res.summary()["uncertainty"]["_meta"]
    assert any("exceeds the spread of the final residual" in w for w in meta.get("warnings", []))
    ok = run_pipeline(noisy, case.recipe("{samples: 50, seed: 2, noise: 50 nm}"))
    assert not any("exceeds" in w for w in ok.summary()["uncertainty"]["_meta"].get("warnings", []))


def _sampling(pattern: str):
    import numpy as np

    if pattern == "raster":
        x, y = np.meshgrid(np.linspace(-10, 10, 40), np.linspace(-10, 10, 40))
        return x.ravel(), y.ravel()
    if pattern == "random":
        p = np.random.default_rng(99).uniform(-10, 10, (1600, 2))
        return p[:, 0], p[:, 1]
    if pattern == "spiral":
        t = np.linspace(0, 1, 900)
        r, a = 10 * np.sqrt(t), 90 * np.pi * np.sqrt(t)
        return r * np.cos(a), r * np.sin(a)
    rs = np.linspace(0.2, 10, 20)  # a 12-line star
    p = np.vstack([np.column_stack([np.r_[-rs[::-1], rs] * np.cos(a), np.r_[-rs[::-1], rs] * np.sin(a)])
                   for a in np.pi * np.arange(12) / 12])
    return p[:, 0], p[:, 1]


@pytest.mark.parametrize("pattern", ["raster", "random", "spiral", "star"])
def test_noise_auto_states_the_scatter_its_sigma_has_on_this_sampling(pattern):
    """σ's relative uncertainty from the data's own neighbourhoods (core/uncertainty/noise.py): the
    former 1.2/√N understated it 1.3–1.6× (a review measured 1.5–1.9/√N over seeds: the leave-one-out
    errors share their neighbours' noise, most on a raster). Over 100 noise draws on each sampling the
    scatter of σ̂/σ is within 30 % of what the estimate states (the two measured from 100 and 160 draws:
    ±7 % and ±6 %)."""
    import numpy as np

    from pointspro.core.uncertainty.noise import estimate_sigma, sigma_with_uncertainty

    x, y = _sampling(pattern)
    sigma = 20e-6
    est = np.array([estimate_sigma(x, y, np.random.default_rng(7000 + s).normal(0, sigma, x.size)) / sigma
                    for s in range(100)])
    _, u_rel = sigma_with_uncertainty(x, y, np.random.default_rng(1).normal(0, sigma, x.size))
    assert abs(np.mean(est) - 1.0) < 0.03  # unbiased
    assert 0.7 < np.std(est, ddof=1) / u_rel < 1.3, (np.std(est, ddof=1), u_rel)
    assert u_rel > 1.3 / np.sqrt(x.size)  # above the independent values' 1.17/√N


def test_a_given_noise_on_few_points_runs():
    """With noise given, σ is estimated from the data only to check the given one; below the 30
    points that estimate needs, the check is skipped — a 20-point input failed on it (a review)."""
    import numpy as np

    import pointspro.core as pp

    rng = np.random.default_rng(4)
    x, y = rng.uniform(-10, 10, (2, 20))
    z = 1e-4 * (x * x + y * y) / 100 + rng.normal(0, 1e-5, 20)
    recipe = {"pointspro": 1, "steps": [{"zernike": {"terms": 4, "remove": ["piston", "tilt"]}}],
              "uncertainty": {"noise": "10 nm", "samples": 50}}
    r = pp.run(recipe, pp.PointCloud.from_numpy(np.column_stack([x, y, z])))
    assert r.summary["uncertainty"]["rms_um"]["U95"] > 0
