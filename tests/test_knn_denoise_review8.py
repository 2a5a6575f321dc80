"""knn_denoise (robust), issue 16 part 3, left from review 7: digs of 20–30 points at a window of 2.5
point spacings, and noise-free small parts whose σ a ripple the window cannot follow sets."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.step import Context
from pointspro.plugins.knn_denoise import KnnDenoiseStep
from pointspro.plugins.knn_denoise.peers import hampel


def report(x, y, d, window):
    c = PointCloud.from_xyz(x, y, np.zeros_like(x), residual=d)
    return KnnDenoiseStep().run(c, KnnDenoiseStep.Params(window=window), Context()).report


def removed(x, y, d, window):
    return {int(i) for i in report(x, y, d, window)["removed_index"]}


@pytest.fixture
def gen(monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import denoise_review_gen

    return denoise_review_gen


def flat_digs(gen, layout, seed, density=4.0, noise=20e-6, ndig=6):
    """A 40 mm part (0.3 µm residual, 30 nm ripple, 20 nm noise) with `ndig` digs as the issue's: the
    nearest 20–30 points, 0.2–2 µm deep (× 0.8–1 per point), 7 mm apart."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed + 100)
    p = dict(R=20.0, density=density, res_um=0.3, ripple_um=0.03, ripple_lam=float(rng.uniform(5, 15)),
             noise_um=noise * 1e3)
    x, y = gen.sample(layout, p["R"], density, rng)
    d = gen.surface(p, x, y, rng) + rng.normal(0, noise, len(x))
    tree = cKDTree(np.column_stack([x, y]))
    centres, truth = [], set()
    for q in rng.permutation(np.flatnonzero(np.hypot(x, y) < p["R"] - 4)):
        if len(centres) == ndig:
            break
        if all(math.hypot(x[q] - a, y[q] - b) > 7 for a, b in centres):
            centres.append((x[q], y[q]))
            g = tree.query([x[q], y[q]], k=int(rng.integers(20, 31)))[1]
            d[g] -= rng.uniform(0.2, 2.0) * 1e-3 * rng.uniform(0.8, 1.0, len(g))
            truth |= set(g.tolist())
    return x, y, d, truth


@pytest.mark.parametrize("layout", ["scattered", "raster", "spiral"])
def test_digs_of_20_to_30_points_are_found_at_a_window_of_2_5_spacings(gen, layout):
    """Review 7: at a = 2.5 mean point spacings a dig of 20–30 points fills the 2a window, and the coarse
    pass's local σ, inflated by the dig itself in its first round (every point in the fits), never let
    the dig's points be trimmed. Its first round's σ leaves out the points beyond 10 σ_g: recall per
    seed 0.46 / 0.18 / 0.13 → 0.99 / 1.00 / 0.83 scattered, 0.29 / 0.63 / 0.46 → 1.00 raster, 0.14 / 0.29 /
    0.77 → 1.00 / 0.82 / 1.00 spiral; Hampel 0.04–0.30; nothing else removed."""
    recall = []
    for seed in range(3):
        x, y, d, truth = flat_digs(gen, layout, seed)
        found = removed(x, y, d, window=2.5 / math.sqrt(4.0))
        ham = set(np.flatnonzero(hampel(x, y, d)).tolist())
        r, rh = len(found & truth) / len(truth), len(ham & truth) / len(truth)
        assert r >= rh, (seed, r, rh)
        assert not found - truth, seed
        recall.append(r)
    assert min(recall) >= 0.8 and np.mean(recall) >= 0.9, recall


