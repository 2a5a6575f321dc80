"""Reversal methods that separate the machine's error motions from the artefact's form (003 §4;
Evans, Hocken & Estler, "Self-calibration: reversal, redundancy, error separation", CIRP 1996).

Measurement models (heights in mm, with the sign the HTM model gives a probe reading,
core.kinematics.htm: e = −EZX(x) + EZC(c) − x·EBC(c) − x·EB0C):

Straightness of X in Z (EZX), a flat scanned along X, then turned 180° with the probe reversed so
the slide's deviation enters with the other sign:
    M1(x) = Eflat(x) − EZX(x),   M2(x) = Eflat(x) + EZX(x)
    ⇒ EZX = (M2 − M1)/2,   Eflat = (M1 + M2)/2                                    (003 eq 7)
Facial reversal of the C axis, probe A at radius L and probe B on the axis facing a reference that
reverses with the flat; after turning the flat 180°, A reads the same track from radius −L:
    M1 = F(c) + EZC − L·EBC,   M4 = F(c) + EZC + L·EBC,   M2 = G(c) + EZC,   M3 = −G(c) + EZC
    ⇒ EZC = (M2 + M3)/2,   EBC = (M4 − M1)/(2L),   Eflat = (M1 + M4)/2 − EZC          (003 eqs 8–10,
      whose EBC = (M1 − M4)/2L is the same with its probe labels)
Squareness of X to C (EB0C), a flat on the chuck scanned along X at c = 0 and c = 180°; the flat's own
tilt θ reverses, the cone does not. With the EZX profile removed first (when known):
    β1 = θ − EB0C − EBC(0),   β2 = −θ − EB0C − EBC(180)
    ⇒ EB0C = −(β1 + β2)/2 − (EBC(0) + EBC(180))/2                                  (003 eq 11)
"""
from __future__ import annotations

import numpy as np


def straightness_reversal(m1, m2):
    """(EZX, Eflat) from the forward and reversed scans (same x samples)."""
    m1, m2 = np.asarray(m1, dtype=np.float64), np.asarray(m2, dtype=np.float64)
    return (m2 - m1) / 2.0, (m1 + m2) / 2.0


def facial_reversal(m1, m2, m3, m4, L: float):
    """(EZC, EBC (rad), Eflat) from the four facial readings over the spindle angle."""
    if not L > 0:
        raise ValueError("the probes' distance L must be > 0")
    m1, m2, m3, m4 = (np.asarray(m, dtype=np.float64) for m in (m1, m2, m3, m4))
    ezc = (m2 + m3) / 2.0
    ebc = (m4 - m1) / (2.0 * L)
    return ezc, ebc, (m1 + m4) / 2.0 - ezc


def line_slope(x, m) -> float:
    """Least-squares slope (rad, for mm/mm) of a line scan."""
    return float(np.polyfit(np.asarray(x, dtype=np.float64), np.asarray(m, dtype=np.float64), 1)[0])


def squareness_reversal(x, m_0, m_180, tilt_0: float = 0.0, tilt_180: float = 0.0, ezx=None) -> float:
    """EB0C (rad) from line scans along X at c = 0 and 180°; ``tilt_*`` the spindle's EBC there
    (rad), ``ezx`` the straightness profile at x (mm) to remove first."""
    x = np.asarray(x, dtype=np.float64)
    add = 0.0 if ezx is None else np.asarray(ezx, dtype=np.float64)
    b1 = line_slope(x, np.asarray(m_0) + add)
    b2 = line_slope(x, np.asarray(m_180) + add)
    return -(b1 + b2) / 2.0 - (tilt_0 + tilt_180) / 2.0
