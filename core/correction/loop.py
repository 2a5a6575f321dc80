"""A machine with a repeatable error, to close the correction loop on (tests, benchmarks, demos).

A run cuts the *programmed* surface (the nominal plus every correction so far, a grid added by
bicubic interpolation) with the machine's repeatable error on top, written with the effects of
core.simulate (the same equations the simulator and `explain` use), evaluated at the point's
radius and polar angle (the spindle angle of a turned part):

    spindle_tilt   EBC lobes (arcsec): −r Σ (a_k cos kc + b_k sin kc)   synchronous, so repeatable
    squareness     EB0C (arcsec): −r·EB0C                              the X–C cone
    straightness   s2…s4 (mm at the rim): Σ s_k (r/R)^k                X-slide straightness
    probe_radius   the TOOL's radius error δ (mm): δ(√(1 + |∇f|²) − 1) (a tool δ larger than
                   programmed cuts −δ along the normal: −δ/cos θ vertically, less its piston)

The part is then measured on a scan path of core.simulate.scan with probe noise, set up with a small
random piston and tilt (what `misalignment` would leave), and handed back as the residual
z − sag_nominal(x, y) in the part frame — what the correction step reads.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cloud import PointCloud
from ..simulate.effects import ScanContext
from ..simulate.model import effects_dz
from ..simulate.scan import ScanSpec, scan_points


@dataclass
class Program:
    """The programmed surface: nominal sag plus the corrections added so far (grids, mm)."""

    nominal: object
    corrections: list = field(default_factory=list)   # [(xs, ys, dz)] with NaN-free dz

    def sag(self, x, y):
        from scipy.interpolate import RectBivariateSpline

        z = self.nominal.sag(x, y)
        for xs, ys, dz in self.corrections:
            f = RectBivariateSpline(ys, xs, dz, kx=3, ky=3)
            z = z + f.ev(y, x)
        return z

    def add(self, xs, ys, dz):
        """Add a correction grid (NaN outside its region: filled by the nearest node, which is where
        the tool path has run out anyway)."""
        from scipy import ndimage

        bad = ~np.isfinite(dz)
        if bad.any():
            idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
            dz = dz[idx[0], idx[1]]
        return Program(self.nominal, [*self.corrections, (np.asarray(xs), np.asarray(ys), dz)])


def machine_error(program: Program, x, y, effects: list[dict]):
    """The repeatable error (mm) the machine leaves on the cut surface at (x, y)."""
    fx, fy = program.nominal.gradient(x, y)
    c = np.degrees(np.arctan2(y, x)) % 360.0
    ctx = ScanContext(np.asarray(x, float), np.asarray(y, float), program.nominal.sag(x, y), fx, fy,
                      np.zeros_like(x, dtype=float), c)
    return effects_dz(ctx, effects)


def default_machine(radius: float, rng=None) -> list[dict]:
    """A diamond-turning lathe's repeatable errors of a few hundred nm over ``radius`` (mm): two- and
    three-lobed spindle tilt, the X–C cone, slide straightness and a 2 µm tool-radius error. With
    ``rng``, each amplitude is scaled by a factor in [0.5, 1.5] and signs drawn at random."""
    s = (lambda: 1.0) if rng is None else (lambda: float(rng.uniform(0.5, 1.5) * rng.choice([-1, 1])))
    arcsec_at_rim = 1e-4 / (radius * np.pi / 180 / 3600)  # arcsec giving 100 nm at the rim
    return [
        {"spindle_tilt": {"a2_arcsec": 1.5 * arcsec_at_rim * s(), "b3_arcsec": 0.8 * arcsec_at_rim * s()}},
        {"squareness": {"eb0c_arcsec": 1.0 * arcsec_at_rim * s()}},
        {"straightness": {"s2": 2e-4 * s(), "s3": -1.5e-4 * s(), "s4": 1e-4 * s()}},
        {"probe_radius": {"radius": 2e-3 * s()}},
    ]


def cut_and_measure(program: Program, machine: list[dict], *, radius: float, scan: ScanSpec | dict,
                    noise_mm: float = 2e-6, seed: int = 0, setup=True) -> PointCloud:
    """Cut ``program`` on ``machine``, measure it on ``scan`` (radius ≥ the aperture's) with
    ``noise_mm`` RMS probe noise: a cloud in the part frame with its ``residual`` channel (mm)."""
    spec = scan if isinstance(scan, ScanSpec) else ScanSpec.model_validate(scan)
    pts = scan_points(spec)
    x, y = pts["x"], pts["y"]
    rng = np.random.default_rng(seed)
    part = program.sag(x, y) + machine_error(program, x, y, machine)
    z = part + rng.normal(0.0, noise_mm, x.size)
    if setup:  # what remains of the set-up after the pose fit: a little piston and tilt
        z = z + rng.normal(0, 1e-4) + rng.normal(0, 1e-6) * x + rng.normal(0, 1e-6) * y
    res = z - program.nominal.sag(x, y)
    return PointCloud.from_xyz(x, y, z, residual=res)


def true_form_error(program: Program, machine: list[dict], radius: float, n: int = 201):
    """RMS (mm) of the cut part's form error over the disk of ``radius``, piston and tilt removed,
    on an n × n grid (no measurement noise)."""
    g = np.linspace(-radius, radius, n)
    X, Y = np.meshgrid(g, g)
    m = X * X + Y * Y <= radius * radius
    x, y = X[m], Y[m]
    e = program.sag(x, y) + machine_error(program, x, y, machine) - program.nominal.sag(x, y)
    A = np.column_stack([np.ones_like(x), x, y])
    e = e - A @ np.linalg.lstsq(A, e, rcond=None)[0]
    return float(np.sqrt(np.mean(e * e)))
