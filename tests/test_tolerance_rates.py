"""The verdict is a statistical decision: its error rates end to end (docs/tolerance.md, "Verdicts").

Repeated simulated CMM measurements (tests/test_uncertainty_sim.py: the issue's asphere on a raster,
fresh pose and fresh noise per repeat) of a part whose TRUE figures — the same recipe on the same
pose without noise — stand at a chosen ratio to the drawing's limits, run through the real pipeline
(core.pipeline.run_pipeline with the recipe's ``uncertainty:`` and ``tolerance:`` blocks, read from
``summary()["tolerance"]`` as the batch does). Per toleranced quantity the verdicts are counted.

ISO 14253-1:2017 guarded acceptance (acceptance zone = tolerance zone less the 95 % interval's
reach): a part exactly at its limit may be judged "conforms" only when the interval's upper end lies
below the truth, which a 95 % interval (probabilistically symmetric, JCGM 101 §7.7) allows with
probability ≤ 2.5 %; a part beyond its limit less often still. The simple rule (ILAC-G8 §4.2.1) judges
the value alone: at the limit it accepts about half the time. The full table (three ratios, 100
repeats) is benchmarks/bench_tolerance_rates.py.

What the benchmark found beyond this part (not tested here: 1–3 s a repeat): on the star scan
(star_probe) guarded acceptance at the limit reads RMS 8 % [3.5, 15.2] — the noise-free "truth" run's
misalignment leaves 6 of 1,080 points out of its pose fit (beyond 8 × 1.4826·MAD of the form itself),
the noisy runs none, so the truth is not what the noisy recipe measures (with exclude_beyond: null,
6 % [2.2, 12.6]); the probe compensation is transparent to the noise (bit-identical to 1e-8 µm without
it). On the radial scan with noise: auto (σ read 16 % high) RMS is over-corrected by 2.1 nm and accepted
12 % [4.8, 22.6] at its limit; with its σ given, 1.7 %. B's u is 0.6–0.7 × its scatter on every part
(the SIMEX correction's own spread), covered on the upper side by its interval's reach to the measured
value, not on the lower (3–7 % "lower end > truth").
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest

from .test_uncertainty_sim import CASES

#: the toleranced quantities: the summary's RMS (a plain limit) and the ISO 10110-5 ones of the form
#: "3/A(B/C) RMSi < D" — A linear, B an extreme value, C a smooth statistic, RMSi quadratic
#: (docs/uncertainty.md: each is bias-corrected as its kind asks)
QUANTITIES = ("rms_um", "sag_um", "irr_um", "rsi_um", "rmsi_um")
LABELS = {"rms_um": "RMS", "sag_um": "A (sag)", "irr_um": "B (irregularity)",
          "rsi_um": "C (rot. sym. irregularity)", "rmsi_um": "RMSi"}


def tolerance_block(limits: dict, rule: str = "guarded") -> str:
    """The recipe's ``tolerance:`` line: the ISO limits as a form in µm, RMS as a plain limit."""
    f = {k: f"{limits[k]:.12f}" for k in ("sag_um", "irr_um", "rsi_um", "rmsi_um")}
    form = f"3/{f['sag_um']}({f['irr_um']}/{f['rsi_um']}) RMSi < {f['rmsi_um']}"
    return f"{{form: \"{form}\", unit: um, rms_um: {limits['rms_um']!r}, rule: {rule}}}"


def recipe(case, uncertainty: str | None, tolerance: str):
    """Case.recipe's text (tests/test_uncertainty_sim.py) with a ``tolerance:`` block, parsed as a
    recipe file is (so its load-time checks run)."""
    from pointspro.core.recipe import parse_recipe
    from pointspro.core.yamlio import load_yaml

    d = case.diameter
    steps = []
    if case.probe_radius:
        steps.append(f"  - probe_radius: {{radius: {case.probe_radius}, side: 1}}")
    steps += ["  - misalignment: {}", f"  - aperture: {{diameter: {d * 0.98:.6g}}}",
              "  - zernike: {ordering: fringe, terms: 36, remove: [piston, tilt]}"]
    s = case.surface
    A = ", ".join(f"{k}: {v!r}" for k, v in s.A.items())
    text = (f"pointspro: 1\nsurface: {{type: even_asphere, c: {s.c!r}, k: {s.k!r}, A: {{{A}}}, "
            f"aperture: {d}}}\nsteps:\n" + "\n".join(steps) + f"\ntolerance: {tolerance}\n")
    if uncertainty:
        text += f"uncertainty: {uncertainty}\n"
    return parse_recipe(load_yaml(text, f"{case.name}.yaml"), f"{case.name}.yaml")


def _items(tolerance: dict) -> dict:
    return {i["quantity"]: i for i in tolerance["items"]}


