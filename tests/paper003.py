"""Simulated set-up of paper 003 (kinematic errors of an ultra-precision lathe, on-machine measurement
of a superpolished flat).

Machine: EZX 52.6 nm PV over 38 mm (a bow and a 25 mm wave), EZC 4.4 nm PV (1 and 3 upr), EBC two
lobes per revolution (0.1″ amplitude), EB0C 0.08″. Flat: 8.7 nm PV about its plane over r ≤ 10 mm.
Reversal measurements: capacitance probes with 0.3 nm noise, averaged as the paper does; on-machine
spiral of radius 10 mm read with 0.3 nm noise. Lengths in mm.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.kinematics.htm import selective_error

ARCSEC = np.pi / 180 / 3600


def ezx(x):
    x = np.asarray(x, dtype=np.float64)
    return 30e-6 * (x / 19.0) ** 2 + 12e-6 * np.sin(2 * np.pi * x / 25.0)


def ezc(c):
    a = np.deg2rad(np.asarray(c, dtype=np.float64))
    return 1.6e-6 * np.cos(a + 0.4) + 0.7e-6 * np.cos(3 * a - 1.0)


def ebc(c):
    a = np.deg2rad(np.asarray(c, dtype=np.float64))
    return 0.1 * ARCSEC * np.cos(2 * a + 0.7) + 0.01 * ARCSEC * np.cos(a)


EB0C = 0.08 * ARCSEC


def flat_form(xw, yw, pv_nm=8.7):
    """A superpolished flat: astigmatism, a little power and a soft ripple, scaled to its PV."""
    r2 = (xw * xw + yw * yw) / 100.0
    f = 0.6 * (xw * xw - yw * yw) / 100.0 + 0.3 * (2 * r2 - 1) + 0.15 * np.sin(xw / 2.1) * np.cos(yw / 3.3)
    return f


def scale_flat(xw, yw, pv_nm=8.7):
    from pointspro.plugins.kinematic import flatness

    f = flat_form(xw, yw)
    return f * (pv_nm * 1e-6 / flatness(xw, yw, f))


def error(r, c):
    return selective_error(r, c, ezx, ezc, ebc, EB0C)


def reversal_files(folder, seed=3, noise=0.3e-6, L=10.0):
    """Write the three reversal measurements as CSV (what the machine's operator records)."""
    rng = np.random.default_rng(seed)
    x = np.linspace(-19.0, 19.0, 381)
    art = 15e-6 * np.sin(x / 6.0) + 5e-6 * (x / 19) ** 3   # the metal mirror's own profile
    n3 = lambda k: rng.normal(0, noise / np.sqrt(3), k)    # noqa: E731  (three runs averaged)
    m1 = art - ezx(x) + n3(x.size)
    m2 = art + ezx(x) + n3(x.size)
    np.savetxt(folder / "straightness.csv", np.column_stack([x, m1, m2]), delimiter=",",
               header="x,m1,m2", comments="", fmt="%.12g")
    c = np.arange(0.0, 360.0, 0.5)
    F = 6e-6 * np.cos(np.deg2rad(2 * c) + 1.2) + 3e-6 * np.sin(np.deg2rad(c))
    G = 2e-6 * np.cos(np.deg2rad(3 * c))
    n20 = lambda k: rng.normal(0, noise / np.sqrt(20), k)  # noqa: E731  (20 revolutions averaged)
    fm1 = F + ezc(c) - L * ebc(c) + n20(c.size)
    fm4 = F + ezc(c) + L * ebc(c) + n20(c.size)
    fm2 = G + ezc(c) + n20(c.size)
    fm3 = -G + ezc(c) + n20(c.size)
    np.savetxt(folder / "facial.csv", np.column_stack([c, fm1, fm2, fm3, fm4]), delimiter=",",
               header="c,m1,m2,m3,m4", comments="", fmt="%.12g")
    xs = np.linspace(-10.0, 10.0, 201)
    theta = 3e-6  # the flat's tilt on the chuck (rad)
    s0 = theta * xs + (-ezx(xs) + ezc(0.0) - xs * (ebc(0.0) + EB0C)) + n3(xs.size)
    s180 = -theta * xs + (-ezx(xs) + ezc(180.0) - xs * (ebc(180.0) + EB0C)) + n3(xs.size)
    np.savetxt(folder / "squareness.csv", np.column_stack([xs, s0, s180]), delimiter=",",
               header="x,m1,m2", comments="", fmt="%.12g")


def omsm_spiral(seed=5, radius=10.0, turns=100, per_turn=720, noise=0.3e-6):
    """The flat on the spindle read along a spiral: probe radius r, spindle angle c; the point probed
    on the workpiece is r·(cos(−c), sin(−c)). Returns x, y (workpiece), z measured, c, and the truth."""
    rng = np.random.default_rng(seed)
    k = np.arange(turns * per_turn)
    c = (k * 360.0 / per_turn) % 360.0
    r = radius * (1 - k / k.size)
    xw, yw = r * np.cos(-np.deg2rad(c)), r * np.sin(-np.deg2rad(c))
    h = scale_flat(xw, yw)
    z = h + error(r, c) + rng.normal(0, noise, k.size)
    return xw, yw, z, c, h
