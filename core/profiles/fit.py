"""Fit of a surface of revolution's meridian, posed in a profile's plane, to a stylus profile.

In the profile's vertical plane (s along the scan, z up; docs/conventions.md, Profiles) the pose of
the part is a rotation τ and a shift (ds, dz):

    (s, z) = Rot(τ)·(u, w) + (ds, dz),   Rot(τ) = [[cos τ, sin τ], [−sin τ, cos τ]],

u the signed radial coordinate along the meridian and w the height in the part frame — the x–z
restriction of p_measuring = Rx(α)·Ry(β)·p_part + d: at azimuth 0 τ = β and ds = dx; at 90° τ = −α and
ds = dy. Two residuals, as for clouds (core/geometry/posed_fit.py):

  * ``vertical`` (misalignment):  r = w − f(|u|), the form error at the contact point;
  * ``normal`` (probe_radius):    r = d − s·ρ, d the signed distance of the tip centre from the
    meridian curve (exact 2-D foot point: the surface of revolution's Newton solve in its meridian).

Analytic Jacobian: with S = s − ds, Z = z − dz and g = ∂r/∂(u, w) — (−f'(u), 1) vertical, the
in-plane normal n̂ = (n_u, n_w) for the normal residual (the foot point is stationary) —

    ∂r/∂τ = −g_u·w + g_w·u,   ∂r/∂ds = −g_u·cos τ − g_w·sin τ,   ∂r/∂dz = g_u·sin τ − g_w·cos τ,

and for design parameters ∂r/∂c = −∂f/∂c (vertical) or −n_w·∂f/∂c (normal). Levenberg–Marquardt on the
normal equations (core.geometry.lsq), uncertainties s²(JᵀJ)⁻¹.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DomainError, StepError
from ..geometry.lsq import levenberg_marquardt
from ..geometry.posed_fit import with_design
from ..surfaces import EvenAsphere, SurfaceOfRevolution

DEG = np.pi / 180.0
PROFILE_POSE = ("tilt", "decentre", "dz")
LABELS = {"tilt": "tilt in the profile's plane", "decentre": "decentre along the profile",
          "dz": "height"}
REPORT_KEY = {"tilt": "tilt_deg", "decentre": "decentre_mm", "dz": "dz", "radius": "R", "conic": "k"}


def profile_dof(dof, surface, explicit: bool = False) -> tuple[list[str], str | None]:
    """The profile DOF for a step's `dof` list (alpha/beta → tilt, dx/dy → decentre, dz, radius,
    conic, A<n>) and a note for the report. A flat has no axis: no decentre. On a sphere a tilt in the
    profile's plane *is* a decentre along it (a rotation about the centre of curvature changes
    nothing): with the default DOF the decentre is fitted and the tilt held, and the note says so."""
    out = []
    for d in dof:
        m = {"alpha": "tilt", "beta": "tilt", "dx": "decentre", "dy": "decentre"}.get(d, d)
        if m == "decentre" and surface is not None and surface.is_flat():
            continue
        if m not in out:
            out.append(m)
    sphere = (isinstance(surface, EvenAsphere) and surface.c != 0 and surface.k == 0 and not surface.A
              and "conic" not in out and not any(n.startswith("A") for n in out))
    if sphere and not explicit and "tilt" in out and "decentre" in out:
        out.remove("tilt")
        return out, ("the nominal is a sphere: a tilt in the profile's plane is a decentre along it, so "
                     "the decentre is fitted and the tilt held at its initial value")
    return out, None


@dataclass
class ProfileFitResult:
    names: list[str]
    values: dict
    uncertainty: dict
    correlation: np.ndarray
    condition_number: float
    residuals: np.ndarray
    iterations: int
    surface: SurfaceOfRevolution
    u: np.ndarray  # part-frame meridian coordinates of the points at the fitted pose
    w: np.ndarray
    warnings: list[str] = field(default_factory=list)

    def rotate(self, vs, vz):
        """Part-frame in-plane vectors (u, w) into the measuring plane (s, z)."""
        t = self.values["tilt"] * DEG
        c, s_ = np.cos(t), np.sin(t)
        return c * vs + s_ * vz, -s_ * vs + c * vz

    def report(self) -> dict:
        rep = {REPORT_KEY.get(n, n): self.values[n] for n in self.names}
        rep["uncertainty"] = {REPORT_KEY.get(n, n): self.uncertainty[n] for n in self.names}
        rep["parameters"] = list(self.names)
        rep["correlation"] = np.round(self.correlation, 6).tolist()
        rep["condition_number"] = self.condition_number
        rep["iterations"] = self.iterations
        return rep


class ProfileFit:
    """Fit tilt, decentre along, height (and chosen design parameters) of ``surface``'s meridian to a
    profile (s, z) in its plane. ``initial``: starting / held values (tilt in degrees, mm)."""

    def __init__(self, surface, s, z, free, initial=None, residual="vertical", offset=0.0,
                 max_iter=100, check=None, name="profile"):
        if not isinstance(surface, SurfaceOfRevolution):
            raise StepError(f"{name}: a profile is fitted to a surface of revolution's meridian (this "
                            f"recipe's surface is {surface.kind}); measure a freeform areally")
        self.surface0 = surface
        self.s = np.asarray(s, dtype=np.float64)
        self.z = np.asarray(z, dtype=np.float64)
        self.free = list(free)
        self.design_free = [n for n in self.free if n not in PROFILE_POSE]
        if self.design_free and not isinstance(surface, EvenAsphere):
            raise StepError(f"fitting {self.design_free} needs an even-asphere nominal "
                            f"(this recipe's surface is {surface.kind})")
        self.given = dict(initial or {})
        self.initial = {n: 0.0 for n in PROFILE_POSE} | self.given
        self.residual = residual
        self.offset = float(offset)
        self.max_iter = max_iter
        self.check = check
        self.name = name

    def _unpack(self, x):
        vals = dict(self.initial)
        vals.update({n: v for n, v in zip(self.free, x) if n in PROFILE_POSE})
        surf = with_design(self.surface0, self.free, x, PROFILE_POSE) if self.design_free else self.surface0
        return vals, surf

    def part(self, vals):
        t = vals["tilt"] * DEG
        c, s_ = np.cos(t), np.sin(t)
        S, Z = self.s - vals["decentre"], self.z - vals["dz"]
        return c * S - s_ * Z, s_ * S + c * Z, c, s_

    def model(self, x, want_jac: bool):
        vals, surf = self._unpack(x)
        u, w, c, s_ = self.part(vals)
        au = np.abs(u)
        if self.residual == "vertical":
            f, fr, _ = surf.profile_r(au)
            r = w - f
            if not want_jac:
                return r, None
            gu, gw = -np.sign(u) * fr, np.ones_like(u)
            rad = au
            dz_design = 1.0
        else:
            foot, n, dist = surf.foot_point(np.column_stack([u, np.zeros_like(u), w]))
            r = dist - self.offset
            if not want_jac:
                return r, None
            gu, gw = n[:, 0], n[:, 2]
            rad = np.abs(foot[:, 0])
            dz_design = gw
        J = np.empty((len(r), len(self.free)), order="F")
        design = None
        if self.design_free:
            names = ["c" if m == "radius" else "k" if m == "conic" else m for m in self.design_free]
            design = dict(zip(self.design_free, surf.parameter_derivatives(rad, names).values()))
        for j, nm in enumerate(self.free):
            if nm == "tilt":
                J[:, j] = (-gu * w + gw * u) * DEG
            elif nm == "decentre":
                J[:, j] = -gu * c - gw * s_
            elif nm == "dz":
                J[:, j] = gu * s_ - gw * c
            else:
                J[:, j] = -design[nm] * dz_design
        return r, J

    def fit(self) -> ProfileFitResult:
        n, k = len(self.s), len(self.free)
        if n <= k:
            named = ", ".join(LABELS.get(f, f) for f in self.free)
            raise StepError(f"{self.name}: {n} point{'' if n == 1 else 's'} for {k} parameters ({named}): "
                            "need more points than parameters — fewer DOF or a longer scan")
        if "dz" in self.free and "dz" not in self.given:
            try:
                vals = dict(self.initial)
                u, w, _, _ = self.part(vals | {"dz": 0.0})
                gap = w - self.surface0.sag_r(np.abs(u))
                self.initial["dz"] = float(np.median(gap)) - (self.offset if self.residual == "normal"
                                                              else 0.0)
            except DomainError:
                pass
        x0 = []
        for nm in self.free:
            if nm in PROFILE_POSE:
                x0.append(self.initial[nm])
            elif nm == "radius":
                x0.append(self.surface0.c)
            elif nm == "conic":
                x0.append(self.surface0.k)
            else:
                x0.append(self.surface0.A.get(int(nm[1:]), 0.0))
        try:
            res = levenberg_marquardt(self.model, np.array(x0, dtype=np.float64), max_iter=self.max_iter,
                                      check=self.check)
        except DomainError as e:
            raise StepError(f"{self.name}: at the starting pose: {e}") from None
        if not res.converged and "tilt" in self.free and "decentre" in self.free:
            _, cond = res.covariance()
            if cond > 1e3:
                raise StepError(f"{self.name}: the fit cannot separate the tilt in the profile's plane from "
                                f"the decentre along it (condition number {cond:.3g}): on a nearly "
                                "spherical part they are one motion — hold one (e.g. `dof: [dx, dz]`)")
        if not res.converged:
            raise StepError(f"{self.name}: the fit did not converge ({res.message}, {res.iterations} "
                            "iterations): check the data's units (mm), the nominal surface, the probe side, "
                            "or give initial values for the pose")
        vals, surf = self._unpack(res.x)
        cov, cond = res.covariance()
        sig = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = np.nan_to_num(cov / np.outer(sig, sig))
        values = {nm: float(v) for nm, v in zip(self.free, res.x)}
        unc = {nm: float(v) for nm, v in zip(self.free, sig)}
        for nm in PROFILE_POSE:
            values.setdefault(nm, float(vals[nm]))
        if "radius" in self.free:
            c = values["radius"]
            values["radius"] = 1.0 / c if c else np.inf
            unc["radius"] = unc["radius"] / (c * c) if c else np.inf
        warnings = []
        if cond > 1e3:
            pairs = [f"{self.free[i]}/{self.free[j]} ({corr[i, j]:+.6f})" for i in range(k)
                     for j in range(i + 1, k) if abs(corr[i, j]) > 0.999]
            sphere = any(p.startswith(("tilt/decentre", "decentre/tilt")) for p in pairs)
            warnings.append(
                f"{self.name}: ill-posed fit (condition number {cond:.3g}): "
                f"{', '.join(pairs) or 'several parameters'} trade off"
                + (" — on a nearly spherical part a tilt in the profile's plane is a decentre along it"
                   if sphere else "")
                + ". These values are not separately meaningful: hold one (leave it out of `dof`, give "
                "it in `initial`) to read the other. The residual is that of the best pose along the "
                "trade-off (exactly so on a circle); form error such a pose change reproduces is in the "
                "pose, not in the residual")
        u, w, _, _ = self.part(vals)
        return ProfileFitResult(list(self.free), values, unc, corr, float(cond), res.residuals,
                                res.iterations, surf, u, w, warnings)


def initial_for(p_angle_deg: float, initial: dict) -> dict:
    """A step's `initial` pose (alpha, beta, dx, dy, dz) as the profile's (tilt, decentre, dz): the
    in-plane components at azimuth θ (tilt = β cos θ − α sin θ to first order)."""
    t = np.radians(p_angle_deg)
    out = {}
    if "alpha" in initial or "beta" in initial:
        out["tilt"] = initial.get("beta", 0.0) * np.cos(t) - initial.get("alpha", 0.0) * np.sin(t)
    if "dx" in initial or "dy" in initial:
        out["decentre"] = initial.get("dx", 0.0) * np.cos(t) + initial.get("dy", 0.0) * np.sin(t)
    if "dz" in initial:
        out["dz"] = initial["dz"]
    return out


def pose_record(p, rep: dict) -> dict:
    """One profile's line of a step report: its label, azimuth, points and each fitted pose/shape
    parameter with its standard uncertainty (``u_<name>``), from ``ProfileFit.report()``."""
    rec = {"profile": p.label, "angle_deg": p.angle_deg, "points": len(p.rows)}
    for key in ("tilt_deg", "decentre_mm", "dz", "R", "k"):
        if key in rep:
            rec[key] = rep[key]
            rec["u_" + key] = rep["uncertainty"][key]
    return rec