def truth_of(case, clean) -> dict:
    """The true figures (µm; A as |A|, what its limit bounds): the recipe on the noise-free measurement."""
    from pointspro.core.pipeline import run_pipeline

    dummy = tolerance_block({k: 1.0 for k in QUANTITIES}, "simple")
    items = _items(run_pipeline(clean, recipe(case, None, dummy)).tolerance)  # (no summary: its slope spline)
    return {k: float(items[k]["value_um"]) for k in QUANTITIES}


def run_rates(case_name: str, ratio: float, repeats: int, samples: int, first_seed: int,
              noise: str | None = None, workers: int = 1) -> dict:
    """``repeats`` measurements (seeds first_seed…) of the case's part with its form scaled so that
    every true figure / its limit = ``ratio``: the limits are each repeat's true figures / ratio at
    form scale ``ratio`` (noise and pose fresh per repeat, the Monte Carlo's seed the repeat's).

    Returns per quantity the records of each repeat: truth, limit, the Monte Carlo's value, measured,
    u, U95, interval and the verdicts — ``guarded`` as summary.tolerance gives it, and ``simple``:
    the same summary.uncertainty block decided by the same block with ``rule: simple``
    (ToleranceSpec.decide, what core.assessment calls); ``plain``: the simple rule on the value of a
    recipe without an uncertainty block (the measured figure, noise bias and all). The pipeline's
    own guarded verdict is checked against ToleranceSpec.decide on the same block."""
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.tolerance import parse_tolerance
    from pointspro.core.tolerance.decision import item_verdict
    from pointspro.core.yamlio import load_yaml

    base = CASES[case_name]
    case = dataclasses.replace(base, form_rms_nm=base.form_rms_nm * ratio)
    rec = {k: [] for k in QUANTITIES}
    overall, sigma = [], []
    t0 = time.perf_counter()
    for r in range(repeats):
        seed = first_seed + r
        noisy, clean = case.measure(seed)
        truth = truth_of(case, clean)
        limits = {k: truth[k] / ratio for k in QUANTITIES}
        block = (f"{{samples: {samples}, seed: {seed}, workers: {workers}"
                 + (f", noise: {noise}" if noise else "") + "}")
        tol = tolerance_block(limits)
        s = run_pipeline(noisy, recipe(case, block, tol)).summary()
        items, unc = _items(s["tolerance"]), s["uncertainty"]
        values = {k: (items[k].get("signed_value_um", items[k]["value_um"])) for k in QUANTITIES}
        again = parse_tolerance(load_yaml(tol, "t.yaml"), "t.yaml").decide(values, unc)
        assert [i["verdict"] for i in again["items"]] == [i["verdict"] for i in s["tolerance"]["items"]]
        simple = _items(parse_tolerance(load_yaml(tolerance_block(limits, "simple"), "t.yaml"), "t.yaml")
                        .decide(values, unc))
        overall.append(s["tolerance"]["verdict"])
        sigma.append((unc["_meta"]["noise_sigma_um"], unc["_meta"]["noise_sigma_u_rel"]))
        for k in QUANTITIES:
            e, it = unc[k], items[k]
            measured = abs(e["measured"]) if k == "sag_um" else e["measured"]
            rec[k].append({"truth": truth[k], "limit": limits[k], "value": it["value_um"],
                           "measured": measured, "u": e["u"], "U95": e["U95"],
                           "interval": tuple(it["interval95"]), "guarded": it["verdict"],
                           "simple": simple[k]["verdict"],
                           "plain": item_verdict(measured, None, limits[k], "simple")[0]})
    return {"case": case_name, "ratio": ratio, "repeats": repeats, "samples": samples,
            "seconds": time.perf_counter() - t0, "records": rec, "overall": overall, "sigma": sigma,
            "noise_nm": case.noise_nm}


def rate(records, rule: str, verdict: str) -> tuple[int, int]:
    return sum(r[rule] == verdict for r in records), len(records)


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper–Pearson) two-sided binomial interval of k successes in n."""
    from scipy.stats import beta

    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def diagnostics(records) -> dict:
    """Bias of the corrected and the plain value against the truth, their scatter, mean u, the
    interval's coverage and its misses on either side."""
    d = np.array([r["value"] - r["truth"] for r in records])
    p = np.array([r["measured"] - r["truth"] for r in records])
    return {"bias": float(d.mean()), "se": float(d.std(ddof=1) / math.sqrt(d.size)),
            "plain_bias": float(p.mean()), "scatter": float(d.std(ddof=1)),
            "plain_scatter": float(p.std(ddof=1)),
            "u": float(np.mean([r["u"] for r in records])),
            "coverage": float(np.mean([r["interval"][0] <= r["truth"] <= r["interval"][1] for r in records])),
            "miss_low": float(np.mean([r["interval"][1] < r["truth"] for r in records])),
            "miss_high": float(np.mean([r["interval"][0] > r["truth"] for r in records])),
            "truth": float(np.mean([r["truth"] for r in records]))}


