"""Simulated CMM measurements of aspheres for the uncertainty tests and benchmark (issue 23).

Each case: a nominal asphere, a scan pattern, a polishing form error of a given RMS, a fresh pose per
repeat and fresh noise N(0, σ²) on the measured z; the noise-free measurement of the same pose gives the
true figures (the same recipe on it). Sizes are kept near 1,000–2,000 points so the Monte Carlo stays
affordable in the tests.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pointspro.core.cloud import PointCloud
from pointspro.core.geometry import Pose
from pointspro.core.recipe import parse_recipe
from pointspro.core.yamlio import load_yaml

from .paper002 import DATA1_SURFACE, DATA2_SURFACE, TABLE1_SURFACE, radial, raster, star


def _form(x, y, radius, rms_mm, kind):
    r = np.hypot(x, y) / radius
    t = np.arctan2(y, x)
    if kind == "low":  # astigmatism, trefoil, a zone: the polishing form
        w = 1.2 * r ** 2 * np.cos(2 * (t - 0.4)) + 0.6 * r ** 3 * np.cos(3 * t + 1.0) \
            + 0.7 * np.exp(-((r - 0.62) / 0.08) ** 2) - 0.3 * r ** 4
    else:  # mid-spatial: rings and a 7-lobed ripple on top of astigmatism
        w = 0.8 * r ** 2 * np.cos(2 * t) + 0.4 * np.sin(2 * np.pi * r * 6) * r \
            + 0.3 * np.cos(7 * t) * r ** 3
    w = w - w.mean()
    return w / np.sqrt(np.mean(w * w)) * rms_mm


@dataclass(frozen=True)
class Case:
    name: str
    surface: object
    pattern: str
    diameter: float
    form_rms_nm: float
    noise_nm: float
    form: str = "low"
    probe_radius: float | None = None

    def points(self):
        if self.pattern == "raster":
            return raster(self.diameter, 12.0 * self.diameter / 600)
        if self.pattern == "star":
            return star(self.diameter, 12, self.diameter / 90)
        return radial(self.diameter, 24, 1200)

    def recipe(self, uncertainty: str | None = None):
        d = self.diameter
        steps = []
        if self.probe_radius:  # contact points, still in the measuring frame: the pose comes next
            steps.append(f"  - probe_radius: {{radius: {self.probe_radius}, side: 1}}")
        steps.append("  - misalignment: {}")
        steps.append(f"  - aperture: {{diameter: {d * 0.98:.6g}}}")
        steps.append("  - zernike: {ordering: fringe, terms: 36, remove: [piston, tilt]}")
        s = self.surface
        A = ", ".join(f"{k}: {v!r}" for k, v in s.A.items())
        text = (f"pointspro: 1\nsurface: {{type: even_asphere, c: {s.c!r}, k: {s.k!r}, A: {{{A}}}, "
                f"aperture: {d}}}\nsteps:\n" + "\n".join(steps) + "\n")
        if uncertainty:
            text += f"uncertainty: {uncertainty}\n"
        return parse_recipe(load_yaml(text, f"{self.name}.yaml"), f"{self.name}.yaml")

    def measure(self, seed: int, noise: bool = True):
        """(noisy, noise-free) clouds of repeat ``seed``: fresh pose and noise."""
        rng = np.random.default_rng(seed)
        x, y = self.points()
        e = _form(x, y, self.diameter / 2, self.form_rms_nm * 1e-6, self.form)
        pose = Pose(rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.5, 0.5),
                    rng.uniform(-0.5, 0.5), rng.uniform(-1.0, 1.0))
        p = np.column_stack([x, y, self.surface.sag(x, y) + e])
        if self.probe_radius:
            fx, fy = self.surface.gradient(x, y)
            m = np.column_stack([-fx, -fy, np.ones_like(x)])
            p = p + self.probe_radius * m / np.linalg.norm(m, axis=1)[:, None]
        clean = pose.to_measuring(p)
        noisy = clean.copy()
        noisy[:, 2] += rng.normal(0.0, self.noise_nm * 1e-6, len(x))
        return PointCloud.from_numpy(noisy), PointCloud.from_numpy(clean)


CASES = {
    # the set-up: 195 nm RMS form, 50 nm noise, 1,961 points on a raster, fresh pose each
    "issue": Case("issue", DATA1_SURFACE, "raster", 600.0, 195.0, 50.0),
    "star_probe": Case("star_probe", TABLE1_SURFACE, "star", 1300.0, 300.0, 80.0, probe_radius=4.0),
    "radial_mid": Case("radial_mid", DATA2_SURFACE, "radial", 1000.0, 120.0, 40.0, form="mid"),
}


KEYS = ("rms_um", "pv_um", "pvr_um", "slope_rms_urad", "zernike.Z5_nm", "zernike.Z9_nm")


def run_coverage(case_name: str, repeats: int, samples: int, workers: int | None = None,
                 first_seed: int = 1000, noise: str | None = None) -> dict:
    """``repeats`` measurements of one case (seeds first_seed…), each with ``samples`` Monte Carlo
    samples; per figure the 95 % intervals' hits of the noise-free value, the plain and corrected
    errors and u. The noise-free figures: the same recipe on the same pose without noise."""
    import time

    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.uncertainty.montecarlo import report_figures

    case = CASES[case_name]
    block = (f"{{samples: {samples}, seed: 7" + (f", workers: {workers}" if workers else "")
             + (f", noise: {noise}" if noise else "") + "}")
    rec_u, rec = case.recipe(block), case.recipe()
    rows = {k: {"hit": [], "plain": [], "corr": [], "u": []} for k in KEYS}
    sig = []
    t0 = time.perf_counter()
    for s in range(repeats):
        noisy, clean = case.measure(first_seed + s)
        b = run_pipeline(noisy, rec_u).summary()["uncertainty"]
        sig.append(b["_meta"]["noise_sigma_um"] * 1e3)
        tr = run_pipeline(clean, rec)
        truth = dict(tr.summary())
        truth.update(report_figures({i + 1: st.report for i, st in enumerate(tr.steps)}, None))
        for k in KEYS:
            e = b[k]
            lo, hi = e["interval95"]
            rows[k]["hit"].append(lo <= truth[k] <= hi)
            rows[k]["plain"].append(e["measured"] - truth[k])
            rows[k]["corr"].append(e["value"] - truth[k])
            rows[k]["u"].append(e["u"])
    out = {"case": case_name, "repeats": repeats, "samples": samples, "seconds": time.perf_counter() - t0,
           "sigma_nm": (float(np.mean(sig)), case.noise_nm), "rows": rows}
    for k in KEYS:
        r = rows[k]
        scatter = float(np.std(r["corr"], ddof=1))
        out[k] = {"coverage": float(np.mean(r["hit"])), "plain_bias": float(np.mean(r["plain"])),
                  "corrected_bias": float(np.mean(r["corr"])), "scatter": scatter,
                  "u": float(np.mean(r["u"])), "u_over_scatter": float(np.mean(r["u"])) / scatter}
    return out
