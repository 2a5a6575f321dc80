"""The library of physical effects — each written once, used both to simulate and to explain.

An effect adds a height error Δz (mm) to every simulated point. Each is linear in its parameters
around zero (the first-order physics of small errors), so its *signature* — ∂Δz/∂parameters, one
column per parameter — is the same function the simulator evaluates: Δz = S·p. Only `vibration` has
a non-linear parameter (its frequency), found from the gap's spectrum before its amplitude is fitted.

Names are the model file's contract (README "Simulate, then explain the difference"). Point context: x, y (mm), nominal sag f and slopes f_x, f_y, radius r,
spindle angle c (deg), time t (s), ż = df/dt along the scan (mm/s).

  pose           α, β (deg), dx, dy, dz (mm): p_meas = Rx(α)Ry(β)p + d to first order, measured against
                 the nominal at the measured (x, y):  Δz = α(y + f f_y) − β(x + f f_x) − f_x dx − f_y dy + dz
  z_scale        s: Δz = s·f                               (amplification error of the z axis)
  probe_radius   ρ (mm) left uncompensated: Δz = ρ(√(1 + f_x² + f_y²) − 1)   (constant part = piston)
  squareness     EB0C (arcsec), X–C squareness: Δz = −r·EB0C        (a cone; 003 selective model)
  spindle_tilt   EBC harmonics k = 2…32 (arcsec): Δz = −r Σ (a_k cos kc + b_k sin kc)   (k = 1 is a part
                 tilt, the pose's)
  spindle_axial  EZC harmonics k = 1…32 (mm): Δz = Σ (a_k cos kc + b_k sin kc)
                 Synchronous error motions (ISO 230-7) have every integer harmonic: a_k, b_k for any k
                 up to SPINDLE_HARMONICS; `explain` fits those the scan's angular sampling resolves
                 (resolved_harmonics) one harmonic at a time and keeps the ones the gap supports.
  straightness   slide straightness over radius (mm at the rim): Δz = Σ_{k=2..4} s_k (r/R)^k
  thermal_drift  d1, d2 (mm over the scan): Δz = d1 τ + d2 τ²,  τ = (t − t₀)/T
  dynamic_lag    τ (s), a first-order measuring loop Gm = 1/(1 + τs): Δz = (1 − Gm)z ≈ τ ż
  vibration      f (Hz, as sampled — the aliased frequency), amplitude (mm), phase (deg):
                 Δz = A cos(2πft + φ)
  volumetric     a smooth machine field (fiducial/GP issue): Δz = cxx x² + cxy xy + cyy y² + cxz xz + cyz yz
                 — a catch-all: a quadratic field fits much of what the physical effects do, so
                 `explain` never names it before a physical effect that fits as well (catch_all)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ARCSEC = np.pi / 180 / 3600
DEG = np.pi / 180


@dataclass
class ScanContext:
    x: np.ndarray
    y: np.ndarray
    f: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    t: np.ndarray
    c: np.ndarray
    #: what the effects normalised by the scan are normalised by — straightness's rim radius R and
    #: thermal drift's start and duration — taken from the model's own scan when it is evaluated at
    #: other points (explain: a measurement that covers less radius or time than the model's scan read
    #: the model's own straightness as a z_scale and its drift at half its size — a review); None:
    #: the points' own (r.max(), t.min(), t.ptp())
    r_norm: float | None = None
    t0: float | None = None
    t_span: float | None = None

    #: set by with_norms_of when the points' time lies outside the scan's (another clock origin: a
    #: CMM log's clock time): thermal drift's τ then counts from the points' own start
    own_clock: bool = False

    def with_norms_of(self, x, y, t) -> "ScanContext":
        """This context normalised by the scan (x, y, t) — the model's own — instead of its points.
        Time: the scan's start and duration where the points' times lie within the scan's (a part of
        it measured); where they do not, the points count from their own start over the scan's
        duration (a review: a clock offset of 1000 s moved a drift's offset into d1, −1.2e-3 for 1e-4)."""
        r = np.hypot(np.asarray(x, float), np.asarray(y, float))
        t = np.asarray(t, float)
        self.r_norm = float(r.max()) if r.size else None
        self.t_span = float(np.ptp(t)) if t.size else None
        self.t0 = float(t.min()) if t.size else None
        if self.t0 is not None and self.t.size:
            tol = 0.01 * (self.t_span or 1.0)
            inside = self.t.min() >= self.t0 - tol and self.t.max() <= self.t0 + (self.t_span or 0.0) + tol
            if not inside:
                self.t0, self.own_clock = float(self.t.min()), True
        return self

    @property
    def r(self):
        return np.hypot(self.x, self.y)

    @property
    def zdot(self):
        """df/dt along the scan (mm/s): in time order, whatever the rows' order in the file (in row
        order a shuffled or x-sorted file lost the dynamic lag and named a vibration instead), points
        measured at one same time stamp sharing their group's rate (a zero time step gave NaN)."""
        if self.t.size < 2 or np.ptp(self.t) == 0:
            return np.zeros_like(self.f)
        order = np.argsort(self.t, kind="stable")
        ts, fs = self.t[order], self.f[order]
        tu, first, counts = np.unique(ts, return_index=True, return_counts=True)
        fu = np.add.reduceat(fs, first) / counts  # one height per time stamp (their mean)
        rate = np.gradient(fu, tu) if tu.size > 1 else np.zeros(1)
        out = np.empty_like(self.f)
        out[order] = np.repeat(rate, counts)
        return out

    @classmethod
    def from_surface(cls, surface, x, y, t, c):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        fx, fy = surface.gradient(x, y)
        return cls(x, y, surface.sag(x, y), fx, fy, np.asarray(t, float), np.asarray(c, float))


class Effect:
    name: str = ""
    params: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    linear = True
    #: a field that fits much of what the physical effects do (explain names it last on a tie)
    catch_all = False

    def params_text(self) -> str:
        return ", ".join(self.params)

    def columns(self, ctx: ScanContext) -> np.ndarray:
        raise NotImplementedError

    def apply(self, ctx: ScanContext, values: dict) -> np.ndarray:
        unknown = set(values) - set(self.params)
        if unknown:
            raise KeyError(f"effect '{self.name}' has no parameter(s) {sorted(unknown)}; "
                           f"it has {self.params_text()}")
        p = np.array([float(values.get(k, 0.0)) for k in self.params])
        return self.columns(ctx) @ p


class Pose(Effect):
    name, params, units = "pose", ("alpha_deg", "beta_deg", "dx", "dy", "dz"), ("deg", "deg", "mm", "mm", "mm")

    def columns(self, c):
        return np.column_stack([(c.y + c.f * c.fy) * DEG, -(c.x + c.f * c.fx) * DEG, -c.fx, -c.fy,
                                np.ones_like(c.x)])


class ZScale(Effect):
    name, params, units = "z_scale", ("scale",), ("1",)

    def columns(self, c):
        return c.f[:, None]


class ProbeRadius(Effect):
    name, params, units = "probe_radius", ("radius",), ("mm",)

    def columns(self, c):
        return (np.sqrt(1.0 + c.fx**2 + c.fy**2) - 1.0)[:, None]


class Squareness(Effect):
    name, params, units = "squareness", ("eb0c_arcsec",), ("arcsec",)

    def columns(self, c):
        return (-c.r * ARCSEC)[:, None]


#: the highest spindle harmonic (undulations per revolution) in the library. Error motions of precision
#: spindles lie in the low orders (bearing lobing); on a spiral at constant speed a line above this
#: order is named a vibration (and reported ambiguous with a synchronous error when it is one).
SPINDLE_HARMONICS = 32


def _lobes(c_deg, ks):
    a = np.deg2rad(c_deg)
    return np.column_stack([f(k * a) for k in ks for f in (np.cos, np.sin)])


def resolved_harmonics(ctx: ScanContext, kmax: int = SPINDLE_HARMONICS) -> int:
    """The highest harmonic of the spindle angle c that the scan's angular sampling resolves: below the
    Nyquist order 180°/Δc of Δc, the widest angular gap within a ring of the scan's outer half (where
    a tilt's signal is largest), the median over the rings; capped at ``kmax``, 0 when no ring is
    sampled. A ring is at least 1.5 times the scan's line spacing wide (the area over the path's
    length: a spiral's pitch, a raster's row spacing), so that it holds whole turns or crossings."""
    r = ctx.r
    if r.size < 8 or not np.ptp(r) > 0:
        return 0
    order = np.argsort(ctx.t, kind="stable") if np.ptp(ctx.t) > 0 else np.arange(r.size)
    length = float(np.sum(np.hypot(np.diff(ctx.x[order]), np.diff(ctx.y[order]))))
    spacing = np.pi * float(r.max()) ** 2 / max(length, 1e-300)
    r0, r1 = float(np.median(r)), float(r.max())
    n = int(max(min(8, (r1 - r0) / max(1.5 * spacing, 1e-12)), 1))
    edges = np.linspace(r0, r1, n + 1)
    ring = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, n - 1)
    cc = np.asarray(ctx.c, float) % 360.0
    gaps = []
    for i in range(n):
        ci = np.sort(cc[(ring == i) & (r >= r0)])
        if ci.size < 4:
            continue
        gaps.append(float(np.max(np.diff(np.r_[ci, ci[0] + 360.0]))))
    if not gaps:
        return 0
    gap = max(float(np.median(gaps)), 1e-9)
    return int(min(max(np.ceil(180.0 / gap) - 1, 0), kmax))


