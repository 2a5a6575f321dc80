"""Issue 23 (part 1): the Monte Carlo's speed on the example and its coverage on repeated simulations.

    .venv/bin/python benchmarks/bench_uncertainty.py speed [--best-of 3]
    .venv/bin/python benchmarks/bench_uncertainty.py coverage [--repeats 100] [--samples 200] [--cases issue,...]

speed: the example recipe (resources/example) + `uncertainty: {samples: 200, seed: 1}` end to end
(read, steps, Monte Carlo), best of N, and the same recipe without the block in the same run (the
ratio is what carries across machines). Goal: ≤ 30 s on 2 cores.

coverage: per case of tests/test_uncertainty_sim.py (the issue's asphere: 195 nm RMS form, 50 nm
noise, 1,961 points; a star scan with probe compensation; a radial scan with mid-spatial form),
`repeats` measurements with fresh pose and noise (seeds 1000…), each run with `samples` Monte Carlo
samples; the noise-free measurement of the same pose through the same recipe is the truth. Reports
the fraction of 95 % intervals that contain the truth (goal ≥ 93 %), the plain and corrected
figures' mean error, and the mean u against the scatter of (corrected − truth).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.test_uncertainty_sim import KEYS  # noqa: E402


def speed(best_of: int) -> None:
    from pointspro.core.io import read_cloud
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import parse_recipe
    from pointspro.core.yamlio import load_yaml

    ex = ROOT / "resources" / "example"
    text = (ex / "recipe.yaml").read_text(encoding="utf-8")
    plain = parse_recipe(load_yaml(text, "recipe.yaml"), "recipe.yaml")
    unc = parse_recipe(load_yaml(text + "uncertainty: {samples: 200, seed: 1}\n", "recipe.yaml"), "recipe.yaml")
    t_plain, t_unc = [], []
    for _ in range(best_of):
        t = time.perf_counter()
        run_pipeline(read_cloud(ex / "asphere_cmm.csv"), plain)
        t_plain.append(time.perf_counter() - t)
        t = time.perf_counter()
        res = run_pipeline(read_cloud(ex / "asphere_cmm.csv"), unc)
        t_unc.append(time.perf_counter() - t)
    m = res.summary()["uncertainty"]["_meta"]
    print(f"example + uncertainty (200 samples, {m['workers']} workers): best {min(t_unc):.2f} s "
          f"(all {', '.join(f'{x:.2f}' for x in t_unc)}); the recipe alone best {min(t_plain):.2f} s; "
          f"ratio {min(t_unc) / min(t_plain):.1f}")
    b = res.summary()["uncertainty"]
    for k in ("rms_um", "pv_um", "pvr_um", "slope_rms_urad"):
        e = b[k]
        print(f"  {k:15s} measured {e['measured']:.4f}  corrected {e['value']:.4f} ± {e['U95']:.4f} (k = 2)")


def coverage(case_name: str, repeats: int, samples: int) -> dict:
    from tests.test_uncertainty_sim import run_coverage

    return run_coverage(case_name, repeats, samples)


def print_coverage(res: dict) -> None:
    print(f"\ncase {res['case']}: {res['repeats']} repeats × {res['samples']} samples, {res['seconds']:.0f} s; "
          f"σ estimated {res['sigma_nm'][0]:.1f} nm (true {res['sigma_nm'][1]:g} nm)")
    print("| figure | coverage 95 % | plain bias | corrected bias | scatter | mean u | u/scatter |")
    print("|---|---|---|---|---|---|---|")
    for k in KEYS:
        r = res[k]
        f = 1e3 if k.endswith("_um") else 1.0
        unit = "nm" if k.endswith(("_um", "_nm")) else "µrad"
        print(f"| {k} | {100 * r['coverage']:.0f} % | {f * r['plain_bias']:+.2f} {unit} | "
              f"{f * r['corrected_bias']:+.2f} {unit} | {f * r['scatter']:.2f} {unit} | {f * r['u']:.2f} {unit} | "
              f"{r['u_over_scatter']:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=["speed", "coverage"])
    ap.add_argument("--best-of", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=100)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--cases", default="issue,star_probe,radial_mid")
    a = ap.parse_args()
    if a.what == "speed":
        speed(a.best_of)
    else:
        for c in a.cases.split(","):
            print_coverage(coverage(c, a.repeats, a.samples))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
