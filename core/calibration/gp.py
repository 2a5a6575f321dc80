"""Gaussian-process model of the volumetric error over the workspace (seed paper 000 eqs 12–19).

Kernel: the spectral mixture in Wilson's multi-dimensional form (Wilson & Adams, ICML 2013, eq. 12),
    k(τ) = Σ_q w_q exp(−2π² Σ_d τ_d² v_qd) cos(2π μ_qᵀ τ),
not GPyTorch's product of 1-D mixtures (its issues #1198/#1981), written as a scikit-learn kernel with
analytic gradients with respect to the log-parameters (checked against finite differences in the
tests):
    ∂k/∂ln w_q = w_q E_q C_q,  ∂k/∂ln v_qd = −2π² τ_d² v_qd w_q E_q C_q,  ∂k/∂ln μ_qd = −2π τ_d μ_qd w_q E_q S_q
(E_q the exponential, C_q/S_q the cosine/sine). Frequencies start from the data — up to the Nyquist
frequency of the fiducials' spacing, as GPyTorch's `initialize_from_data` — and the optimiser restarts
from several draws. With ~24 fiducials the marginal likelihood is multimodal and can pick absurd
length scales, so the bounds come from the workspace (periods between the fiducial spacing and ten
workspace sizes) and the kernel actually used is the one with the lowest leave-one-out error among the
spectral mixture, RBF and Matérn 5/2 (each plus a constant and a white-noise term).
LOO residuals in closed form: r_i = [K⁻¹y]_i / [K⁻¹]_ii (Rasmussen & Williams eq. 5.12). The targets are
normalised here (NormalisedGP), not by scikit-learn's normalize_y, so only its public API is used.
"""
from __future__ import annotations

import numpy as np
from sklearn.gaussian_process.kernels import Hyperparameter, Kernel, StationaryKernelMixin


class SpectralMixture(StationaryKernelMixin, Kernel):
    def __init__(self, weights, means, variances, weights_bounds=(1e-12, 1e6),
                 means_bounds=(1e-6, 1e3), variances_bounds=(1e-10, 1e3)):
        self.weights = np.asarray(weights, dtype=np.float64)
        self.means = np.asarray(means, dtype=np.float64)          # (Q, D) flattened allowed
        self.variances = np.asarray(variances, dtype=np.float64)  # (Q, D)
        self.weights_bounds = weights_bounds
        self.means_bounds = means_bounds
        self.variances_bounds = variances_bounds

    @property
    def Q(self):
        return self.weights.size

    @property
    def hyperparameter_weights(self):
        return Hyperparameter("weights", "numeric", self.weights_bounds, self.weights.size)

    @property
    def hyperparameter_means(self):
        return Hyperparameter("means", "numeric", self.means_bounds, self.means.size)

    @property
    def hyperparameter_variances(self):
        return Hyperparameter("variances", "numeric", self.variances_bounds, self.variances.size)

    def __call__(self, X, Y=None, eval_gradient=False):
        X = np.atleast_2d(X)
        Yv = X if Y is None else np.atleast_2d(Y)
        D = X.shape[1]
        Q = self.Q
        mu = self.means.reshape(Q, D)
        v = self.variances.reshape(Q, D)
        w = self.weights.ravel()
        tau = X[:, None, :] - Yv[None, :, :]                     # (n, m, D)
        K = np.zeros(tau.shape[:2])
        grads = []
        gw, gm, gv = [], [], []
        for q in range(Q):
            E = np.exp(-2 * np.pi**2 * np.einsum("nmd,d->nm", tau**2, v[q]))
            arg = 2 * np.pi * np.einsum("nmd,d->nm", tau, mu[q])
            C, S = np.cos(arg), np.sin(arg)
            K += w[q] * E * C
            if eval_gradient:
                gw.append(w[q] * E * C)
                for d in range(D):
                    gm.append(-2 * np.pi * tau[:, :, d] * mu[q, d] * w[q] * E * S)
                    gv.append(-2 * np.pi**2 * tau[:, :, d] ** 2 * v[q, d] * w[q] * E * C)
        if not eval_gradient:
            return K
        if Y is not None:
            raise ValueError("gradient only with Y = None")
        # scikit-learn orders θ by the hyperparameters' names: means, variances, weights
        grads = []
        if not self.hyperparameter_means.fixed:
            grads += gm
        if not self.hyperparameter_variances.fixed:
            grads += gv
        if not self.hyperparameter_weights.fixed:
            grads += gw
        return K, np.stack(grads, axis=-1) if grads else np.empty(K.shape + (0,))

    def diag(self, X):
        return np.full(np.atleast_2d(X).shape[0], float(np.sum(self.weights)))

    def __repr__(self):
        return f"SpectralMixture(Q={self.Q})"


def _bounds(X):
    span = float(np.max(np.ptp(X, axis=0))) or 1.0
    from scipy.spatial.distance import pdist

    dmin = float(np.min(pdist(X))) if len(X) > 1 else span
    fmax = 0.5 / max(dmin, 1e-9)          # Nyquist of the fiducial spacing
    fmin = 1.0 / (10 * span)
    return span, dmin, fmin, fmax