class _Harmonics(Effect):
    """A synchronous spindle error motion: harmonics k = first…SPINDLE_HARMONICS of the spindle angle,
    parameters a_k (cos), b_k (sin) with ``suffix`` (the unit in the name)."""
    first = 1
    suffix = ""
    unit = "mm"

    def __init__(self):
        self.harmonics = tuple(range(self.first, SPINDLE_HARMONICS + 1))
        self.params = tuple(f"{ab}{k}{self.suffix}" for k in self.harmonics for ab in ("a", "b"))
        self.units = (self.unit,) * len(self.params)

    def weight(self, c) -> np.ndarray:
        return np.ones_like(c.x)

    def harmonic_columns(self, c, k: int) -> np.ndarray:
        """The two columns (cos, sin) of harmonic k."""
        return self.weight(c)[:, None] * _lobes(c.c, (k,))

    def harmonic_params(self, k: int) -> tuple[str, str]:
        return f"a{k}{self.suffix}", f"b{k}{self.suffix}"

    def harmonic_block(self, c, ks) -> np.ndarray:
        """The columns (cos kc, sin kc) of every k in ks (ascending), 2 per harmonic, by the recurrence
        e^{ikc} = e^{i(k−1)c}·e^{ic} (one complex exponential for them all; error ~k·1e-16)."""
        e1 = np.exp(1j * np.deg2rad(np.asarray(c.c, float)))
        w = self.weight(c)
        out = np.empty((e1.size, 2 * len(ks)))
        ek, k0 = np.ones_like(e1), 0
        for j, k in enumerate(ks):
            ek = ek * e1 ** (k - k0) if k - k0 != 1 else ek * e1
            k0 = k
            out[:, 2 * j] = w * ek.real
            out[:, 2 * j + 1] = w * ek.imag
        return out

    def columns(self, c):
        return self.harmonic_block(c, self.harmonics)

    def apply(self, c, values):
        unknown = set(values) - set(self.params)
        if unknown:
            raise KeyError(f"effect '{self.name}' has no parameter(s) {sorted(unknown)}; "
                           f"it has {self.params_text()}")
        dz = np.zeros_like(c.x)
        for k in self.harmonics:
            a, b = (float(values.get(n, 0.0)) for n in self.harmonic_params(k))
            if a or b:
                dz = dz + self.harmonic_columns(c, k) @ np.array([a, b])
        return dz

    def params_text(self) -> str:
        a, b = self.harmonic_params(self.first)
        za, zb = self.harmonic_params(SPINDLE_HARMONICS)
        return f"{a}, {b}, … {za}, {zb} (harmonics {self.first}…{SPINDLE_HARMONICS})"