# -- the tests: the issue's part at its limits, and well inside -----------------------------------------

#: repeats at the limit and well inside, and the seeds (the benchmark's start at 20,000). 50 Monte Carlo
#: samples each (the least the recipe allows): about 1.1 s a repeat on 2 idle cores, ~40 s in all
AT_LIMIT, INSIDE, SAMPLES = 30, 8, 50
#: guarded acceptance's claim: a part at its limit is accepted only when the 95 % interval's upper end
#: falls below the truth, P ≤ 2.5 %. With 30 repeats, 4 or more acceptances of one quantity happen with
#: probability 0.64 % if its rate were exactly 2.5 % (binomial; less for any smaller rate): the slack.
#: Measured here: RMS, B, C, RMSi 0 of 30, A 1 of 30 (benchmark, 100 repeats: 0, 2, 0, 0, 0 %); with the
#: guard band removed from decision.py: 12–18 of 30
MAX_ACCEPTED = 3
#: the simple rule at the limit accepts whenever the corrected value falls at or below the truth: about
#: half the time. 8…22 of 30 holds a rate of 50 % with probability 99.5 %; a guard band that went
#: missing from the guarded rule would make it accept as often as this. Measured here: 12–18 of 30
SIMPLE_RANGE = (8, 22)


@pytest.fixture(scope="module")
def at_limit():
    return run_rates("issue", 1.0, AT_LIMIT, SAMPLES, 7_000, workers=2)


def test_guarded_acceptance_rarely_accepts_a_part_at_its_limit(at_limit):
    """ISO 14253-1: a part whose true figure is at its limit (and so any part beyond it) is judged
    "conforms" with probability ≤ 2.5 %, per toleranced quantity, through the whole pipeline."""
    accepted = {k: rate(at_limit["records"][k], "guarded", "conforms")[0] for k in QUANTITIES}
    assert all(v <= MAX_ACCEPTED for v in accepted.values()), (accepted, AT_LIMIT)
    assert sum(v == "conforms" for v in at_limit["overall"]) <= MAX_ACCEPTED


def test_the_simple_rule_accepts_about_half_the_parts_at_their_limit(at_limit):
    """The simple rule's known false acceptance at the limit (~50 %, ILAC-G8 §4.2.1: w = 0), on the
    same Monte Carlo: the guard band is what brings the guarded rule's rate down."""
    lo, hi = SIMPLE_RANGE
    for k in QUANTITIES:
        simple = rate(at_limit["records"][k], "simple", "conforms")[0]
        guarded = rate(at_limit["records"][k], "guarded", "conforms")[0]
        assert lo <= simple <= hi, (k, simple, AT_LIMIT)
        assert guarded <= simple - 5, (k, guarded, simple)


def test_the_parts_at_the_limit_are_rarely_rejected_and_the_interval_holds_the_truth(at_limit):
    """The other side of the same interval: a part at its limit conforms (≤), and is judged "does not
    conform" only when the interval's lower end passes the truth (≤ 2.5 %, the same slack); the
    interval holds the truth (≥ 85 % of 30: 3 binomial standard deviations below 95 %). And the
    figures whose noise-bias correction is exact by construction — RMS and RMSi (quadratic), A
    (linear, none) — are unbiased within 3 standard errors: a correction that overshoots lowers the
    interval and lets parts at their limit pass (benchmarks/bench_tolerance_rates.py: the star scan
    with probe compensation, RMS 1.2 nm low, accepted 8–10 % at the limit). B and C are corrected
    approximately (docs/uncertainty.md) and are held to the rates alone."""
    for k in QUANTITIES:
        rec = at_limit["records"][k]
        assert rate(rec, "guarded", "does not conform")[0] <= MAX_ACCEPTED, k
        d = diagnostics(rec)
        assert d["coverage"] >= 0.85, (k, d)
        if k in ("rms_um", "rmsi_um", "sag_um"):
            assert abs(d["bias"]) <= 3 * d["se"], (k, d)


def test_a_part_well_inside_conforms_and_is_never_rejected():
    """True figures at 0.6 × their limits: every quantity conforms (the guard band costs nothing
    there), never "does not conform" — the 2.5 % the rule allows at the limit is ~0 this far inside."""
    run = run_rates("issue", 0.6, INSIDE, SAMPLES, 8_000, workers=2)
    for k in QUANTITIES:
        rec = run["records"][k]
        assert rate(rec, "guarded", "does not conform")[0] == 0, k
        assert rate(rec, "guarded", "conforms")[0] >= INSIDE - 1, (k, [r["guarded"] for r in rec])
    assert sum(v == "conforms" for v in run["overall"]) >= INSIDE - 1