def spectral_mixture_from_data(X, y, Q: int = 10, seed: int = 0) -> SpectralMixture:
    """Start: weights var(y)/Q, frequencies uniform up to the fiducials' Nyquist frequency, spectral
    variances ~ (1/workspace)² (GPyTorch's initialize_from_data does the same in spirit)."""
    rng = np.random.default_rng(seed)
    X = np.asarray(X, float)
    D = X.shape[1]
    span, dmin, fmin, fmax = _bounds(X)
    var = float(np.var(y)) or 1e-12
    means = rng.uniform(fmin, fmax, (Q, D))
    variances = np.full((Q, D), (1.0 / span) ** 2)
    return SpectralMixture(np.full(Q, var / Q), means.ravel(), variances.ravel(),
                           weights_bounds=(var * 1e-6, var * 1e2), means_bounds=(fmin, fmax),
                           variances_bounds=((1.0 / (10 * span)) ** 2, (1.0 / dmin) ** 2))


def _scale(y) -> tuple[float, float]:
    """Mean and standard deviation of the targets; a (near-)zero deviation becomes 1, as
    scikit-learn's normalize_y does (sklearn.preprocessing's handling of zero scales)."""
    y = np.asarray(y, dtype=np.float64)
    mean, std = float(np.mean(y)), float(np.std(y))
    if std < 10 * np.finfo(np.float64).eps:
        std = 1.0
    return mean, std


class NormalisedGP:
    """A GaussianProcessRegressor fitted (normalize_y=False) to the targets normalised here,
    (y − y_mean) / y_std, so that nothing reads scikit-learn's private attributes. ``predict``
    answers in the units of y, as ``GaussianProcessRegressor(normalize_y=True).predict`` would."""

    def __init__(self, regressor, y_mean: float, y_std: float):
        self.regressor = regressor
        self.y_mean = float(y_mean)
        self.y_std = float(y_std)

    @classmethod
    def fit(cls, regressor, X, y) -> NormalisedGP:
        """Fit ``regressor`` (normalize_y=False) to the normalised y; returns the wrapper."""
        if regressor.normalize_y:
            raise ValueError("NormalisedGP normalises the targets itself: give normalize_y=False")
        mean, std = _scale(y)
        regressor.fit(X, (np.asarray(y, dtype=np.float64) - mean) / std)
        return cls(regressor, mean, std)

    @property
    def kernel_(self):
        return self.regressor.kernel_

    @property
    def alpha(self):
        return self.regressor.alpha

    def predict(self, X, return_std: bool = False):
        if not return_std:
            return self.y_std * self.regressor.predict(X) + self.y_mean
        m, s = self.regressor.predict(X, return_std=True)
        return self.y_std * m + self.y_mean, s * self.y_std


def loo_rms(gp, X, y) -> float:
    """Closed-form leave-one-out RMS, in the units of y, of a fitted NormalisedGP (or of a plain
    GaussianProcessRegressor: its normalize_y scale is recomputed from y, as it computed it)."""
    K = gp.kernel_(X)
    K[np.diag_indices_from(K)] += gp.alpha
    Ki = np.linalg.inv(K)
    if isinstance(gp, NormalisedGP):
        mean, std = gp.y_mean, gp.y_std
    elif gp.normalize_y:
        mean, std = _scale(y)
    else:
        mean, std = 0.0, 1.0
    yy = (np.asarray(y, dtype=np.float64) - mean) / std
    r = (Ki @ yy) / np.diag(Ki)
    return float(np.sqrt(np.mean(r**2)) * std)


def fit_gp(X, y, Q: int = 10, restarts: int = 5, seed: int = 0) -> tuple[object, dict]:
    """The GP with the best leave-one-out error among spectral mixture, RBF and Matérn 5/2.
    Returns (NormalisedGP, {"loo_rms": {kernel: LOO RMS}, "chosen": kernel}); the NormalisedGP's
    ``predict``/``kernel_`` are those of a GaussianProcessRegressor, in the units of y."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

    X = np.asarray(X, float)
    y = np.asarray(y, float)
    span, dmin, fmin, fmax = _bounds(X)
    noise = WhiteKernel(1e-3, (1e-8, 1.0))
    cands = {
        "spectral_mixture": spectral_mixture_from_data(X, (y - y.mean()) / (y.std() or 1), Q, seed) + noise,
        "rbf": ConstantKernel(1.0, (1e-3, 1e3)) * RBF(np.full(X.shape[1], span / 2), (dmin / 2, 10 * span))
        + noise,
        "matern52": ConstantKernel(1.0, (1e-3, 1e3)) * Matern(np.full(X.shape[1], span / 2),
                                                               (dmin / 2, 10 * span), nu=2.5) + noise,
    }
    loo, fitted = {}, {}
    for name, k in cands.items():
        reg = GaussianProcessRegressor(k, normalize_y=False, n_restarts_optimizer=restarts,
                                       random_state=seed, alpha=1e-10)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            try:
                gp = NormalisedGP.fit(reg, X, y)
            except (np.linalg.LinAlgError, ValueError):
                continue
        loo[name] = loo_rms(gp, X, y)
        fitted[name] = gp
    best = min(loo, key=loo.get)
    return fitted[best], {"loo_rms": loo, "chosen": best}
