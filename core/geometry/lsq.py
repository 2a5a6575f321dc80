"""Levenberg–Marquardt on the normal equations, for large point clouds and few parameters.

scipy's ``least_squares`` works on the N × p Jacobian (QR/SVD each iteration) and, without an
analytic Jacobian, spends p extra model evaluations per iteration on finite differences. For a pose
(5 parameters) on 10⁶ points what matters is evaluating the model and its analytic Jacobian *once*
per iteration; the p × p normal equations JᵀJ δ = −Jᵀr then cost nothing. Columns are scaled to unit
norm before solving (Marquardt's scaling), so the conditioning is that of the scaled Jacobian.
At the solution the residual is re-evaluated in full precision, so solving the normal equations
(rather than QR) limits only the step, not the accuracy of the converged parameters.

The model is one callable ``model(x, want_jacobian) -> (r, J or None)``; a trial step that leaves the
model's domain (it raises DomainError) is rejected like a step that increases the cost. For millions of
points ``levenberg_marquardt_normal`` takes a model that returns the normal equations themselves,
``(r, JᵀJ, Jᵀr)``, accumulated over chunks of points, so that no N × p Jacobian is ever held (issue 26:
the iteration then holds the residual of the current and of the trial parameters, two columns).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import DomainError


@dataclass
class LMResult:
    x: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray | None  # None from levenberg_marquardt_normal: see ``normal``
    iterations: int
    converged: bool
    message: str
    cost_history: list = field(default_factory=list)
    normal: np.ndarray | None = None  # JᵀJ at x (p × p)

    def covariance(self) -> tuple[np.ndarray, float]:
        """(s² (JᵀJ)⁻¹, condition number of the column-scaled J), s² = rᵀr / (n − p)."""
        from .fits import _covariance, _covariance_normal

        if self.jacobian is None:
            return _covariance_normal(self.normal, self.residuals, len(self.x))
        return _covariance(self.jacobian, self.residuals, len(self.x))

    @property
    def cost(self) -> float:
        return float(self.residuals @ self.residuals)


def levenberg_marquardt(model: Callable, x0, **options) -> LMResult:
    """Minimise |r(x)|² for ``model(x, want_jacobian) -> (r, J)`` (options: see ``_lm``)."""
    def evaluate(x):
        r, J = model(x, True)
        return r, J.T @ J, J.T @ r, J

    return _lm(evaluate, x0, **options)


def levenberg_marquardt_normal(model: Callable, x0, **options) -> LMResult:
    """Minimise |r(x)|² for ``model(x) -> (r, JᵀJ, Jᵀr)``: the normal equations accumulated by the
    model (over chunks of points), no Jacobian held; the same iteration as ``levenberg_marquardt``."""
    return _lm(lambda x: (*model(x), None), x0, **options)


#: a residual RMS below this (mm: a femtometre) is an exact fit — no measurement tells it from zero
RMS_FLOOR_MM = 1e-12


def _lm(evaluate: Callable, x0, *, max_iter: int = 100, xtol: float = 1e-12, ftol: float = 1e-10,
        floor: float = 1e-13, check: Callable[[], None] | None = None) -> LMResult:
    """Minimise |r(x)|². Converged when an accepted step is below ``xtol`` relative to x, or lowers
    the cost by less than ``ftol`` of it (a parameter error that small moves the fit by 10⁻⁵ of the
    residual's RMS), or when the linear model predicts a gain below ``floor``·cost — the floor set by
    rounding, where no step can be told from noise (without this test LM would keep damping steps
    it cannot accept) — or when the residual's RMS is below RMS_FLOOR_MM (a review: noise-free points
    at 4e-25 mm² of cost kept lowering it by more than ``ftol``·cost each step, rounding against
    rounding, and the fit was refused as "did not converge" after 100 iterations)."""
    x = np.asarray(x0, dtype=np.float64).copy()
    r, A0, g0, J = evaluate(x)
    cost = float(r @ r)
    history = [cost]
    lam = 0.0  # start as pure Gauss–Newton; damp only when a step fails
    converged, message = False, "maximum number of iterations reached"
    it = 0
    for it in range(1, max_iter + 1):
        if check is not None:
            check()
        scale = np.sqrt(np.diag(A0)).copy()
        scale[scale == 0] = 1.0
        A = A0 / np.outer(scale, scale)  # normal matrix of the column-scaled Jacobian
        g = g0 / scale
        accepted = False
        at_floor = False
        for _ in range(30):
            # minimum-norm solve: directions the data cannot determine (a sphere's tilt ≈ decenter,
            # eigenvalues below 1e-14 of the largest, i.e. cond(J) > 10⁷) are not moved at all
            step_s = np.linalg.lstsq(A + lam * np.eye(len(x)), -g, rcond=1e-14)[0]
            predicted = -(2.0 * g @ step_s + step_s @ A @ step_s)
            if predicted <= floor * cost:
                at_floor = True
                break
            step = step_s / scale
            x_new = x + step
            try:  # evaluate with the Jacobian: Gauss–Newton steps are nearly always accepted
                r_new, A0_new, g0_new, J_new = evaluate(x_new)
                cost_new = float(r_new @ r_new)
            except DomainError:
                cost_new = np.inf
            if np.isfinite(cost_new) and cost_new <= cost:
                accepted = True
                break
            r_new = A0_new = g0_new = J_new = None  # rejected: not held while the next one is evaluated
            lam = max(lam * 10.0, 1e-6)
        if at_floor:
            converged, message = True, "converged (no gain left above rounding)"
            break
        if not accepted:
            message = "no step reduces the cost (the model may be far from the data)"
            break
        small_step = np.all(np.abs(step) <= xtol * (np.abs(x_new) + xtol))
        small_gain = (cost - cost_new) <= ftol * cost
        x, r, A0, g0, J = x_new, r_new, A0_new, g0_new, J_new
        r_new = A0_new = g0_new = J_new = None
        cost = cost_new
        history.append(cost)
        lam = lam / 10.0 if lam > 1e-9 else 0.0
        if small_step or small_gain or cost <= RMS_FLOOR_MM ** 2 * max(len(r), 1):
            converged = True
            message = "converged"
            break
    return LMResult(x, r, J, it, converged, message, history, A0)