class SpindleTilt(_Harmonics):
    name = "spindle_tilt"
    first = 2
    suffix = "_arcsec"
    unit = "arcsec"

    def weight(self, c):
        return -c.r * ARCSEC


class SpindleAxial(_Harmonics):
    name = "spindle_axial"


class Straightness(Effect):
    name, params, units = "straightness", ("s2", "s3", "s4"), ("mm", "mm", "mm")

    def columns(self, c):
        r = c.r
        R = (c.r_norm if c.r_norm else float(r.max())) or 1.0
        return np.column_stack([(r / R) ** k for k in (2, 3, 4)])


class ThermalDrift(Effect):
    name, params, units = "thermal_drift", ("d1", "d2"), ("mm", "mm")

    def columns(self, c):
        T = (c.t_span if c.t_span else float(np.ptp(c.t))) or 1.0
        tau = (c.t - (c.t0 if c.t0 is not None else c.t.min())) / T
        return np.column_stack([tau, tau * tau])


class DynamicLag(Effect):
    name, params, units = "dynamic_lag", ("tau_s",), ("s",)

    def columns(self, c):
        return c.zdot[:, None]


class Vibration(Effect):
    name, params, units = "vibration", ("frequency_hz", "amplitude", "phase_deg"), ("Hz", "mm", "deg")
    linear = False

    def columns_at(self, c, f_hz):
        w = 2 * np.pi * f_hz * c.t
        return np.column_stack([np.cos(w), -np.sin(w)])  # A cos(wt + φ) = A cosφ cos wt − A sinφ sin wt

    def apply(self, c, values):
        unknown = set(values) - set(self.params)
        if unknown:
            raise KeyError(f"effect 'vibration' has no parameter(s) {sorted(unknown)}")
        f = float(values.get("frequency_hz", 0.0))
        A = float(values.get("amplitude", 0.0))
        ph = np.deg2rad(float(values.get("phase_deg", 0.0)))
        return self.columns_at(c, f) @ np.array([A * np.cos(ph), A * np.sin(ph)])

    @staticmethod
    def from_columns(f_hz, coef) -> dict:
        A = float(np.hypot(*coef))
        return {"frequency_hz": float(f_hz), "amplitude": A, "phase_deg": float(np.degrees(np.arctan2(coef[1], coef[0])))}


class Volumetric(Effect):
    name, params, units = "volumetric", ("cxx", "cxy", "cyy", "cxz", "cyz"), ("1/mm",) * 5
    catch_all = True

    def columns(self, c):
        return np.column_stack([c.x * c.x, c.x * c.y, c.y * c.y, c.x * c.f, c.y * c.f])


LIBRARY: dict[str, Effect] = {e.name: e for e in (
    Pose(), ZScale(), ProbeRadius(), Squareness(), SpindleTilt(), SpindleAxial(), Straightness(),
    ThermalDrift(), DynamicLag(), Vibration(), Volumetric())}
