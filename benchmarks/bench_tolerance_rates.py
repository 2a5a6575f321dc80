"""The verdict's error rates end to end (docs/tolerance.md, "Verdicts"; tests/test_tolerance_rates.py).

    .venv/bin/python benchmarks/bench_tolerance_rates.py [--repeats 100] [--samples 50]
        [--ratios 1,1.05,0.6] [--case issue|star_probe|radial_mid] [--noise "50 nm"] [--out rates.json]
    .venv/bin/python benchmarks/bench_tolerance_rates.py --load rates.json     # print a saved run again

Repeated simulated measurements (a case of tests/test_uncertainty_sim.py — by default the issue's
asphere: 1,961 points on a raster, 195 nm RMS polishing form, 50 nm noise; fresh pose and noise per
repeat, fixed seeds) of parts whose TRUE figures — the same recipe on the noise-free measurement of
the same pose — stand at ``ratio`` × their limits (the form scaled by the ratio, the limits each
repeat's true figures / ratio), run through core.pipeline.run_pipeline with ``uncertainty:`` (noise:
auto unless --noise) and ``tolerance: {form: "3/A(B/C) RMSi < D", unit: um, rms_um: …}``. Per quantity
the verdicts of summary.tolerance are counted (guarded, ISO 14253-1) with exact (Clopper–Pearson) 95 %
binomial intervals, beside the simple rule decided on the same Monte Carlo (the corrected value alone)
and on the plain measured value (what a recipe without an uncertainty block compares). Then why: the
corrected value's bias against the truth, the plain one's, the repeats' scatter against the mean u,
the 95 % interval's coverage and misses (an upper end below the truth is what lets a part at its
limit pass), the quadratic figures' noise bias (of f²) against the Monte Carlo's estimate of it, and
noise: auto's σ against the truth. Prints markdown.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.test_tolerance_rates import LABELS, QUANTITIES, clopper_pearson, diagnostics, rate, run_rates  # noqa: E402

NAMES = {1.0: "at the limit", 1.05: "5 % above the limit", 0.6: "well inside (0.6 × limit)"}
VERDICTS = ("conforms", "does not conform", "undecided")
QUADRATIC = ("rms_um", "rmsi_um")


def pct(k: int, n: int) -> str:
    lo, hi = clopper_pearson(k, n)
    return f"{100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def report(runs: list[dict], title: str, total: float | None = None) -> None:
    print(f"\n### Verdict rates: {title}\n")
    print("Per quantity, the verdict of summary.tolerance (guarded, ISO 14253-1:2017) with its exact "
          "binomial 95 % interval; `simple`: the simple rule on the same Monte Carlo's corrected value; "
          "`plain simple`: on the measured value (a recipe without `uncertainty:`).\n")
    print("| case | quantity | true / limit | repeats | P(conforms) | P(does not conform) | P(undecided) "
          "| simple: P(conforms) | plain simple: P(conforms) | seconds |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for run in runs:
        name = NAMES.get(run["ratio"], f"{run['ratio']:g} × limit")
        for k in QUANTITIES:
            rec = run["records"][k]
            g = [pct(*rate(rec, "guarded", v)) for v in VERDICTS]
            print(f"| {name} | {LABELS[k]} | {run['ratio']:g} | {len(rec)} | {g[0]} | {g[1]} | {g[2]} "
                  f"| {pct(*rate(rec, 'simple', 'conforms'))} | {pct(*rate(rec, 'plain', 'conforms'))} "
                  f"| {run['seconds']:.0f} |")
        ov = run["overall"]
        n, k_c, k_n = len(ov), sum(v == VERDICTS[0] for v in ov), sum(v == VERDICTS[1] for v in ov)
        print(f"| {name} | **overall** (all five) | {run['ratio']:g} | {n} | {pct(k_c, n)} | {pct(k_n, n)} "
              f"| {pct(n - k_c - k_n, n)} | | | {run['seconds']:.0f} |")

    print("\n### Why: the corrected value against the truth (µm), u against the repeats' scatter\n")
    print("| true / limit | quantity | truth | corrected bias ± se | plain bias | scatter | plain scatter "
          "| mean u | u / scatter | 0.05 × limit / u | coverage | upper end < truth | lower end > truth |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for run in runs:
        for k in QUANTITIES:
            d = diagnostics(run["records"][k])
            lim = d["truth"] / run["ratio"]
            print(f"| {run['ratio']:g} | {LABELS[k]} | {d['truth']:.4f} | {d['bias']:+.5f} ± {d['se']:.5f} "
                  f"| {d['plain_bias']:+.5f} | {d['scatter']:.5f} | {d['plain_scatter']:.5f} | {d['u']:.5f} "
                  f"| {d['u'] / d['scatter']:.2f} | {0.05 * lim / d['u']:.1f} | {100 * d['coverage']:.0f} % "
                  f"| {100 * d['miss_low']:.1f} % | {100 * d['miss_high']:.1f} % |")

    print("\n### The quadratic figures' noise-bias correction, and noise: auto's σ\n")
    print("Noise bias of f² (nm²): actual = mean(measured² − truth²) over the repeats; the Monte Carlo's "
          "estimate = mean(measured² − corrected²). A ratio above 1 over-corrects: the corrected value "
          "and its interval sit low.\n")
    print("| true / limit | quantity | actual bias of f² | Monte Carlo's estimate | ratio | σ̂ / σ (mean) "
          "| σ̂'s relative sd | its stated u_rel |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for run in runs:
        sig = np.array(run.get("sigma") or [(np.nan, np.nan)], dtype=float)
        s_hat = sig[:, 0] * 1e3 / run["noise_nm"] if "noise_nm" in run else np.array([np.nan])
        for k in QUADRATIC:
            rec = run["records"][k]
            f0, t, fc = (np.array([r[n] for r in rec]) for n in ("measured", "truth", "value"))
            a, b = (f0**2 - t**2) * 1e6, (f0**2 - fc**2) * 1e6
            se = lambda x: x.std(ddof=1) / np.sqrt(x.size)  # noqa: E731
            print(f"| {run['ratio']:g} | {LABELS[k]} | {a.mean():.0f} ± {se(a):.0f} | {b.mean():.0f} ± {se(b):.0f} "
                  f"| {b.mean() / a.mean():.2f} | {np.mean(s_hat):.3f} "
                  f"| {100 * np.std(s_hat, ddof=1) / np.mean(s_hat) if s_hat.size > 1 else np.nan:.1f} % "
                  f"| {100 * np.mean(sig[:, 1]):.1f} % |")
    if total is not None:
        n = sum(r["repeats"] for r in runs)
        print(f"\nTotal {total:.0f} s ({total / n:.2f} s a repeat: the noise-free run, the pipeline and its "
              f"{runs[0]['samples']}-sample Monte Carlo).")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=100)
    ap.add_argument("--samples", type=int, default=50)
    ap.add_argument("--ratios", default="1,1.05,0.6")
    ap.add_argument("--case", default="issue")
    ap.add_argument("--noise", default=None, help='σ given in the recipe (e.g. "50 nm"); default noise: auto')
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--first-seed", type=int, default=20_000)
    ap.add_argument("--out", default=None, help="write every repeat's records as JSON here")
    ap.add_argument("--load", default=None, help="print the tables of a run saved with --out")
    a = ap.parse_args(argv)
    if a.load:
        saved = json.loads(Path(a.load).read_text(encoding="utf-8"))
        runs, total = saved["runs"], saved.get("total_s")
        report(runs, saved["title"], total)
        return
    ratios = [float(r) for r in a.ratios.split(",")]
    t0 = time.perf_counter()
    runs = []
    for j, ratio in enumerate(ratios):
        runs.append(run_rates(a.case, ratio, a.repeats, a.samples, a.first_seed + 10_000 * j,
                              noise=a.noise, workers=a.workers))
        print(f"<!-- ratio {ratio:g}: {runs[-1]['seconds']:.0f} s -->", flush=True)
    total = time.perf_counter() - t0
    title = (f"case `{a.case}`, {a.repeats} repeats per ratio, {a.samples} Monte Carlo samples, noise "
             f"{'given ' + a.noise if a.noise else 'auto'}")
    report(runs, title, total)
    if a.out:
        Path(a.out).write_text(json.dumps({"title": title, "total_s": total, "runs": runs}, indent=1),
                               encoding="utf-8")


if __name__ == "__main__":
    main()
