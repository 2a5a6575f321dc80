"""`explain` out of sample (issue 16 part 2): every hidden effect of tests/test_explain_cases.py on
every surface × scan, at seeds the tests do not use.

    .venv/bin/python benchmarks/bench_explain_cases.py [--seed-offset 777] [--scale 1.0]

The tests hide each effect on one surface and one scan, chosen where it shows; here each is hidden on
all four surfaces (rotational asphere, anamorphic asphere, steep convex conic, Forbes Q-con) and three
scans (inward spiral, outward spiral, raster), 2 nm noise, amplitudes × ``--scale``. Each case is
counted as
  right       the effect is named first (a spindle error with exactly its harmonics), gap down to the noise;
  ambiguous   another effect is named first, reported ambiguous with the hidden one (their signatures
              coincide on that scan: the report says so and how to separate them);
  invisible   the effect leaves no gap above the noise on that scan (gap ≤ 1.05 σ) and nothing is named;
  wrong       anything else.
About 2 s a case, ~7 minutes for the 200.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import test_explain_cases as T  # noqa: E402 — the tests' cases, simulator and helpers

SURFACES = {"asphere": T.ASPHERE, "anamorphic": T.ANAMORPHIC, "steep": T.STEEP, "qcon": T.QCON}
SCANS = {"spiral": T.SPIRAL, "outward": T.SPIRAL_OUT, "raster": T.RASTER}


def verdict(rep, name, params) -> str:
    found = T.names(rep)
    noise_nm = T.NOISE * 1e6
    if found[:1] == [name]:
        ok = rep["gap_after"]["rms_um"] * 1e3 <= 1.1 * noise_nm
        if name.startswith("spindle"):
            ok = ok and rep["found"][0]["harmonics"] == T.harmonics_of(params) and found == [name]
        return "right" if ok else "wrong"
    if found and any(set(a["effects"]) == {found[0], name} for a in rep["ambiguous_with"]):
        return "ambiguous"
    if not found and rep["gap_before"]["rms_um"] * 1e3 <= 1.05 * noise_nm:
        return "invisible"
    return "wrong"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed-offset", type=int, default=777)
    ap.add_argument("--scale", type=float, default=1.0, help="amplitudes × this")
    args = ap.parse_args()
    tally = Counter()
    print("| effect | surface | scan | verdict | named | gap before nm | gap after nm |\n|---|---|---|---|---|---:|---:|")
    t0 = time.perf_counter()
    for case, (_, _, hidden, seed) in sorted(T.ONE.items()):
        (name, params), = hidden.items()
        params = {k: v * args.scale if isinstance(v, float) and k not in ("frequency_hz", "phase_deg") else v
                  for k, v in params.items()}
        for sn, surface in SURFACES.items():
            for cn, scan in SCANS.items():
                with tempfile.TemporaryDirectory() as d:
                    rep = T.run(Path(d), surface, scan, [{name: params}], seed=seed + args.seed_offset)
                v = verdict(rep, name, params)
                tally[v] += 1
                print(f"| {case} | {sn} | {cn} | {v} | {', '.join(T.names(rep)) or '—'} | "
                      f"{rep['gap_before']['rms_um'] * 1e3:.2f} | {rep['gap_after']['rms_um'] * 1e3:.2f} |",
                      flush=True)
    n = sum(tally.values())
    print(f"\n{n} cases in {time.perf_counter() - t0:.0f} s: " +
          ", ".join(f"{k} {tally[k]}" for k in ("right", "ambiguous", "invisible", "wrong")))


if __name__ == "__main__":
    main()
