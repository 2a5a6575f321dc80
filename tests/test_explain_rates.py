"""The explain selection's false-positive rate on a gap with no effect in it (pure noise).

`core.explain.select` lets an effect enter when p < α/m (Bonferroni over the m candidates of the
stage; the vibration's m counts its N/2 searched frequencies), ΔBIC < −10, and its gain is not local.
On white noise the chance that anything is found must stay at or below α. Checked over 200 fixed seeds
on small clouds with a one-sided binomial bound: a count above the 99.9 % quantile of Binomial(200, α)
(8 of 200 for α = 0.01) fails.

On such clouds the ΔBIC gate (a 1-parameter term needs χ² > 10 + ln N, p ≈ 1e-4 for N = 400) and the
locality gate (a fit to noise gains in a few cells) each keep the rate far below α by themselves, and
would hide a missing correction. The second test therefore switches both off: the significance gate
must then hold α alone — and, on the same seeds, the uncorrected gate p < α does not (94 of 200 noise
gaps on the spiral "find" an effect, nearly all a vibration at the strongest of 200 frequencies).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from pointspro.core.explain import select as S
from pointspro.core.simulate.effects import ScanContext
from pointspro.core.simulate.model import ModelSpec
from pointspro.core.simulate.scan import scan_points

SEEDS = range(200)
NOISE = 2e-6  # mm
SURFACE = {"type": "even_asphere", "R": 200.0, "k": -0.5, "A": {4: 2e-8}, "aperture": 50.0}
# small clouds: a spiral of 400 points (uniform time stamps: the vibration search runs; 20 samples a turn
# resolve the spindle's harmonics up to 9), a spiral of 800 points sampled finely in angle (80 a turn:
# all 32 harmonics of the spindle_axial and spindle_tilt, ~70 candidates a stage) and a raster (its
# clock has jumps at the row changes; the vibration is searched on it too)
SCANS = {
    "spiral": {"type": "spiral", "radius": 10.0, "rpm": 60.0, "pitch": 0.5, "fs": 20.0},
    "spiral_harmonics": {"type": "spiral", "radius": 10.0, "rpm": 60.0, "pitch": 1.0, "fs": 80.0},
    "raster": {"type": "raster", "radius": 10.0, "spacing": 0.5, "lines": 15, "speed": 5.0},
}


def scan_context(scan: dict) -> ScanContext:
    m = ModelSpec.model_validate({"pointspro_model": 1, "surface": SURFACE, "scan": scan, "effects": []})
    sp = scan_points(m.scan)
    return ScanContext.from_surface(m.build_surface(), sp["x"], sp["y"], sp["t"], sp["c"])


def false_positives(ctx: ScanContext) -> int:
    """How many of the pure-noise gaps make the selection find an effect."""
    n = ctx.x.size
    return sum(bool(S.select(ctx, np.random.default_rng(seed).normal(0.0, NOISE, n), bootstrap=0)["found"])
               for seed in SEEDS)


def most_allowed(alpha: float) -> int:
    """The largest false-positive count out of len(SEEDS) that a rate ≤ α explains (P(X > k) < 0.1 %)."""
    return int(stats.binom.ppf(0.999, len(SEEDS), alpha))


@pytest.fixture(scope="module", params=sorted(SCANS))
def ctx(request):
    return scan_context(SCANS[request.param])


def test_pure_noise_finds_nothing_at_rate_alpha(ctx):
    fp = false_positives(ctx)
    assert fp <= most_allowed(S.ALPHA), f"{fp}/{len(SEEDS)} pure-noise gaps found an effect (α = {S.ALPHA})"


def test_significance_gate_alone_holds_alpha(ctx, monkeypatch):
    monkeypatch.setattr(S, "BIC_STRONG", np.inf)  # every ΔBIC is strong enough
    monkeypatch.setattr(S, "LOCAL_LIMIT", np.inf)  # no gain is local
    fp = false_positives(ctx)
    assert fp <= most_allowed(S.ALPHA), (
        f"{fp}/{len(SEEDS)} pure-noise gaps pass p < α/m: the Bonferroni correction does not hold α")


def test_without_bonferroni_the_gate_does_not_hold_alpha(ctx, monkeypatch):
    """The same seeds with p < α: the test above sees a correction that is missing."""
    monkeypatch.setattr(S, "BIC_STRONG", np.inf)
    monkeypatch.setattr(S, "LOCAL_LIMIT", np.inf)
    monkeypatch.setattr(S, "significant", lambda p, m: p < S.ALPHA)
    fp = false_positives(ctx)
    assert fp > most_allowed(S.ALPHA), f"{fp}/{len(SEEDS)}"


def test_the_spindle_harmonics_are_in_the_family():
    """Each resolved harmonic is a candidate of its own: the fine spiral's stage judges ~70."""
    from pointspro.core.simulate.effects import resolved_harmonics

    ctx = scan_context(SCANS["spiral_harmonics"])
    assert resolved_harmonics(ctx) == 32
    groups, _ = S.linear_groups(ctx)
    assert sum(g.effect == "spindle_axial" for g in groups) == 32
    assert sum(g.effect == "spindle_tilt" for g in groups) == 31


