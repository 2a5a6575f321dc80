"""The kinematic error map: a look-up table of the measurement error e(X, c) over the probe's position
X on the X slide (mm, signed: the spindle axis at X = 0; ``r`` in the table and its JSON, "r_mm") and
the spindle angle c (deg), built from the separated components with the selective model
(core.kinematics.htm.selective_error), interpolated bilinearly (periodic in c) and subtracted from
on-machine heights. The table holds 0 ≤ X ≤ r_max and, where the straightness scan reaches there,
X < 0: a scan through the centre has the probe on both sides, and e(−X, c) ≠ e(X, c) (EZX(−X),
and the cone −X·(EBC + EB0C) changes sign). A map of X ≥ 0 only (built before, or from a straightness
scan that starts at the axis) refuses points at X < 0 rather than reading them at |X|."""
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
    r: np.ndarray            # (nr,) mm, ascending: the probe's signed position X on the slide
    c_deg: np.ndarray        # (nc,) deg, ascending over [0, 360)
    e: np.ndarray            # (nr, nc) mm
    components: dict = field(default_factory=dict)

    def __call__(self, r, c_deg) -> np.ndarray:
        from scipy.interpolate import RegularGridInterpolator

        r = np.asarray(r, dtype=np.float64)
        c = np.mod(np.asarray(c_deg, dtype=np.float64), 360.0)
        tol = 1e-9 * max(abs(self.r[0]), abs(self.r[-1]), 1.0)
        if r.size and (r.max() > self.r[-1] + tol or r.min() < self.r[0] - tol):
            out = (r > self.r[-1] + tol) | (r < self.r[0] - tol)
            raise InputError(f"{int(out.sum())} points with the probe at X from {r[out].min():.4g} to "
                             f"{r[out].max():.4g} mm lie outside the kinematic map (X {self.r[0]:g}–"
                             f"{self.r[-1]:g} mm)")
        # periodic in c on both sides: a map whose angles start above 0 (bin centres 0.5…359.5°) has
        # c in [0, c_deg[0]) below its first node (a review: an internal error "xi out of bounds")
        cc = np.r_[self.c_deg[-1] - 360.0, self.c_deg, self.c_deg[0] + 360.0]
        ee = np.concatenate([self.e[:, -1:], self.e, self.e[:, :1]], axis=1)
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
        # a review: a NaN in e_mm wrote NaN heights with exit 0; descending or repeated axes gave a
        # misleading range message or an internal error from the interpolator
        for key, a in (("r_mm", m.r), ("c_deg", m.c_deg), ("e_mm", m.e)):
            if a.size == 0 or not np.all(np.isfinite(a)):
                raise InputError(f"{source}: key '{key}' holds values that are not finite numbers"
                                 if a.size else f"{source}: key '{key}' is empty")
        for key, a in (("r_mm", m.r), ("c_deg", m.c_deg)):
            if a.size > 1 and not np.all(np.diff(a) > 0):
                raise InputError(f"{source}: key '{key}' is not strictly increasing")
        if m.c_deg.size and (m.c_deg[0] < 0 or m.c_deg[-1] >= m.c_deg[0] + 360.0):
            raise InputError(f"{source}: key 'c_deg' spans more than one turn (0 ≤ c < 360°)")
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


def map_positions(x_lo: float, r_max: float, n_r: int) -> np.ndarray:
    """The table's probe positions X: 0…r_max in n_r steps, continued at that step down to x_lo < 0
    (x_lo itself the first node), or from x_lo > 0 when the straightness scan starts off the axis."""
    pos = np.linspace(0.0, r_max, n_r)
    if x_lo > 0:
        return np.r_[x_lo, pos[pos > x_lo * (1 + 1e-12)]]
    k = int(np.floor(-x_lo / pos[1] + 1e-9)) if x_lo < 0 else 0
    r = np.r_[-pos[1:k + 1][::-1], pos]
    return np.r_[x_lo, r] if x_lo < r[0] - 1e-9 * r_max else r


#: the squareness reversal's fit needs at least this many samples on each side of the spindle axis
MIN_SQUARENESS_SIDE = 3


