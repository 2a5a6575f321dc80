"""The kinematic error map: a look-up table of the measurement error e(r, c) over probe radius r (mm)
and spindle angle c (deg), built from the separated components with the selective model
(core.kinematics.htm.selective_error), interpolated bilinearly (periodic in c) and subtracted from
on-machine heights."""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .htm import selective_error

ARCSEC = np.pi / 180 / 3600
#: the undulations per revolution undulations_per_rev resolves (1 … MAX_UPR)
MAX_UPR = 15
#: the facial reversal's spindle angles must leave no gap this wide (deg): MAX_UPR sampled at Nyquist
MAX_GAP_DEG = 180.0 / MAX_UPR


@dataclass(frozen=True)
class KinematicMap:
    r: np.ndarray            # (nr,) mm, ascending
    c_deg: np.ndarray        # (nc,) deg, ascending over [0, 360)
    e: np.ndarray            # (nr, nc) mm
    components: dict = field(default_factory=dict)

    def __call__(self, r, c_deg) -> np.ndarray:
        from scipy.interpolate import RegularGridInterpolator

        r = np.asarray(r, dtype=np.float64)
        c = np.mod(np.asarray(c_deg, dtype=np.float64), 360.0)
        if r.size and (r.max() > self.r[-1] * (1 + 1e-9) or r.min() < self.r[0] - 1e-9):
            raise InputError(f"points at radius up to {r.max():.4g} mm lie outside the kinematic map "
                             f"({self.r[0]:g}–{self.r[-1]:g} mm)")
        cc = np.r_[self.c_deg, self.c_deg[0] + 360.0]
        ee = np.concatenate([self.e, self.e[:, :1]], axis=1)
        f = RegularGridInterpolator((self.r, cc), ee)
        return f(np.column_stack([np.clip(r, self.r[0], self.r[-1]), c]))

    def to_json(self) -> str:
        return json.dumps({"pointspro_kinematic_map": 1, "r_mm": self.r.tolist(),
                           "c_deg": self.c_deg.tolist(), "e_mm": self.e.tolist(),
                           "components": self.components}) + "\n"

    @classmethod
    def from_json(cls, text: str, source: str = "map") -> "KinematicMap":
        try:
            d = json.loads(text)
            if d.get("pointspro_kinematic_map") != 1:
                raise KeyError("pointspro_kinematic_map")
            m = cls(np.asarray(d["r_mm"], float), np.asarray(d["c_deg"], float),
                    np.asarray(d["e_mm"], float), d.get("components", {}))
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            from ..io.text import json_problem  # quotes nothing of the file

            raise InputError(f"{source}: not a PointsPro kinematic map ({json_problem(e)})") from None
        if m.e.shape != (m.r.size, m.c_deg.size):
            raise InputError(f"{source}: the map's table does not match its axes")
        return m


def periodic(c_samples, values):
    """A callable interpolating values given at spindle angles (deg) periodically over 360°."""
    c = np.mod(np.asarray(c_samples, dtype=np.float64), 360.0)
    o = np.argsort(c)
    c, v = c[o], np.asarray(values, dtype=np.float64)[o]
    cc = np.r_[c[-1] - 360.0, c, c[0] + 360.0]
    vv = np.r_[v[-1], v, v[0]]
    return lambda q: np.interp(np.mod(np.asarray(q, dtype=np.float64), 360.0), cc, vv)


def facial_coverage(c_samples, path, step: str = "kinematic_map") -> None:
    """Refuse facial readings that do not go round the spindle: EZC(c) and EBC(c) are identified,
    mapped and analysed for undulations over the whole revolution, and a gap of MAX_GAP_DEG or more
    between successive angles (around the circle) leaves them undetermined there — half a turn gave
    EBC harmonics of 2.7e6″ for 0.1″ and the other half of the map interpolated. InputError naming
    the file, the step, the coverage found and the one needed."""
    c = np.unique(np.mod(np.asarray(c_samples, dtype=np.float64), 360.0))
    if c.size == 0:
        raise InputError(f"{path}: no facial readings")
    gaps = np.diff(np.r_[c, c[0] + 360.0])
    i = int(np.argmax(gaps))
    if gaps[i] < MAX_GAP_DEG:
        return
    start, end = float(c[i]), float(c[(i + 1) % c.size])  # the gap runs from start to end
    end_at = end + 360.0 if end <= start else end
    found = (f"one angle ({start:g}°)" if c.size == 1 else
             f"c from {end:g}° {'round ' if start < end else ''}to {start:g}° ({c.size} angles): a gap of "
             f"{gaps[i]:.4g}°, from {start:g}° to {end_at:g}°")
    raise InputError(f"{path}: the {step} step needs facial readings all round the spindle, no gap of "
                     f"{MAX_GAP_DEG:g}° or more between successive angles c (EZC and EBC are mapped over the "
                     f"whole revolution and analysed up to {MAX_UPR} undulations per revolution); the file "
                     f"covers {found}")


def build_map(x_samples, ezx_values, c_samples, ezc_values, ebc_values, eb0c: float, r_max: float,
              n_r: int = 101, n_c: int = 360) -> KinematicMap:
    """The table of e(r, c) = −EZX(r) + EZC(c) − r(EBC(c) + EB0C) over 0 ≤ r ≤ r_max."""
    xs = np.asarray(x_samples, dtype=np.float64)
    if r_max > xs.max() + 1e-9:
        raise InputError(f"the straightness scan covers x ≤ {xs.max():g} mm but the map needs "
                         f"r ≤ {r_max:g} mm")
    o = np.argsort(xs)
    ezx = lambda q: np.interp(q, xs[o], np.asarray(ezx_values, dtype=np.float64)[o])  # noqa: E731
    ezc = periodic(c_samples, ezc_values)
    ebc = periodic(c_samples, ebc_values)
    r = np.linspace(0.0, r_max, n_r)
    c = np.arange(n_c) * 360.0 / n_c
    R, C = np.meshgrid(r, c, indexing="ij")
    e = selective_error(R, C, ezx, ezc, ebc, eb0c)
    comps = {"ezx_pv_nm": float(np.ptp(ezx_values) * 1e6), "ezc_pv_nm": float(np.ptp(ezc_values) * 1e6),
             "ebc_pv_arcsec": float(np.ptp(ebc_values) / ARCSEC), "eb0c_arcsec": float(eb0c / ARCSEC)}
    return KinematicMap(r, c, e, comps)


def undulations_per_rev(c_samples, values, top: int = 3) -> list[dict]:
    """The largest harmonics (undulations per revolution) of a periodic error over the spindle angle."""
    c = np.mod(np.asarray(c_samples, dtype=np.float64), 360.0)
    v = np.asarray(values, dtype=np.float64)
    k = np.arange(1, MAX_UPR + 1)
    A = np.column_stack([np.ones_like(c)] + [f(np.deg2rad(c) * kk) for kk in k for f in (np.cos, np.sin)])
    coef, *_ = np.linalg.lstsq(A, v, rcond=None)
    amp = np.hypot(coef[1::2], coef[2::2])
    order = np.argsort(amp)[::-1][:top]
    return [{"upr": int(k[i]), "amplitude": float(amp[i])} for i in order]
