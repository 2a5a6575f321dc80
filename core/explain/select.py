"""Which library effects the gap supports: greedy group-forward selection with evidence.

Signatures: each effect's columns S_e = ∂Δz/∂p_e (core.simulate.effects), scaled to unit RMS.
Stage k: for every effect not yet chosen, least squares of the gap g on [chosen, S_e]; with SSR the
residual sum of squares, N points and P parameters in all,
    F = ((SSR_k − SSR_e)/p_e) / (SSR_e/(N − P)),   p = P(F_{p_e, N−P} > F),
    ΔBIC = N ln(SSR_e/SSR_k) + p_e ln N.
The effect with the lowest ΔBIC enters if p < α/m (Bonferroni over the m candidates; for the vibration
the search over N/2 frequencies counts too) and ΔBIC < −10 (strong evidence, Kass & Raftery).
Ambiguity: another candidate whose fit is statistically as good (SSR_o − SSR_e < σ² χ²_{0.999}(p))
cannot be told apart on this scan path → `ambiguous_with`, with the angle between the two fitted
signatures and the measurement that would separate them. At the end: VIF of every chosen column,
a χ² test of the residual against the noise σ (estimated from second differences along the scan,
σ = 1.4826·MAD(Δ²g)/√6, which a smooth gap does not inflate), the lag-1 autocorrelation of the
residual along the scan (whiteness), regions where the residual's local mean is significant, and a
block bootstrap of the selection (stability of each choice).

Sums over points are done once: the Gram matrix AᵀA and Aᵀg of all columns, then every candidate
fit is a small solve — the whole library on 290,011 points costs a few passes over the data.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from ..simulate.effects import LIBRARY, ScanContext, Vibration

ALPHA = 0.01
BIC_STRONG = -10.0
#: an effect whose SSR gain comes for more than this share from the 10 % best cells is local
LOCAL_LIMIT = 0.6


def local_fraction(ctx: ScanContext, r_old: np.ndarray, r_new: np.ndarray, cells: int = 24) -> float:
    """Share of the SSR gain r_old² − r_new² that the best 10 % of occupied cells hold."""
    x, y = ctx.x, ctx.y
    span = max(np.ptp(x), np.ptp(y)) or 1.0
    ix = np.clip(((x - x.min()) / span * cells).astype(int), 0, cells - 1)
    iy = np.clip(((y - y.min()) / span * cells).astype(int), 0, cells - 1)
    k = iy * cells + ix
    gain = np.bincount(k, weights=r_old * r_old - r_new * r_new, minlength=cells * cells)
    occ = np.bincount(k, minlength=cells * cells) > 0
    gain = np.sort(gain[occ])[::-1]
    total = gain.sum()
    if total <= 0:
        return 1.0
    top = max(int(np.ceil(0.1 * gain.size)), 1)
    return float(gain[:top].sum() / total)

#: what separates two effects that a scan cannot tell apart
SEPARATE_BY = {
    frozenset({"thermal_drift", "squareness"}): "on a spiral the radius is linear in time: run the "
    "spiral the other way (outward) or scan a raster, so time and radius part",
    frozenset({"thermal_drift", "straightness"}): "time and radius are tied by the spiral: repeat the "
    "scan in the opposite direction or interleave rings",
    frozenset({"z_scale", "straightness"}): "on this part the sag is a function of radius: measure a "
    "step artefact (z_scale) or a flat (straightness)",
    frozenset({"z_scale", "probe_radius"}): "measure with a second tip radius or a sphere of known radius",
    frozenset({"probe_radius", "straightness"}): "measure with a second tip radius",
    frozenset({"dynamic_lag", "spindle_axial"}): "change the spindle speed: a lag scales with speed, "
    "an axial motion does not",
    frozenset({"dynamic_lag", "pose"}): "change the scan speed or direction: a lag follows the velocity",
    frozenset({"vibration", "spindle_axial"}): "measure at another spindle speed: a synchronous spindle "
    "error follows the spindle, a vibration keeps its frequency",
    frozenset({"vibration", "spindle_tilt"}): "measure at another spindle speed: a synchronous spindle "
    "error follows the spindle, a vibration keeps its frequency",
}


def separate_by(a: str, b: str) -> str:
    return SEPARATE_BY.get(frozenset({a, b}), "a second scan on which their signatures differ (another "
                           "path, speed or direction)")


def noise_sigma(g_in_scan_order: np.ndarray) -> float:
    d2 = np.diff(g_in_scan_order, 2)
    if d2.size < 10:
        return float(np.std(g_in_scan_order))
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


@dataclass
class Group:
    name: str
    cols: np.ndarray          # (N, p) scaled
    scale: np.ndarray         # (p,) the factor each raw column was divided by
    frequency: float | None = None


@dataclass
class Stage:
    effect: str
    ssr_before: float
    ssr_after: float
    F: float
    p: float
    delta_bic: float
    ambiguous_with: list = field(default_factory=list)


def linear_groups(ctx: ScanContext) -> tuple[list[Group], list[str]]:
    groups, unobservable = [], []
    for name, eff in LIBRARY.items():
        if not eff.linear:
            continue
        S = eff.columns(ctx)
        s = np.sqrt(np.mean(S * S, axis=0))
        keep = s > 1e-18
        if not keep.any():
            unobservable.append(name)
            continue
        S = S[:, keep] / s[keep]
        # drop columns that repeat others within the group (e.g. a cos lobe that is constant here)
        from scipy.linalg import qr

        q, rr, piv = qr(S, mode="economic", pivoting=True)
        rank = int(np.sum(np.abs(np.diag(rr)) > 1e-9 * abs(rr[0, 0])))
        sel = np.sort(piv[:rank])
        idx = np.flatnonzero(keep)[sel]
        full_scale = np.full(len(eff.params), np.nan)
        full_scale[idx] = s[idx]
        groups.append(Group(name, S[:, sel], full_scale))
    return groups, unobservable


def vibration_group(ctx: ScanContext, resid_t_order: np.ndarray, order: np.ndarray) -> Group | None:
    """cos/sin at the strongest spectral line of the residual (uniform time stamps only)."""
    t = ctx.t[order]
    if t.size < 64:
        return None
    dt = np.diff(t)
    if np.ptp(t) == 0 or np.std(dt) > 1e-3 * np.mean(dt):
        return None
    fs = 1.0 / np.mean(dt)
    n = t.size
    r = resid_t_order - resid_t_order.mean()
    F = np.abs(np.fft.rfft(r * np.hanning(n)))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    low = f < 5.0 / np.ptp(t)
    F[low] = 0.0
    k = int(np.argmax(F))
    if k == 0 or k >= len(F) - 1:
        return None
    a, b, c = np.log(F[k - 1] + 1e-300), np.log(F[k] + 1e-300), np.log(F[k + 1] + 1e-300)
    shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
    fk = (k + shift) * fs / n
    V = Vibration().columns_at(ctx, fk)
    s = np.sqrt(np.mean(V * V, axis=0))
    return Group("vibration", V / s, s, frequency=fk)


class _Design:
    """All candidate columns with their Gram matrix and Aᵀg, computed once (vibration columns are
    appended when found)."""

    def __init__(self, groups, g):
        self.g = g
        self.gg = float(g @ g)
        self.cols = [gr.cols for gr in groups]
        self.index = {}
        k = 0
        for gr in groups:
            self.index[gr.name] = list(range(k, k + gr.cols.shape[1]))
            k += gr.cols.shape[1]
        self.A = np.hstack(self.cols) if self.cols else np.zeros((g.size, 0))
        self.G = self.A.T @ self.A
        self.b = self.A.T @ g

    def add(self, name, cols):
        AtV = self.A.T @ cols
        k0 = self.A.shape[1]
        self.A = np.hstack([self.A, cols])
        G = np.zeros((k0 + cols.shape[1],) * 2)
        G[:k0, :k0] = self.G
        G[:k0, k0:] = AtV
        G[k0:, :k0] = AtV.T
        G[k0:, k0:] = cols.T @ cols
        self.G = G
        self.b = np.r_[self.b, cols.T @ self.g]
        self.index[name] = list(range(k0, k0 + cols.shape[1]))

    def ssr(self, idx):
        if not idx:
            return self.gg, np.zeros(0)
        beta = np.linalg.lstsq(self.G[np.ix_(idx, idx)], self.b[idx], rcond=1e-12)[0]
        return float(self.gg - self.b[idx] @ beta), beta


@dataclass
class Candidate:
    """The evidence for adding one effect to those already chosen (module doc):
        F = ((SSR_k − SSR_e)/p_e) / (SSR_e/(N − P)),   p = P(F_{p_e, N−P} > F),
        ΔBIC = N ln(SSR_e/SSR_k) + p_e ln N,
    and m, the size of the Bonferroni family its p is judged in."""
    effect: str
    ssr: float
    F: float
    p: float
    delta_bic: float
    m: float


def significant(p: float, m: float) -> bool:
    """p < α/m: Bonferroni over the m candidates of a stage, so that on a gap with no effect in it the
    chance that any candidate passes stays ≤ α (the vibration's m counts its N/2 searched frequencies)."""
    return p < ALPHA / m


def enters(c: Candidate) -> bool:
    """Significant after Bonferroni and strong evidence by ΔBIC (< −10, Kass & Raftery)."""
    return significant(c.p, c.m) and c.delta_bic < BIC_STRONG


def scan_order(ctx: ScanContext, n: int) -> np.ndarray:
    """The points in the order the probe visited them (by time; as given when there are no times)."""
    return np.argsort(ctx.t, kind="stable") if np.ptp(ctx.t) > 0 else np.arange(n)


def gap_noise(g: np.ndarray, order: np.ndarray) -> float:
    """The noise σ of the gap (noise_sigma along the scan), floored so that a noise-free gap
    (simulation against simulation) does not divide by zero."""
    return max(noise_sigma(g[order]), 1e-9 * (float(np.sqrt(np.mean(g * g))) + 1e-12))


def candidate(D: _Design, chosen_cols: list[int], name: str, ssr_cur: float, n_candidates: int) -> Candidate:
    """F-test and ΔBIC of adding effect `name` to the columns already chosen (Candidate's equations)."""
    N = D.g.size
    cand = chosen_cols + D.index[name]
    ssr, _ = D.ssr(cand)
    pe = len(D.index[name])
    dof = N - len(cand)
    ssr = max(ssr, 1e-300)
    F = ((ssr_cur - ssr) / pe) / (ssr / dof) if dof > 0 else 0.0
    pval = float(stats.f.sf(F, pe, dof)) if dof > 0 and F > 0 else 1.0
    dbic = N * np.log(ssr / max(ssr_cur, 1e-300)) + pe * np.log(N)
    m = n_candidates * (N / 2 if name == "vibration" else 1)
    return Candidate(name, ssr, F, pval, dbic, m)


@dataclass
class _Search:
    """The state of the forward selection: the design, the columns and stages chosen so far, and the
    residual of the fit on them."""
    ctx: ScanContext
    g: np.ndarray
    order: np.ndarray
    groups: list
    D: _Design
    by_name: dict
    cols: list
    ssr: float
    resid: np.ndarray
    stages: list = field(default_factory=list)

    @property
    def chosen(self) -> list[str]:
        return [st.effect for st in self.stages]


def _start(ctx: ScanContext, g: np.ndarray, order: np.ndarray, groups: list) -> _Search:
    """Stage 0: the piston alone (the absolute height offset is a nuisance of every measurement,
    never an effect)."""
    piston = Group("_piston", np.ones((g.size, 1)), np.ones(1))
    D = _Design([piston] + groups, g)
    cols = list(D.index["_piston"])
    ssr, beta0 = D.ssr(cols)
    return _Search(ctx, g, order, groups, D, {gr.name: gr for gr in groups}, cols, ssr, g - beta0[0])


def _candidates(s: _Search) -> list[str]:
    """The effects not chosen yet; the vibration at the strongest spectral line of what is left, found
    anew at every stage until it is chosen."""
    names = [gr.name for gr in s.groups if gr.name not in s.chosen]
    if "vibration" not in s.chosen:
        vib = vibration_group(s.ctx, s.resid[s.order], s.order)
        if vib is not None:
            s.D.add("vibration", vib.cols)
            s.by_name["vibration"] = vib
            names.append("vibration")
    return names


def _is_local(s: _Search, name: str) -> bool:
    """Every library effect acts over the whole part: one whose SSR gain comes from a small area is
    fitting a local defect, which no effect explains (→ unexplained, located)."""
    cols = s.cols + s.D.index[name]
    _, beta = s.D.ssr(cols)
    return local_fraction(s.ctx, s.resid, s.g - s.D.A[:, cols] @ beta) > LOCAL_LIMIT


def _ambiguous_with(s: _Search, best: Candidate, others: list[Candidate], sigma: float) -> list[dict]:
    """The other candidates that would enter too and whose fit is statistically as good:
    SSR_o − SSR_e < σ² χ²_{0.999}(p_e) — this scan path cannot tell them from the best."""
    thr = sigma * sigma * stats.chi2.ppf(0.999, len(s.D.index[best.effect]))
    return [{"effect": o.effect, "ssr_excess": float(o.ssr - best.ssr)}
            for o in others if o.ssr - best.ssr < thr and enters(o)]


def _add(s: _Search, best: Candidate, ambiguous: list[dict]) -> None:
    """Record the stage and refit the gap on the chosen columns."""
    s.stages.append(Stage(best.effect, s.ssr, best.ssr, float(best.F), best.p, float(best.delta_bic), ambiguous))
    s.cols = s.cols + s.D.index[best.effect]
    s.ssr, beta = s.D.ssr(s.cols)
    s.resid = s.g - s.D.A[:, s.cols] @ beta


def forward_search(s: _Search, sigma: float, max_effects: int) -> _Search:
    """Greedy group-forward selection: at each stage the candidate of lowest ΔBIC enters when it is
    significant, strong and not local; stops at the first stage where it is not, or at max_effects."""
    for _ in range(max_effects):
        names = _candidates(s)
        if not names:
            break
        results = sorted((candidate(s.D, s.cols, name, s.ssr, len(names)) for name in names),
                         key=lambda c: c.delta_bic)
        best = results[0]
        if not enters(best) or _is_local(s, best.effect):
            break
        _add(s, best, _ambiguous_with(s, best, results[1:], sigma))
    return s


def uncentred_vif(G: np.ndarray) -> np.ndarray:
    """Variance inflation of each column, uncentred (the design holds a constant column): the diagonal
    of the inverse of the Gram matrix normalised to unit diagonal."""
    dn = np.sqrt(np.diag(G))
    return np.diag(np.linalg.pinv(G / np.outer(dn, dn)))


def _fitted_effects(s: _Search) -> tuple[list[dict], np.ndarray]:
    """The final least-squares fit on all chosen columns: each chosen effect's coefficients, their
    standard deviations (σ̂² (AᵀA)⁻¹, σ̂² = SSR/(N − P)), its largest VIF, its fitted part and the gap
    left after the effects up to it; and the final residual."""
    D, g, idx = s.D, s.g, s.cols
    N, P = g.size, len(idx)
    X = D.A[:, idx]
    Gs = D.G[np.ix_(idx, idx)]
    beta = np.linalg.lstsq(Gs, D.b[idx], rcond=1e-12)[0]
    resid = g - X @ beta
    s2 = float(resid @ resid) / max(N - P, 1)
    cov = np.linalg.pinv(Gs) * s2
    vif = uncentred_vif(Gs)
    found = []
    col = 1  # after the piston
    for st in s.stages:
        p = len(D.index[st.effect])
        bb = beta[col:col + p]
        sd = np.sqrt(np.clip(np.diag(cov)[col:col + p], 0, None))
        upto = idx[: col + p]
        _, bk = D.ssr(upto)
        found.append({"group": s.by_name[st.effect], "stage": st, "beta": bb, "sd": sd,
                      "vif_max": float(np.max(vif[col:col + p])), "fitted": X[:, col:col + p] @ bb,
                      "resid_upto": g - D.A[:, upto] @ bk})
        col += p
    return found, resid


def residual_checks(resid: np.ndarray, sigma: float, order: np.ndarray, P: int) -> dict:
    """What is left against the noise: its RMS, the χ² test of Σr²/σ² with N − P degrees of freedom,
    and the lag-1 autocorrelation along the scan (whiteness)."""
    N = resid.size
    rms = float(np.sqrt(np.mean(resid**2)))
    chi2_p = float(stats.chi2.sf(float(resid @ resid) / max(sigma, 1e-300) ** 2, max(N - P, 1)))
    ro = resid[order]
    rho1 = float(np.corrcoef(ro[:-1], ro[1:])[0, 1]) if N > 3 and np.std(ro) > 0 else 0.0
    return {"rms": rms, "chi2_p": chi2_p, "rho1": rho1}


def select(ctx: ScanContext, g: np.ndarray, max_effects: int = 6, bootstrap: int = 10,
           seed: int = 0) -> dict:
    """The forward selection (module doc). Returns a dict of plain results (see workflow)."""
    order = scan_order(ctx, g.size)
    sigma = gap_noise(g, order)
    groups, unobservable = linear_groups(ctx)
    s = forward_search(_start(ctx, g, order, groups), sigma, max_effects)
    found, resid = _fitted_effects(s) if s.stages else ([], s.resid)
    checks = residual_checks(resid, sigma, order, len(s.cols))
    stability = {}
    if s.stages and bootstrap > 0:
        stability = _bootstrap(ctx, g - resid, resid, s.chosen, bootstrap, seed, max_effects)
    return {"sigma": sigma, "found": found, "residual": resid, **checks, "unobservable": unobservable,
            "stability": stability, "order": order}


def _bootstrap(ctx, fitted, resid, names, B, seed, max_effects) -> dict:
    """How often each chosen effect is chosen again when the residual is resampled in blocks along the
    scan (moving-block bootstrap; the scan itself, every k-th point down to ≤ 50,000, is kept)."""
    rng = np.random.default_rng(seed)
    order = np.argsort(ctx.t, kind="stable")
    k = max(order.size // 50_000, 1)
    keep = np.sort(order[::k])
    sub = ScanContext(ctx.x[keep], ctx.y[keep], ctx.f[keep], ctx.fx[keep], ctx.fy[keep], ctx.t[keep],
                      ctx.c[keep])
    r_sorted = resid[order][::k]
    n = r_sorted.size
    L = max(n // 50, 1)
    count = {nm: 0 for nm in names}
    pos_in_sub = np.argsort(np.argsort(ctx.t[keep], kind="stable"), kind="stable")
    for _ in range(B):
        starts = rng.integers(0, max(n - L, 1), int(np.ceil(n / L)))
        rb = np.concatenate([r_sorted[s:s + L] for s in starts])[:n]
        g_star = fitted[keep] + rb[pos_in_sub]
        res = select(sub, g_star, max_effects, bootstrap=0)
        got = {f["group"].name for f in res["found"]}
        for nm in names:
            count[nm] += nm in got
    return {nm: c / B for nm, c in count.items()}
