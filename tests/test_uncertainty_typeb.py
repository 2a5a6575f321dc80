"""A type-B source's own variance is not noise bias (core/uncertainty/estimate.py, _cv): a source
acting quadratically on a mean-square figure (a z-scale error adds (ε·power)² to RMS²) must not be
subtracted from the figure as if it were noise."""
import numpy as np
import pytest

from pointspro.core.uncertainty.estimate import estimate


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("c", [0.0, 0.3, 1.0])
def test_quadratic_type_b_effect_is_not_taken_for_noise(seed, c):
    rng = np.random.default_rng(seed)
    truth, sigma, M = 0.46, 0.3, 200
    f0 = np.sqrt(truth**2 + sigma**2)                       # the measured RMS, inflated by the noise
    Z = rng.standard_normal((M, 2))                          # two type-B sources' standard draws
    # samples: the data's noise plus as much again, the first source quadratic, the second linear
    g = f0**2 + sigma**2 + (c * Z[:, 0]) ** 2 + 0.02 * Z[:, 1] + 0.001 * rng.standard_normal(M)
    e = estimate("rms_um", "quadratic", f0, np.sqrt(g), Z)
    assert e["value"] == pytest.approx(truth, abs=0.01)
    assert not e.get("below_noise")


@pytest.mark.parametrize("M", [50, 100, 200])
def test_interval_ends_give_95_percent_for_a_new_draw_at_finite_M(M):
    """The interval's ends (order statistics) hold a further draw of the same distribution with
    probability ≥ 95 % — np.quantile's interpolated 2.5/97.5 % points hold it ~93 % at M = 100."""
    from pointspro.core.uncertainty.estimate import _quantiles

    rng = np.random.default_rng(7)
    trials = 20_000
    samples = rng.standard_normal((trials, M))
    new = rng.standard_normal(trials)
    ends = np.array([_quantiles(s) for s in samples])
    cover = np.mean((ends[:, 0] <= new) & (new <= ends[:, 1]))
    assert 0.945 <= cover <= 0.975  # binomial sd 0.15 % at 20,000 trials
    q = np.quantile(samples, [0.025, 0.975], axis=1)
    interp = np.mean((q[0] <= new) & (new <= q[1]))
    assert interp < cover  # the interpolated percentiles cover less