def _ar1_noise(ctx: ScanContext, rho: float, seed: int) -> np.ndarray:
    """AR(1) noise of marginal σ NOISE along the scan (in time order), lag-1 correlation rho."""
    from scipy.signal import lfilter

    n = ctx.x.size
    e = lfilter([1.0], [1.0, -rho], np.random.default_rng(seed).normal(0.0, NOISE * np.sqrt(1 - rho * rho), n))
    g = np.empty(n)
    g[np.argsort(ctx.t, kind="stable")] = e
    return g


@pytest.mark.parametrize("scan", ["spiral", "raster"])
def test_correlated_noise_alone_names_no_effect(scan, monkeypatch):
    """Noise correlated along the scan (AR(1), ρ = 0.5: a probe's or an interferometer's) has a red
    spectrum, and the white-noise tests named an effect — a low "vibration" mostly — in 15–17 of 40
    such gaps. Each named effect is now tested again on data whitened for the residual's own AR(1)
    correlation (select._correlated_noise_gate): at most the binomial bound at α over 40 seeds. Without the gate
    the same seeds exceed it (the test can fail)."""
    ctx = scan_context(SCANS[scan])
    seeds = range(40)
    bound = int(stats.binom.ppf(0.999, len(seeds), S.ALPHA))

    def named():
        return sum(bool(S.select(ctx, _ar1_noise(ctx, 0.5, 1000 + s), bootstrap=0)["found"]) for s in seeds)

    assert named() <= bound
    monkeypatch.setattr(S, "RHO_GATE", np.inf)
    assert named() > bound


def test_noise_correlated_negatively_names_no_vibration():
    """Blue noise (AR(1) of ρ = −0.5: consecutive readings alternating) has its power at high
    frequencies: the white-noise tests named a high "vibration" in 15 of 40 spiral gaps (a review);
    the gate fires on |ρ̂| and whitens for it."""
    ctx = scan_context(SCANS["spiral"])
    seeds = range(40)
    named = sum(bool(S.select(ctx, _ar1_noise(ctx, -0.5, 2000 + s), bootstrap=0)["found"]) for s in seeds)
    assert named <= int(stats.binom.ppf(0.999, len(seeds), S.ALPHA))


def test_a_true_effect_beside_a_look_alike_survives_the_gate(monkeypatch):
    """A hidden squareness cone (8 σ) in AR(1) noise of ρ = 0.8 on the spiral: the white-noise search
    names it with a look-alike (straightness) and vibrations; beside each other on whitened data
    both smooth ones fail (F 3.9 and 2.4), and dropping every failing effect at once lost the cone,
    which alone has F ≈ 5000 (a review). One at a time, least supported first, keeps it: on every seed
    where the search without the gate names the cone, the gate keeps it, and the spurious names go.
    On this spiral the radius is linear in time, so the cone is named squareness, thermal drift or
    dynamic lag (the known tie): any of them counts."""
    from pointspro.core.simulate.effects import LIBRARY

    ctx = scan_context(SCANS["spiral"])
    sq = LIBRARY["squareness"].columns(ctx)[:, 0]
    sq = (sq - sq.mean()) / np.sqrt(np.mean((sq - sq.mean()) ** 2))
    cone = {"squareness", "thermal_drift", "dynamic_lag"}

    from scipy.signal import lfilter

    def names(seed):  # AR(1) started in its stationary state (the review's generator)
        rng = np.random.default_rng(seed)
        w = rng.normal(0.0, NOISE * 0.6, sq.size)
        w[0] = rng.normal(0.0, NOISE)
        e = np.empty(sq.size)
        e[np.argsort(ctx.t, kind="stable")] = lfilter([1.0], [1.0, -0.8], w)
        g = 8.0 * NOISE * sq + e
        found = S.select(ctx, g, bootstrap=0)["found"]
        # each stage's evidence is stated against the stages kept before it (after a drop too)
        stages = sorted((st for f in found for st in f["stages"]), key=lambda st: -st.ssr_before)
        ssr = float(np.sum((g - g.mean()) ** 2))
        for st in stages:
            assert st.ssr_before == pytest.approx(ssr, rel=1e-9)
            ssr = st.ssr_after
        return [f["effect"] for f in found]

    seeds = range(9000, 9012)
    gated = [names(s) for s in seeds]
    monkeypatch.setattr(S, "RHO_GATE", np.inf)
    plain = [names(s) for s in seeds]
    assert sum(bool(cone & set(p)) for p in plain) >= 8
    assert all(cone & set(g) for g, p in zip(gated, plain) if cone & set(p))
    assert sum(len(g) for g in gated) < sum(len(p) for p in plain)  # the vibrations and look-alikes go