def small_part(seed, cone, noise=0.0):
    """A 10 mm part, hexagonal (even seeds) or round, raster or scattered (every third seed), 3,000–20,000
    points: 0.3 µm defocus, some astigmatism and a ripple of 1–4 windows, 10–100 nm (a = 3–8 spacings);
    `cone`: a diamond-turning centre cone, 0.2–0.5 µm high, 0.5–1 mm radius."""
    rng = np.random.default_rng(seed)
    hexa = seed % 2 == 0
    n = int(rng.uniform(3000, 20000))
    R = 5.0
    h = math.sqrt((1.5 * math.sqrt(3) if hexa else math.pi) * R * R / n)
    if seed % 3 == 0:
        x, y = rng.uniform(-R, R, 2 * n), rng.uniform(-R, R, 2 * n)
    else:
        X, Y = np.meshgrid(np.arange(-R, R + h / 2, h), np.arange(-R, R + h / 2, h))
        x, y = X.ravel(), Y.ravel()
    if hexa:
        keep = np.ones(len(x), bool)
        for k in range(6):
            keep &= x * math.cos(k * math.pi / 3) + y * math.sin(k * math.pi / 3) <= R * math.sqrt(3) / 2
    else:
        keep = np.hypot(x, y) <= R
    x, y = x[keep], y[keep]
    if seed % 3 == 0:
        x, y = x[:n], y[:n]
    window = float(rng.choice([3.0, 4.0, 6.0, 8.0])) * h
    lam, amp, th = float(rng.uniform(1, 4)) * window, float(rng.uniform(10, 100)) * 1e-6, rng.uniform(0, np.pi)
    r = np.hypot(x, y)
    d = (0.3e-3 * (2 * (r / R) ** 2 - 1) + 0.1e-3 * rng.normal() * (r / R) ** 2 * np.cos(2 * np.arctan2(y, x))
         + amp * np.sin(2 * np.pi * (x * np.cos(th) + y * np.sin(th)) / lam + rng.uniform(0, 6)))
    crad, chgt = float(rng.uniform(0.5, 1.0)), float(rng.uniform(0.2, 0.5)) * 1e-3
    if cone:
        d += chgt * np.clip(1 - r / crad, 0, None)
    if noise:
        d += rng.normal(0, noise, len(x))
    return x, y, d, window


@pytest.mark.parametrize("cone", [True, False])
def test_noise_free_rippled_small_parts_lose_nothing(cone):
    """Noise-free, a ripple of 1–4 windows sets σ (0.8–15 nm: the global σ of z is its model error), so
    neither the floor nor the rule for σ → 0 kept the centre cone's top: 301, 58, 164, 4 and 59 points
    of seeds 4, 11, 13, 29, 32 were removed. The points' own noise, from their nearest neighbours'
    quadratic (robust._point_noise), is 0.01–0.3 nm there: form, not outlier, where it ramps into its
    surroundings or continues the quadratic of its unflagged neighbours (robust._continuous)."""
    seeds = list(range(16)) + ([29, 32] if cone else [])
    lost = {s: len(removed(*small_part(s, cone)[:3], window=small_part(s, cone)[3])) for s in seeds}
    assert not any(lost.values()), lost


def test_outliers_on_a_noise_free_rippled_part_are_still_found():
    """The noise-free rule keeps form, not what is cut out of the surface: spikes (their neighbours'
    quadratic misses them by their height) and a flat dig on the rippled cone parts are all found,
    nothing else goes."""
    from scipy.spatial import cKDTree

    for seed in (4, 13, 32):
        x, y, d, window = small_part(seed, cone=True)
        rng = np.random.default_rng(seed)
        r = np.hypot(x, y)
        spikes = rng.choice(np.flatnonzero((r > 1.5) & (r < 3.5)), 8, replace=False)
        d[spikes] += rng.choice([-1, 1], 8) * rng.uniform(0.1, 0.5, 8) * 1e-3
        centre = np.flatnonzero((r > 3.8) & (r < 4.0))[0]
        dig = cKDTree(np.column_stack([x, y])).query([x[centre], y[centre]], k=20)[1]
        d[dig] -= 0.3e-3
        truth = set(spikes.tolist()) | set(dig.tolist())
        gone = removed(x, y, d, window)
        assert gone == truth, (seed, len(truth - gone), len(gone - truth))


def test_the_noise_free_rule_does_not_act_on_low_noise():
    """1 nm of noise on the same rippled parts is noise (the neighbours' quadratic reads 1.00–1.04 nm), not
    form: nothing is kept as form over 8 seeds with a smooth 30-point pit 0.2 µm deep, and where its
    deep points stand 5 σ out of the ripple's model error (seeds 4, 7: σ 1.3, 3.1 nm) all are found
    (review 7: smooth pits on 1 nm noise must not be kept as form). Where that error sets σ at 2–90 nm
    the pit is missed, before this rule as after (6 of 8 seeds: a limit of the window, not of the rule)."""
    for seed in range(8):
        x, y, d, window = small_part(seed, cone=False, noise=1e-6)
        r = np.hypot(x - 2.5, y)
        s = math.sqrt(30 / (len(x) / (np.ptp(x) * np.ptp(y))) / math.pi) / 1.5
        add = 0.2e-3 * np.exp(-r ** 2 / (2 * s * s))
        rep = report(x, y, d - add, window)
        assert rep["kept_as_form"] == 0, seed
        if seed in (4, 7):
            deep = set(np.flatnonzero(add > 0.1e-3).tolist())
            assert deep <= set(rep["removed_index"]), seed