def squareness_window(x_squareness, x_straightness, path, straightness_path, step: str = "kinematic_map"):
    """The squareness samples the EB0C fit may use: |x| ≤ a, the largest range symmetric about the
    spindle axis that both the squareness scans and the straightness scan (EZX, removed from them
    first) cover. Symmetric, because turned by 180° the flat is read at −x: only over ±x does its own
    form drop out of β1 + β2 (over 0…R its even part — power — goes into EB0C: 0.08″ read as −0.245″);
    within the straightness scan, because EZX is not known beyond it (held at its end value it gave
    −0.176″ for 0.08″). Returns (mask, a, warning or None); InputError, naming the files, the ranges
    found and what is needed, when fewer than MIN_SQUARENESS_SIDE samples are left on a side."""
    xq = np.asarray(x_squareness, dtype=np.float64)
    xs = np.asarray(x_straightness, dtype=np.float64)
    need = MIN_SQUARENESS_SIDE
    neg, pos = np.sort(-xq[xq < 0]), np.sort(xq[xq > 0])
    sq_range = f"x {xq.min():g}…{xq.max():g} mm ({xq.size} samples, {neg.size} at x < 0, {pos.size} at x > 0)"
    if min(neg.size, pos.size) < need:
        raise InputError(
            f"{path}: the {step} step's squareness reversal needs the scans across the spindle axis, at least "
            f"{need} samples on each side of x = 0 over a range symmetric about it (turned by 180°, the flat is "
            f"read at −x, and only over ±x does its own form drop out of the slopes; a one-sided scan puts the "
            f"flat's power into EB0C); the file covers {sq_range} — scan the flat through its centre, or "
            f"leave squareness empty (EB0C = 0)")
    a = min(float(neg[-1]), float(pos[-1]), float(-xs.min()), float(xs.max()))
    tol = 1e-9 * max(float(np.max(np.abs(xq))), 1.0)
    keep = np.abs(xq) <= a + tol
    n_neg, n_pos = int(np.sum(keep & (xq < 0))), int(np.sum(keep & (xq > 0)))
    st_range = f"x {xs.min():g}…{xs.max():g} mm"
    if min(n_neg, n_pos) < need:
        a_need = max(float(neg[need - 1]), float(pos[need - 1]))
        left = (f"|x| ≤ {a:g} mm with {n_neg} samples at x < 0 and {n_pos} at x > 0" if a > 0 else
                "no range about the axis (EZX is known on one side of it only)")
        raise InputError(
            f"{path}: the {step} step fits EB0C where the straightness scan ({straightness_path}) gives EZX, over "
            f"a range symmetric about the spindle axis; the straightness scan covers {st_range} and the "
            f"squareness scan {sq_range}, which leaves {left} — at least {need} samples on each side are "
            f"needed: the straightness scan must cover x from −{a_need:g} to {a_need:g} mm or more (EZX is not "
            f"extrapolated; the wider the range, the less noise in EB0C)")
    warning = None
    if not keep.all():
        why = ("where the straightness scan gives EZX and " if a < min(float(neg[-1]), float(pos[-1])) - tol
               else "")
        warning = (f"squareness: EB0C fitted over |x| ≤ {a:g} mm only ({int(keep.sum())} of {xq.size} samples), "
                   f"{why}symmetric about the spindle axis so that the flat's form drops out: the squareness "
                   f"scan covers {sq_range.split(' (')[0]}, the straightness scan {st_range} (EZX is not "
                   f"extrapolated); the shorter range leaves EB0C noisier")
    return keep, a, warning


def build_map(x_samples, ezx_values, c_samples, ezc_values, ebc_values, eb0c: float, r_max: float,
              n_r: int = 101, n_c: int = 360) -> KinematicMap:
    """The table of e(X, c) = −EZX(X) + EZC(c) − X(EBC(c) + EB0C) over the probe's position X from
    max(−r_max, the straightness scan's smallest x) to r_max (n_r positions over 0…r_max, as many at
    the same step below 0) — never beyond the x the straightness scan covers: EZX is not extrapolated."""
    xs = np.asarray(x_samples, dtype=np.float64)
    if r_max > xs.max() + 1e-9:
        raise InputError(f"the straightness scan covers x ≤ {xs.max():g} mm but the map needs "
                         f"r ≤ {r_max:g} mm")
    x_lo = max(float(xs.min()), -r_max)
    if x_lo >= r_max:
        raise InputError(f"the straightness scan covers x {xs.min():g}–{xs.max():g} mm, none of the map's "
                         f"0–{r_max:g} mm")
    o = np.argsort(xs)
    ezx = lambda q: np.interp(q, xs[o], np.asarray(ezx_values, dtype=np.float64)[o])  # noqa: E731
    ezc = periodic(c_samples, ezc_values)
    ebc = periodic(c_samples, ebc_values)
    r = map_positions(x_lo, r_max, n_r)
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