def _flicker_noise(ctx: ScanContext, slope: float, seed: int) -> np.ndarray:
    """Power-law noise (power ∝ 1/f^slope) of marginal σ NOISE along the scan: a window of n samples
    out of a series 8 times as long, so not periodic over the scan (an instrument's drift is not)."""
    n = ctx.x.size
    m = 8 * n
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft(rng.normal(0.0, 1.0, m))
    f = np.arange(spec.size, dtype=np.float64)
    f[0] = 1.0
    start = int(rng.integers(0, m - n))
    e = np.fft.irfft(spec / f ** (slope / 2), m)[start: start + n]
    e = (e - e.mean()) * NOISE / np.std(e)
    g = np.empty(n)
    g[np.argsort(ctx.t, kind="stable")] = e
    return g


@pytest.mark.parametrize("slope", [1.0, 1.5])
def test_flicker_noise_alone_names_no_effect(slope, monkeypatch):
    """Flicker noise (1/f, 1/f^1.5: an interferometer's or a probe's drift) wanders slowly, and its
    slowest wander is a polynomial in time — on a spiral, straightness's or a drift's signature. The
    AR(3) gate left 8 (1/f) and 16 (1/f^1.5) of 40 spiral gaps naming an effect: the chosen effects had
    taken that wander out of the residual it models. The power-law model (select.power_law_gls,
    fitted above the frequencies the effects took and extrapolated below them) keeps the rate within
    the binomial bound at α; without it (power_law_gls → None) the same seeds exceed it at
    1/f^1.5 (at 1/f these seeds name 3, at the bound: the 1/f case checks the rate alone)."""
    ctx = scan_context(SCANS["spiral"])
    seeds = range(40)
    bound = int(stats.binom.ppf(0.999, len(seeds), S.ALPHA))

    def named():
        return sum(bool(S.select(ctx, _flicker_noise(ctx, slope, 3000 + s), bootstrap=0)["found"])
                   for s in seeds)

    assert named() <= bound
    if slope == 1.5:
        monkeypatch.setattr(S, "power_law_gls", lambda *a, **k: None)
        assert named() > bound


def test_a_random_walk_beside_white_noise_names_fewer_effects():
    """White noise plus a random walk of the same RMS along the scan (an instrument's drift): the
    chosen low-frequency effects take the walk's wander and leave a residual of lag-1 autocorrelation
    0.08–0.13, below the gate's old 0.2 — 14 of 20 such null gaps on a 5,000-point spiral named effects
    (a review: straightness and three vibrations, verdict "explained"). At RHO_GATE 0.05: 4 of 20 on
    these seeds. Not the rate α: a random walk's slow wander is what a drift or a slide's straightness
    is (benchmarks/README.md) — this guards the gain; with the old gate the same seeds name more."""
    ctx = scan_context({"type": "spiral", "radius": 20.0, "rpm": 60.0, "pitch": 0.4, "fs": 100.0})
    order = np.argsort(ctx.t, kind="stable")
    n = ctx.x.size

    def gap(seed):
        rng = np.random.default_rng(6000 + seed)
        walk = np.cumsum(rng.normal(0.0, 1.0, n))
        walk = (walk - walk.mean()) * NOISE / walk.std()
        g = np.empty(n)
        g[order] = rng.normal(0.0, NOISE, n) + walk
        return g

    def named():
        return sum(bool(S.select(ctx, gap(s), bootstrap=0)["found"]) for s in range(20))

    assert named() <= 5
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(S, "RHO_GATE", 0.2)
        assert named() >= 10
