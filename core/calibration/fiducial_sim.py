"""Simulated fiducial calibrations in the set-up of seed paper 000 §2.4, for tests and benchmarks.

24 balls at random in a 200 × 40 × 50 mm workspace, a machine frame (small rotation, scale, shear
and shift), a smooth volumetric error field of a given RMS magnitude, probing noise on the probe
points of the balls and calibration noise on the reference centres, and workpiece points that are
not fiducials. Two families of random smooth fields, so that no one kernel is favoured by the
construction:

* ``fourier``: a sum of six random plane waves per component, their frequencies along each axis
  normal with σ = 0.3 cycles per travel (a Gaussian spectrum: a field that varies along every axis
  at once, correlation length about ½ travel);
* ``kinematic``: the ISO 230-1 picture of a three-axis machine: positioning and straightness errors,
  each a smooth function of one axis (cubic plus a sine of period 1–3 travels), and angular errors
  of each axis times their Abbe offsets (products of a function of one axis and another coordinate).

The field is e(p) = X_c − X_m: the machine reads a point at p_true − e(p_true) (mm).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fiducials import ball_points

EXTENT = np.array([200.0, 40.0, 50.0])          # mm
LOW = np.array([-100.0, -20.0, 0.0])
SPECTRUM = 0.3    # σ of the plane waves' frequencies, cycles per travel


def machine_frame(ref):
    """The machine frame: small rotation, scale and shear, and a shift (mm)."""
    D = np.array([[1 + 2e-5, 3e-5, -1e-5], [-3e-5, 1 - 1e-5, 2e-5], [1e-5, -2e-5, 1 + 3e-5]])
    return np.asarray(ref, float) @ D.T + np.array([120.0, -35.0, 8.0])


def _fourier(rng, extent, low):
    waves = []
    for _k in range(3):
        n = 6
        u = rng.normal(0, SPECTRUM, (n, 3))                  # cycles per travel
        f = u / extent                                       # cycles per mm
        a = rng.normal(0, 1, n) / np.sqrt(n)
        ph = rng.uniform(0, 2 * np.pi, n)
        waves.append((f, a, ph))

    def e(P):
        Q = np.asarray(P, float) - low
        return np.column_stack([np.cos(2 * np.pi * Q @ f.T + ph) @ a for f, a, ph in waves])

    return e


def _kinematic(rng, extent, low):
    def one_axis():
        c = rng.normal(0, 1, 3) / np.array([1.0, 1.0, 1.5])
        per = rng.uniform(1.0, 3.0)
        s, ph = rng.normal(0, 0.5), rng.uniform(0, 2 * np.pi)
        return lambda t: c[0] * t + c[1] * t**2 + c[2] * t**3 + s * np.sin(2 * np.pi * t / per + ph)

    lin = [[one_axis() for _ in range(3)] for _ in range(3)]     # lin[axis][component]
    ang = [[one_axis() for _ in range(3)] for _ in range(3)]     # ang[axis][rotation about x, y, z]

    def e(P):
        Q = np.asarray(P, float) - low
        t = Q / extent                                          # 0…1 along each travel
        arm = Q / extent.max()                                  # Abbe offsets, relative
        out = np.zeros((len(Q), 3))
        for ax in range(3):
            for k in range(3):
                out[:, k] += lin[ax][k](t[:, ax])
            r = np.column_stack([ang[ax][j](t[:, ax]) for j in range(3)]) * 0.6
            out += np.cross(r, arm)                             # small rotation of the arm
        return out

    return e


def smooth_field(seed: int, kind: str = "fourier", rms_um: float = 1.3, extent=EXTENT, low=LOW):
    """A random smooth volumetric error field e(P) (mm) over the box ``low`` + [0, ``extent``] (machine
    frame), scaled so that the RMS of |e| over the box is ``rms_um`` µm."""
    rng = np.random.default_rng(seed)
    extent, low = np.asarray(extent, float), np.asarray(low, float)
    base = {"fourier": _fourier, "kinematic": _kinematic}[kind](rng, extent, low)
    probe = low + rng.uniform(0, 1, (4000, 3)) * extent
    v = base(probe)
    scale = rms_um * 1e-3 / np.sqrt(np.mean(np.sum((v - v.mean(axis=0)) ** 2, axis=1)))
    mean = v.mean(axis=0)
    return lambda P: (base(P) - mean) * scale


@dataclass
class FiducialCase:
    ref_true: np.ndarray      # (n, 3) true reference centres (mm)
    ref_given: np.ndarray     # (n, 3) the calibrated centres as the certificate gives them (σ_r noise)
    points: np.ndarray        # probe points on the balls, machine frame (mm)
    ids: np.ndarray           # their ball ids 1…n
    work_ref: np.ndarray      # (m, 3) workpiece points, true reference coordinates (mm)
    work_meas: np.ndarray     # (m, 3) the same as the machine reads them (no probing noise)
    field: object             # e(P), machine frame, mm

    def reference_csv(self) -> str:
        n = len(self.ref_given)
        rows = np.column_stack([np.arange(1, n + 1), self.ref_given])
        return "fiducial,x,y,z\n" + "".join(f"{int(r[0])}," + ",".join(repr(float(v)) for v in r[1:]) + "\n"
                                             for r in rows)


def case_000(seed: int, kind: str = "fourier", n: int = 24, rms_um: float = 1.3, probe_um: float = 0.2,
             calib_um: float = 0.2, workpiece: int = 3000) -> FiducialCase:
    """The set-up of 000 §2.4: ``n`` balls at random in 200 × 40 × 50 mm, a smooth field of ``rms_um``,
    probing noise ``probe_um`` on each of the 20 probe points of a ball, calibration noise ``calib_um``
    per axis on the reference centres, ``workpiece`` points at random inside the balls' bounding box
    (the calibrated workspace), none of them a fiducial."""
    rng = np.random.default_rng(10_000 + seed)
    ref = LOW + rng.uniform(0, 1, (n, 3)) * EXTENT
    f = smooth_field(seed, kind, rms_um, EXTENT, machine_frame(LOW))
    true_c = machine_frame(ref)
    meas_c = true_c - f(true_c)
    pts, ids = ball_points(meas_c, noise=probe_um * 1e-3, seed=seed)
    given = ref + rng.normal(0, calib_um * 1e-3, ref.shape)
    lo, hi = ref.min(axis=0), ref.max(axis=0)
    W = lo + rng.uniform(0, 1, (workpiece, 3)) * (hi - lo)
    TW = machine_frame(W)
    return FiducialCase(ref, given, pts, ids, W, TW - f(TW), f)
