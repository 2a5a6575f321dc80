"""Fiducial-aided calibration: the 12-parameter transform between calibrated and measured fiducial
centres with its GUM uncertainty (seed papers 000 eqs 3–11 and 001 eqs 1–14).

    X_c = D X_r + A        (D a full 3 × 3 matrix: rotation, scale and shear of the machine frame;
                            A the translation — 12 parameters D1…D9, Ax, Ay, Az)
fitted by least squares (001 eq 11; with one σ per axis the weights do not change the solution). Each axis k is
a linear least-squares problem in (D_k1, D_k2, D_k3, A_k) with the design [X_r, 1]; its covariance
σ_m,k² (XᵀX)⁻¹ is the inverse normal matrix of 001 eq 15/16. The calibrated positions carry σ_r too
(001 eqs 6–7): their effect is propagated by the Jacobian ∂θ/∂X_r (computed by central differences)
and added: Σθ = Σ_m + J_r diag(σ_r²) J_rᵀ. A transformed point's standard uncertainty is
u(X_c)² = g Σθ gᵀ with g = ∂X_c/∂θ (001 eqs 12–14, with every covariance term). The reduced χ² is
reported against 3N − 12 degrees of freedom (000 prints 3N − 8), χ² = Σ_i Σ_k (X_m,ik − X_c,ik)² /
(σ_m,k² + Σ_j D_kj² σ_r,j²): both centres' noise reaches the residuals (``residual_variance``).

The affine transform needs four fiducials that are not coplanar (rank of [X_r, 1] = 4); fewer, or a
nearly coplanar set (condition number of the centred positions > 1e3), is said with the numbers.
Volumetric error at a fiducial: e_i = X_c(X_r,i) − X_m,i, Ev_i = |e_i| (000).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import StepError

PARAMS = ("D1", "D2", "D3", "D4", "D5", "D6", "D7", "D8", "D9", "Ax", "Ay", "Az")


#: the layout's second singular value (centred) below this × its first: nearly collinear — the balls' spread
#: off their line is then within 1e-4 of its length (20 µm over 200 mm), a few times a centre's noise
#: (0.2–1 µm) over √n balls, so the off-line rotation and scales are determined to no better than percents
NEARLY_COLLINEAR = 1e-4


def layout_check(ref) -> tuple[float, list[str]]:
    """(condition number of the centred layout, warnings); StepError when it cannot determine D."""
    ref = np.asarray(ref, dtype=np.float64)
    n = ref.shape[0]
    if n < 3:
        raise StepError(f"{n} fiducial(s): the transform needs at least 3 non-collinear balls "
                        "(4 non-coplanar for all 12 parameters)")
    s = np.linalg.svd(ref - ref.mean(axis=0), compute_uv=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    if s[1] <= 1e-9 * s[0]:
        raise StepError(f"the {n} fiducials are collinear (singular values {s.round(6).tolist()} mm): "
                        "no transform can be determined")
    if s[1] <= NEARLY_COLLINEAR * s[0]:
        # a review: 10 balls 1 µm off a 200 mm line (s₁/s₀ 2e-5) passed this test and failed the frame check
        # with "scaled by 0.98…1.18 — give both in mm": the scale and rotation off the line were noise
        _, _, vt = np.linalg.svd(ref - ref.mean(axis=0), full_matrices=False)
        length = float(np.ptp((ref - ref.mean(axis=0)) @ vt[0]))
        raise StepError(f"the {n} fiducials are nearly collinear (they stray {s[1] / np.sqrt(n) * 1e3:.3g} µm RMS "
                        f"from a line of {length:.4g} mm along {vt[0].round(4).tolist()}; singular "
                        f"values {s.round(6).tolist()} mm): the transform is undetermined across that line "
                        "(rotation about it, scale and shear off it) — add balls away from it")
    if n < 4 or s[2] <= 1e-9 * s[0]:
        raise StepError(f"the {n} fiducials are coplanar (singular values {s.round(6).tolist()} mm): "
                        "the 12-parameter transform is undetermined out of their plane — add a ball "
                        "at another height (4 non-coplanar at least)")
    warnings = []
    if cond > 1e3 and s[1] <= 1e-3 * s[0]:
        warnings.append(f"the fiducials are nearly collinear (singular values {s.round(4).tolist()} mm): the "
                        "transform is poorly determined across their line (rotation about it, scale off it)")
    elif cond > 1e3:
        warnings.append(f"the fiducials are nearly coplanar (condition number {cond:.3g}): the transform "
                        "is poorly determined out of their plane")
    if 3 * n - 12 <= 6:
        warnings.append(f"{n} fiducials leave {3 * n - 12} degrees of freedom for the χ² check")
    return cond, warnings


#: how far a machine frame's scale may differ from the reference's: a CMM's scale errors are parts per
#: million to a few per thousand; 10 % means the two files are not in the same unit or not the same balls
SCALE_TOLERANCE = 0.1
_UNIT_RATIOS = {1000.0: "the measured centres are in mm and the reference in metres",
                1e-3: "the reference is in µm or the measured centres in metres",
                25.4: "the reference is in inches", 1 / 25.4: "the measured centres are in inches"}


def frame_check(D, ref=None) -> str | None:
    """Why the fitted D (X_c = D X_r + A) cannot be a machine frame's small distortion, or None.

    Its singular values are the scales along the principal directions: a reference in metres against
    centres in mm fits exactly with D ≈ 1000·R (a review: such a reference calibrated silently), and a
    negative determinant is a mirror — an axis whose sign differs between the two files. ``ref``: the
    reference layout; when it is nearly coplanar (layout_check's condition number > 10³) the scale out
    of its plane is not determined (balls on one plate, 5 µm apart in height under 1 µm of noise read
    0.84…1.18: a review), so only the scales within the plane are judged, and no mirror."""
    D = np.asarray(D, dtype=np.float64)
    if ref is not None:
        ref = np.asarray(ref, dtype=np.float64)
        _, sv, vt = np.linalg.svd(ref - ref.mean(axis=0), full_matrices=False)
        if sv[-1] <= 0 or sv[0] / sv[-1] > 1e3:
            D = D @ vt[:2].T  # D on the layout's plane: its two in-plane scales
    s = np.linalg.svd(D, compute_uv=False)
    if s[-1] < 1 - SCALE_TOLERANCE or s[0] > 1 + SCALE_TOLERANCE:
        mean = float(np.exp(np.mean(np.log(np.maximum(s, 1e-300)))))
        hint = next((f" — perhaps {why}" for r, why in _UNIT_RATIOS.items() if abs(np.log(mean / r)) < 0.05),
                    "")
        return (f"the measured centres are the reference scaled by {s[-1]:.6g}…{s[0]:.6g}, where a machine "
                f"frame's scale differs from 1 by less than {SCALE_TOLERANCE * 100:g} %{hint}; give both in mm, "
                "for the same balls")
    if D.shape == (3, 3) and np.linalg.det(D) < 0:
        return ("the measured centres are a mirror image of the reference (the transform's determinant "
                "is negative): an axis's sign differs between the two files")
    return None


def _solve(ref, meas):
    X = np.column_stack([ref, np.ones(len(ref))])
    theta, *_ = np.linalg.lstsq(X, meas, rcond=None)  # (4, 3): column k = (D_k1, D_k2, D_k3, A_k)
    D = theta[:3].T
    A = theta[3]
    return np.r_[D.ravel(), A]


@dataclass
class AffineFit:
    theta: np.ndarray            # (12,) D1…D9, Ax, Ay, Az
    cov: np.ndarray              # (12, 12)
    chi2: float
    dof: int
    cond: float
    residuals: np.ndarray        # (N, 3) measured − transformed (mm)
    warnings: list = field(default_factory=list)

    @property
    def D(self):
        return self.theta[:9].reshape(3, 3)

    @property
    def A(self):
        return self.theta[9:]

    def transform(self, p) -> np.ndarray:
        return np.asarray(p, dtype=np.float64) @ self.D.T + self.A

    def inverse(self, q) -> np.ndarray:
        return np.linalg.solve(self.D, (np.asarray(q, dtype=np.float64) - self.A).T).T

    def jacobian(self, p) -> np.ndarray:
        """(N, 3, 12) ∂X_c/∂θ."""
        p = np.atleast_2d(np.asarray(p, dtype=np.float64))
        J = np.zeros((p.shape[0], 3, 12))
        for k in range(3):
            J[:, k, 3 * k: 3 * k + 3] = p
            J[:, k, 9 + k] = 1.0
        return J

    def point_sigma(self, p) -> np.ndarray:
        """(N, 3) standard uncertainties of transformed points (001 eqs 12–14, full covariance)."""
        J = self.jacobian(p)
        return np.sqrt(np.einsum("nkp,pq,nkq->nk", J, self.cov, J))

    @property
    def volumetric_errors(self) -> np.ndarray:
        return -self.residuals

    def to_dict(self) -> dict:
        return {"params": dict(zip(PARAMS, self.theta.tolist())), "covariance": self.cov.tolist(),
                "chi2": self.chi2, "dof": self.dof, "chi2_reduced": self.chi2 / max(self.dof, 1),
                "condition_number": self.cond}


def fit_affine(ref, meas, sigma_m, sigma_r=(0.0, 0.0, 0.0)) -> AffineFit:
    """The weighted fit and its covariance (module doc). σ in mm, per axis."""
    ref = np.asarray(ref, dtype=np.float64)
    meas = np.asarray(meas, dtype=np.float64)
    sm = np.broadcast_to(np.asarray(sigma_m, dtype=np.float64), (3,))
    sr = np.broadcast_to(np.asarray(sigma_r, dtype=np.float64), (3,))
    if np.any(sm <= 0):
        raise StepError("the measured fiducials' σ must be > 0 in every axis")
    cond, warnings = layout_check(ref)
    theta = _solve(ref, meas)
    X = np.column_stack([ref, np.ones(len(ref))])
    inv = np.linalg.inv(X.T @ X)
    cov = np.zeros((12, 12))
    for k in range(3):
        idx = [3 * k, 3 * k + 1, 3 * k + 2, 9 + k]
        cov[np.ix_(idx, idx)] = sm[k] ** 2 * inv
    if np.any(sr > 0):
        h = 1e-6
        Jr = np.zeros((12, ref.size))
        for i in range(ref.shape[0]):
            for k in range(3):
                dp = np.zeros_like(ref)
                dp[i, k] = h
                Jr[:, 3 * i + k] = (_solve(ref + dp, meas) - _solve(ref - dp, meas)) / (2 * h)
        cov = cov + Jr @ np.diag(np.tile(sr ** 2, ref.shape[0])) @ Jr.T
    fit = AffineFit(theta, cov, 0.0, 3 * len(ref) - 12, cond, np.zeros_like(ref), warnings)
    fit.residuals = meas - fit.transform(ref)
    # the residual of axis k holds the measured centre's noise and the calibrated one's carried through
    # the transform, −Σ_j D_kj δX_r,j: its variance σ_m,k² + Σ_j D_kj² σ_r,j² (a review: with σ_m alone
    # χ²/ν read ~5 on a machine without volumetric error at the defaults σ_r 0.2 µm, σ_m 0.1 µm)
    fit.chi2 = float(np.sum(fit.residuals ** 2 / residual_variance(fit.D, sm, sr)))
    return fit


def residual_variance(D, sigma_m, sigma_r) -> np.ndarray:
    """(3,) the variance of a fiducial's residual X_m − (D X_r + A) per axis from the noise of both
    centres: σ_m,k² + Σ_j D_kj² σ_r,j² (the χ² check's weights, before the fit's 12 parameters take
    their share — that is the 3N − 12 of the degrees of freedom)."""
    sm = np.broadcast_to(np.asarray(sigma_m, dtype=np.float64), (3,))
    sr = np.broadcast_to(np.asarray(sigma_r, dtype=np.float64), (3,))
    return sm ** 2 + np.asarray(D, dtype=np.float64) ** 2 @ sr ** 2


def monte_carlo(ref, meas, sigma_m, sigma_r, points, runs: int = 3000, seed: int = 0) -> np.ndarray:
    """GUM Supplement 1: the (N, 3) standard deviation of transformed ``points`` over ``runs`` fits
    with the measured and calibrated centres drawn from their normal distributions."""
    rng = np.random.default_rng(seed)
    ref = np.asarray(ref, float)
    meas = np.asarray(meas, float)
    out = np.empty((runs, len(points), 3))
    sm = np.broadcast_to(np.asarray(sigma_m, float), (3,))
    sr = np.broadcast_to(np.asarray(sigma_r, float), (3,))
    P = np.asarray(points, float)
    for r in range(runs):
        th = _solve(ref + rng.normal(0, 1, ref.shape) * sr, meas + rng.normal(0, 1, meas.shape) * sm)
        out[r] = P @ th[:9].reshape(3, 3).T + th[9:]
    return out.std(axis=0, ddof=1)


def count_study(ref, meas, sigma_m, counts, runs: int = 200, seed: int = 0) -> list[dict]:
    """000 Fig. 3: how Ev (RMS over all fiducials of |X_c − X_m|, the transform fitted on random
    subsets of n fiducials) settles with n; mean and spread over ``runs`` subsets per n."""
    rng = np.random.default_rng(seed)
    ref = np.asarray(ref, float)
    meas = np.asarray(meas, float)
    out = []
    for n in counts:
        if n < 4 or n > len(ref):
            continue
        ev = []
        for _ in range(runs):
            pick = rng.choice(len(ref), n, replace=False)
            s = np.linalg.svd(ref[pick] - ref[pick].mean(axis=0), compute_uv=False)
            if s[2] <= 1e-6 * s[0]:
                continue
            th = _solve(ref[pick], meas[pick])
            e = ref @ th[:9].reshape(3, 3).T + th[9:] - meas
            ev.append(np.sqrt(np.mean(np.sum(e * e, axis=1))))
        if ev:
            out.append({"fiducials": int(n), "ev_mean_um": float(np.mean(ev) * 1e3),
                        "ev_std_um": float(np.std(ev) * 1e3)})
    return out


def ball_points(centres, diameter=9.997, per_ball=20, patch=6.0, noise=0.0, seed=0):
    """Probe points on the top caps of balls (a 6 × 6 mm patch, as 000): (points (N, 3), ball ids
    1…n) — simulated measurements of a fiducial layout."""
    rng = np.random.default_rng(seed)
    R = diameter / 2
    k = int(np.ceil(np.sqrt(per_ball)))
    u = (np.arange(k) / max(k - 1, 1) - 0.5) * patch
    U, V = [a.ravel()[:per_ball] for a in np.meshgrid(u, u)]
    pts, ids = [], []
    for i, c in enumerate(np.asarray(centres, float)):
        w = np.sqrt(R * R - U * U - V * V)
        p = c + np.column_stack([U, V, w])
        p = p + rng.normal(0, noise, p.shape)
        pts.append(p)
        ids.append(np.full(len(p), i + 1))
    return np.vstack(pts), np.concatenate(ids)


def example_layout() -> np.ndarray:
    """Ten calibrated fiducial centres (mm): a 2 × 2 × 2 box and two inside it (the steps' examples)."""
    g = np.array([[x, y, z] for x in (-90.0, 90.0) for y in (-15.0, 15.0) for z in (5.0, 45.0)])
    return np.vstack([g, [[0.0, 0.0, 25.0], [40.0, -10.0, 15.0]]])


def example_measured_centres(ref) -> np.ndarray:
    """Where a slightly sheared, scaled and shifted machine measures the centres ``ref`` (examples)."""
    D = np.array([[1, 2e-5, 0], [-2e-5, 1, 1e-5], [0, 0, 1.00001]])
    return np.asarray(ref, float) @ D.T + [0.5, -0.2, 0.1]


#: a ball whose held-out residual lies more than this many robust σ off what the other balls predict is
#: named in the fiducials step's warnings (``held_out_outliers``); chosen from the simulator — see there
OUTLIER_SIGMA = 6.0
#: the smooth kernel the other balls predict a held-out ball with: RBF, length scale this × the layout's
#: extent per axis (0.5: the simulator's fields have correlation lengths about ½ travel)
OUTLIER_LENGTH = 0.5


def _held_out(X, H, E, sigma2, length):
    """Leave-one-out residuals of universal kriging (the affine transform re-estimated without the held-out
    ball, a smooth GP of fixed shape for the rest): r = P e / diag P, var = 1 / diag P with
    P = K⁻¹ − K⁻¹H(HᵀK⁻¹H)⁻¹HᵀK⁻¹ (Dubrule 1983) — exact held-out residuals, no re-fit per ball."""
    from scipy.spatial.distance import cdist

    ext = np.maximum(np.ptp(X, axis=0), 1e-3 * max(float(np.max(np.ptp(X, axis=0))), 1e-9))
    R = np.exp(-0.5 * cdist(X / (length * ext), X / (length * ext), "sqeuclidean"))
    r = np.empty_like(E)
    v = np.empty_like(E)
    for k in range(E.shape[1]):
        Ki = np.linalg.inv(np.eye(len(X)) * sigma2 + R * max(float(np.var(E[:, k])) - sigma2, sigma2))
        KH = Ki @ H
        P = Ki - KH @ np.linalg.solve(H.T @ KH, KH.T)
        d = np.diag(P)
        r[:, k] = P @ E[:, k] / d
        v[:, k] = 1.0 / d
    return r, v


def held_out_outliers(ref, meas, sigma, threshold: float = OUTLIER_SIGMA, length: float = OUTLIER_LENGTH,
                      most: int = 3) -> list[tuple[int, np.ndarray, float]]:
    """Balls the others cannot predict (a blunder: dirt on the ball, a mis-probed point): [(index, held-out
    residual vector (mm, what the ball's error exceeds the other balls' prediction by), z)], the worst first.

    Each ball's held-out residual (``_held_out``: the transform and a smooth GP through the other balls,
    the error's measured centres X_m) is divided by its predictive σ and then by a robust scale of the
    other balls' (1.4826 × median |t|, per component, so a wrong amplitude of the fixed kernel cancels);
    z = the norm of the three components' ratios (≈ χ with 3 degrees of freedom without a blunder). The
    worst ball beyond ``threshold`` is named, left out, and the rest tested again (``most`` times: a
    blunder pulls its neighbours' predictions, which must not name them too). ``sigma``: the σ of the
    error at a ball (mm, √(σ_m² + σ_r²)), the kernel's noise.

    The threshold (6), measured with the review's simulator (24 random balls in 200 × 40 × 50 mm, 0.2 µm
    probing and reference noise, 1.3 µm fields): the worst ball's z exceeded 6 on 1/200 runs of fourier
    fields, 2/200 kinematic, 1/200 null (0.67 % per run together); 1/100 poly, 0/100 sine_x, 5/100 one_axis
    (a field of x alone, sharper than the kernel), 2/100 scale_curv; 1/100 on two planes, 0/50 on a grid.
    (z > 5: 4.5–13 % of runs; z > 7: 0–2 %.) A 5 µm blunder on one ball: z > 6 on 98/100 fourier,
    100/100 kinematic, 100/100 poly runs (median z 12), the blundered ball the worst on all 300
    (tests/test_fiducials_review7.py)."""
    ref = np.asarray(ref, dtype=np.float64)
    meas = np.asarray(meas, dtype=np.float64)
    keep = np.arange(len(ref))
    out = []
    sigma2 = max(float(sigma) ** 2, 1e-18)
    for _ in range(most):
        if len(keep) < 10:  # a robust scale and a prediction need balls around
            break
        X, H = meas[keep], np.column_stack([ref[keep], np.ones(len(keep))])
        theta, *_ = np.linalg.lstsq(H, X, rcond=None)
        E = H @ theta - X
        try:
            r, v = _held_out(X, H, E, sigma2, length)
        except np.linalg.LinAlgError:
            break
        t = r / np.sqrt(v)
        z = np.empty(len(keep))
        for i in range(len(keep)):
            others = np.delete(np.abs(t), i, axis=0)
            s = 1.4826 * np.median(others, axis=0)
            z[i] = float(np.sqrt(np.sum((t[i] / np.maximum(s, 1e-300)) ** 2)))
        i = int(np.argmax(z))
        if z[i] <= threshold:
            break
        out.append((int(keep[i]), r[i], float(z[i])))
        keep = np.delete(keep, i)
    return out
