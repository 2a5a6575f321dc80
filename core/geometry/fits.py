"""Least-squares sphere, plane and circle fits with standard uncertainties.

Every fit minimises orthogonal (geometric) distances, not algebraic ones, and returns a `FitResult`:
the parameters, their standard uncertainties and covariance
    Σ = s² (JᵀJ)⁻¹,   s² = Σ rᵢ² / (n − p)            (GUM / ISO 10360-6 style, Type A)
computed from the analytic Jacobian J at the solution, the correlation matrix and the condition
number of J (column-scaled), so that an ill-posed fit (e.g. a sphere from a small patch: centre and
radius trade) warns instead of returning silent garbage.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import StepError

ILL_CONDITIONED = 1e8


@dataclass
class FitResult:
    names: list[str]
    values: np.ndarray
    covariance: np.ndarray
    residuals: np.ndarray
    condition_number: float
    extra: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def params(self) -> dict[str, float]:
        return dict(zip(self.names, map(float, self.values)))

    @property
    def uncertainty(self) -> dict[str, float]:
        return dict(zip(self.names, map(float, np.sqrt(np.clip(np.diag(self.covariance), 0, None)))))

    @property
    def correlation(self) -> np.ndarray:
        s = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            c = self.covariance / np.outer(s, s)
        return np.nan_to_num(c)

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.residuals ** 2)))

    @property
    def dof(self) -> int:
        return len(self.residuals) - len(self.names)

    def __getitem__(self, name):
        return self.params[name]

    def to_report(self) -> dict:
        return {**self.params, "uncertainty": self.uncertainty,
                "correlation": np.round(self.correlation, 6).tolist(), "rms": self.rms,
                "dof": self.dof, "condition_number": self.condition_number, **self.extra,
                "warnings": list(self.warnings)}


def _covariance(jac: np.ndarray, residuals: np.ndarray, npar: int):
    return _covariance_normal(jac.T @ jac, residuals, npar)


def _covariance_normal(a: np.ndarray, residuals: np.ndarray, npar: int):
    """(s² (JᵀJ)⁻¹, cond of the column-scaled J) from the normal matrix a = JᵀJ (p × p)."""
    n = len(residuals)
    dof = n - npar
    s2 = float(residuals @ residuals) / dof if dof > 0 else np.nan
    # the normal matrix of the column-scaled Jacobian: p × p, whatever the number of points
    scale = np.sqrt(np.diag(a)).copy()
    scale[scale == 0] = 1.0
    a_s = a / np.outer(scale, scale)
    ev, vec = np.linalg.eigh(a_s)
    cond = float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else np.inf  # cond(J_s) = sqrt(cond(J_sᵀJ_s))
    # the inverse on every direction, however weakly determined: a pseudo-inverse drops directions
    # below ~1e-15 of the largest, and the parameters along them got a variance of ~0 instead of a
    # huge one (a sphere fitted with 5 DOF: u(α) 4.6e-6° for an α 0.1° off); an undetermined
    # direction (eigenvalue ≤ 0) makes its parameters' variance infinite
    null = ev <= 0
    jtj_inv = (vec[:, ~null] / ev[~null]) @ vec[:, ~null].T
    if null.any():
        loose = np.any(np.abs(vec[:, null]) > 1e-3, axis=1)  # the parameters along the null space
        jtj_inv[loose, :] = np.inf
        jtj_inv[:, loose] = np.inf
    jtj_inv = jtj_inv / np.outer(scale, scale)
    with np.errstate(invalid="ignore"):  # an exact fit (s² = 0) along an undetermined direction: inf
        cov = s2 * jtj_inv
    if not np.isnan(s2):
        cov[np.isinf(jtj_inv)] = np.inf
    return cov, cond


def _finish(names, values, jac, res, extra=None) -> FitResult:
    cov, cond = _covariance(jac, res, len(names))
    warn = []
    if len(res) - len(names) <= 0:
        warn.append(f"no redundancy: {len(res)} points for {len(names)} parameters; uncertainties unknown")
    if cond > ILL_CONDITIONED:
        warn.append(f"ill-conditioned fit (condition number {cond:.3g}): parameters are strongly "
                    "correlated; spread the points over more of the feature")
    return FitResult(list(names), np.asarray(values, float), cov, res, cond, extra or {}, warn)


def _points(p, min_n, what):
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise StepError(f"{what} fit: expected (N, 3) points")
    if len(p) < min_n:
        raise StepError(f"{what} fit needs at least {min_n} points, got {len(p)}")
    if not np.all(np.isfinite(p)):
        raise StepError(f"{what} fit: non-finite coordinates")
    return p


# ---------------------------------------------------------------------------------------- sphere
def fit_sphere(points, radius: float | None = None) -> FitResult:
    """Sphere by orthogonal distance rᵢ = |pᵢ − c| − R; R free, or fixed (e.g. a calibrated ball).

    Start: the algebraic (Kåsa) fit |p|² = 2 p·c + (R² − |c|²), linear in c and R² − |c|².
    """
    p = _points(points, 4 if radius is None else 3, "sphere")
    a = np.column_stack([2 * p, np.ones(len(p))])
    sol, *_ = np.linalg.lstsq(a, np.einsum("ij,ij->i", p, p), rcond=None)
    c0 = sol[:3]
    r0 = float(np.sqrt(max(sol[3] + c0 @ c0, 0.0)))
    if radius is not None:
        r_fixed = float(radius)
        if r_fixed <= 0:
            raise StepError("sphere fit: fixed radius must be > 0")
        # start on the side of the patch where the Kåsa centre lies, at the given radius
        mean = p.mean(axis=0)
        d = c0 - mean
        nd = np.linalg.norm(d)
        c0 = mean + (d / nd if nd > 0 else np.array([0, 0, -1.0])) * r_fixed

    def fun(q):
        c = q[:3]
        r = r_fixed if radius is not None else q[3]
        return np.linalg.norm(p - c, axis=1) - r

    def jac(q):
        d = p - q[:3]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        return -u if radius is not None else np.column_stack([-u, -np.ones(len(p))])

    from scipy.optimize import least_squares  # lazy: 0.8 s of every batch's start (issue 17)

    x0 = c0 if radius is not None else np.r_[c0, r0]
    sol = least_squares(fun, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    names = ["x0", "y0", "z0"] + ([] if radius is not None else ["radius"])
    extra = {"radius_fixed": radius is not None, "iterations": int(sol.nfev)}
    if radius is not None:
        extra["radius"] = float(radius)
    return _finish(names, sol.x, jac(sol.x), fun(sol.x), extra)


# ----------------------------------------------------------------------------------------- plane
def fit_plane(points) -> FitResult:
    """Total-least-squares plane n̂·p = d (SVD of the centred points; n̂ oriented +z).

    Parameters reported: the normal's tilts ``tilt_u``, ``tilt_v`` (rad, rotations of n̂ towards the
    plane's in-plane axes ê₁, ê₂ — zero at the solution, their uncertainty is the normal's angular
    uncertainty) and the offset ``d`` (mm) along n̂ at the centroid. ``flatness`` = PV of residuals.
    """
    p = _points(points, 3, "plane")
    centroid = p.mean(axis=0)
    q = p - centroid
    _, s, vt = np.linalg.svd(q, full_matrices=False)
    n = vt[2]
    if n[2] < 0 or (n[2] == 0 and (n[1] < 0 or (n[1] == 0 and n[0] < 0))):
        n = -n
    e1, e2 = vt[0], np.cross(n, vt[0])
    res = q @ n
    jac = np.column_stack([q @ e1, q @ e2, -np.ones(len(p))])
    d = float(n @ centroid)
    extra = {"normal": n.tolist(), "centroid": centroid.tolist(), "axis_u": e1.tolist(),
             "axis_v": e2.tolist(), "flatness": float(np.ptp(res)) if len(res) else 0.0}
    out = _finish(["tilt_u", "tilt_v", "d"], [0.0, 0.0, d], jac, res, extra)
    if s[1] <= 1e-12 * max(s[0], 1e-300):
        out.warnings.append("points are collinear: the plane is not determined")
    return out


# ---------------------------------------------------------------------------------------- circle
def fit_circle(points) -> FitResult:
    """Circle by orthogonal distance. 2-D points (N, 2): in x, y. 3-D points: first a TLS plane,
    then the circle in that plane (centre reported in 3-D as ``center``).

    rᵢ = |qᵢ − c| − R with start from the algebraic (Kåsa) fit.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 2 and p.shape[1] == 2:
        q2, plane = p, None
        if len(q2) < 3:
            raise StepError(f"circle fit needs at least 3 points, got {len(q2)}")
    else:
        p = _points(p, 3, "circle")
        plane = fit_plane(p)
        c = np.asarray(plane.extra["centroid"])
        e1, e2 = np.asarray(plane.extra["axis_u"]), np.asarray(plane.extra["axis_v"])
        q2 = np.column_stack([(p - c) @ e1, (p - c) @ e2])
    a = np.column_stack([2 * q2, np.ones(len(q2))])
    sol, *_ = np.linalg.lstsq(a, np.einsum("ij,ij->i", q2, q2), rcond=None)
    x0 = np.r_[sol[:2], np.sqrt(max(sol[2] + sol[:2] @ sol[:2], 0.0))]

    def fun(t):
        return np.linalg.norm(q2 - t[:2], axis=1) - t[2]

    def jac(t):
        d = q2 - t[:2]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        return np.column_stack([-u, -np.ones(len(q2))])

    from scipy.optimize import least_squares

    s = least_squares(fun, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    extra = {}
    names = ["x0", "y0", "radius"]
    if plane is not None:
        centre3 = c + s.x[0] * e1 + s.x[1] * e2
        extra = {"center": centre3.tolist(), "normal": plane.extra["normal"],
                 "out_of_plane_rms": plane.rms}
        names = ["u0", "v0", "radius"]
    out = _finish(names, s.x, jac(s.x), fun(s.x), extra)
    if plane is not None:
        out.warnings.extend(plane.warnings)
    return out
