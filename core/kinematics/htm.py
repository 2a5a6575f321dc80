"""Homogeneous-transform model of a three-axis turning machine with the ISO 230-1 error components.

Chains (003 Fig. 3): base → Z slide → C spindle → workpiece, and base → X slide → probe. With
nominal motions Trans(0, 0, z), Rz(c) and Trans(x, 0, 0), the probe tip seen from the workpiece is
    p_w = (T_Z T_C)⁻¹ T_X p_probe,
    T_X = Trans(x,0,0) · E(EXX, EYX, EZX, EAX, EBX, ECX)(x)
    T_Z = Trans(0,0,z) · E(EXZ, EYZ, EZZ, EAZ, EBZ, ECZ)(z)
    T_C = E_loc(EA0C, EB0C) · E(EXC, EYC, EZC, EAC, EBC, ECC)(c) · Rz(c)   (error motions in the
          machine frame, ISO 230-7)
E(δx, δy, δz, α, β, γ) = Trans(δ) · Rx(α) Ry(β) Rz(γ) (exact rotations, so the model holds beyond
first order). Error functions are callables of the axis position (mm or deg) returning mm or rad;
EA0C/EB0C (location errors, squareness of C to the X/Y–Z planes) are constants (rad).

The measured height carries e = −(z error of the probe tip in the workpiece frame): a tip that sits
higher reads the surface lower. To first order in the errors, with the probe at radius x on the
X slide and the others zero, the sensitive-direction ("selective", 003 §3) model is
    e(x, c) = −EZX(x) + EZC(c) − x·EBC(c) − x·EB0C,
which ``selective_error`` evaluates and the tests check against the full HTM.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

COMPONENTS = ("EXX", "EYX", "EZX", "EAX", "EBX", "ECX",
              "EXZ", "EYZ", "EZZ", "EAZ", "EBZ", "ECZ",
              "EXC", "EYC", "EZC", "EAC", "EBC", "ECC")
LOCATION = ("EA0C", "EB0C")


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(b):
    c, s = np.cos(b), np.sin(b)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(g):
    c, s = np.cos(g), np.sin(g)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def htm(R=None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def error_htm(dx=0.0, dy=0.0, dz=0.0, a=0.0, b=0.0, g=0.0) -> np.ndarray:
    return htm(_rx(a) @ _ry(b) @ _rz(g), (dx, dy, dz))


@dataclass
class TurningMachine:
    """Error components by ISO 230-1 name: callables of the axis position (x, z in mm; c in deg),
    or constants; location errors EA0C, EB0C constants (rad). Missing components are zero."""

    errors: dict[str, Callable | float] = field(default_factory=dict)

    def _e(self, name, pos):
        f = self.errors.get(name, 0.0)
        return float(f(pos)) if callable(f) else float(f)

    def _axis(self, prefix_axis: str, pos) -> np.ndarray:
        ax = prefix_axis
        return error_htm(self._e(f"EX{ax}", pos), self._e(f"EY{ax}", pos), self._e(f"EZ{ax}", pos),
                         self._e(f"EA{ax}", pos), self._e(f"EB{ax}", pos), self._e(f"EC{ax}", pos))

    def tip_in_workpiece(self, x: float, c_deg: float, z: float = 0.0, probe=(0.0, 0.0, 0.0)):
        TX = htm(t=(x, 0.0, 0.0)) @ self._axis("X", x)
        TZ = htm(t=(0.0, 0.0, z)) @ self._axis("Z", z)
        loc = htm(_rx(self._e("EA0C", 0.0)) @ _ry(self._e("EB0C", 0.0)))
        # error motions of the spindle in the machine's (non-rotating) frame, as ISO 230-7 defines them
        TC = loc @ self._axis("C", c_deg) @ htm(_rz(np.deg2rad(c_deg)))
        p = np.r_[probe, 1.0]
        return (np.linalg.inv(TZ @ TC) @ TX @ p)[:3]

    def measurement_error(self, x, c_deg, z: float = 0.0) -> np.ndarray:
        """e(x, c) (mm) that a height measured by the probe carries: −(tip z error in the workpiece)."""
        x = np.atleast_1d(np.asarray(x, dtype=np.float64))
        c = np.broadcast_to(np.asarray(c_deg, dtype=np.float64), x.shape)
        out = np.empty(x.shape)
        for i, (xi, ci) in enumerate(zip(x.ravel(), c.ravel())):
            nominal = TurningMachine().tip_in_workpiece(xi, ci, z)
            out.ravel()[i] = -(self.tip_in_workpiece(xi, ci, z)[2] - nominal[2])
        return out


def selective_error(x, c_deg, ezx: Callable, ezc: Callable, ebc: Callable, eb0c: float) -> np.ndarray:
    """003's selective model in the sensitive z direction (mm): −EZX(x) + EZC(c) − x(EBC(c) + EB0C)."""
    x = np.asarray(x, dtype=np.float64)
    c = np.asarray(c_deg, dtype=np.float64)
    return -ezx(x) + ezc(c) - x * (ebc(c) + eb0c)
