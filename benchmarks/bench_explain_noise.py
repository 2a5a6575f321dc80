"""`explain` on gaps of coloured noise with no effect in them (issue 16 part 2): how often an effect is
named, with the correlated-noise gate (core/explain/select.py `_correlated_noise_gate`) and without.

    .venv/bin/python benchmarks/bench_explain_noise.py [--seeds 40] [--scans spiral,raster_big]

The selection's F tests assume white noise; a probe's lag or an interferometer's drift is not. Each
gap is noise of marginal σ 2 nm along the scan (in time order), of one kind: white, white with 4
spikes of 8–15 σ, AR(1) at ρ 0.5 / 0.8 / −0.5, AR(2) (φ 1.4, −0.5), flicker 1/f and 1/f^1.5. A count
above the binomial 99.9 % bound at α (2 of 40 for α = 0.01) means the rate the selection claims does
not hold on that noise. Seeds 7000 + k (not the tests'). About a minute for the defaults.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats
from scipy.signal import lfilter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pointspro.core.explain import select as S  # noqa: E402
from tests.test_explain_rates import NOISE, SCANS, scan_context  # noqa: E402

MORE_SCANS = {
    "spiral_big": {"type": "spiral", "radius": 20.0, "rpm": 60.0, "pitch": 0.4, "fs": 100.0},
    "raster_big": {"type": "raster", "radius": 20.0, "spacing": 0.5, "lines": 25, "speed": 10.0},
}
KINDS = ("white", "spikes", "ar1_0.5", "ar1_0.8", "ar1_-0.5", "ar2", "flicker", "flicker_1.5")


def noise(n: int, kind: str, rng: np.random.Generator) -> np.ndarray:
    """n samples of noise of marginal σ NOISE, in time order."""
    if kind in ("white", "spikes"):
        e = rng.normal(0.0, NOISE, n)
        if kind == "spikes":
            at = rng.choice(n, 4, replace=False)
            e[at] += rng.choice([-1.0, 1.0], 4) * rng.uniform(8.0, 15.0, 4) * NOISE
        return e
    if kind.startswith("ar1_"):
        rho = float(kind[4:])
        w = rng.normal(0.0, NOISE * np.sqrt(1.0 - rho * rho), n)
        w[0] = rng.normal(0.0, NOISE)  # started in its stationary state
        return lfilter([1.0], [1.0, -rho], w)
    if kind == "ar2":
        e = lfilter([1.0], [1.0, -1.4, 0.5], rng.normal(0.0, 1.0, n + 500))[500:]
    else:  # flicker: power ∝ 1/f (or 1/f^1.5), a window of n out of a series 8 times longer — not
        # periodic over the scan, as an instrument's drift is not (a spectrum shaped over n samples
        # alone makes the series wrap around, which a frequency-domain noise model fits exactly)
        slope = 1.0 if kind == "flicker" else 1.5
        m = 8 * n
        spec = np.fft.rfft(rng.normal(0.0, 1.0, m))
        f = np.arange(spec.size, dtype=np.float64)
        f[0] = 1.0
        long = np.fft.irfft(spec / f ** (slope / 2), m)
        start = int(rng.integers(0, m - n))
        e = long[start: start + n]
        e = e - e.mean()
    return e * NOISE / np.std(e)


def named(ctx, kind: str, seeds, gate: bool) -> int:
    order = np.argsort(ctx.t, kind="stable")
    saved = S.RHO_GATE
    S.RHO_GATE = saved if gate else np.inf
    try:
        count = 0
        for seed in seeds:
            g = np.empty(ctx.x.size)
            g[order] = noise(ctx.x.size, kind, np.random.default_rng(seed))
            count += bool(S.select(ctx, g, bootstrap=0)["found"])
        return count
    finally:
        S.RHO_GATE = saved


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--scans", default="spiral,raster_big")
    args = ap.parse_args()
    seeds = range(7000, 7000 + args.seeds)
    bound = int(stats.binom.ppf(0.999, args.seeds, S.ALPHA))
    print(f"gaps in which an effect is named, of {args.seeds} (without the gate → with it); "
          f"the rate's bound at α = {S.ALPHA}: {bound}\n")
    print("| scan (points) | " + " | ".join(KINDS) + " |")
    print("|---|" + "---:|" * len(KINDS))
    for name in args.scans.split(","):
        ctx = scan_context({**SCANS, **MORE_SCANS}[name])
        t0 = time.perf_counter()
        cells = [f"{named(ctx, k, seeds, False)} → {named(ctx, k, seeds, True)}" for k in KINDS]
        print(f"| {name} ({ctx.x.size:,}) | " + " | ".join(cells) + f" |  ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
