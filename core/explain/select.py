"""Which library effects the gap supports: greedy group-forward selection with evidence.

Signatures: each effect's columns S_e = ∂Δz/∂p_e (core.simulate.effects), scaled to unit RMS. A
spindle error motion (spindle_axial, spindle_tilt) is not one group but one candidate per harmonic k
(cos kc, sin kc), for k up to what the scan's angular sampling resolves (resolved_harmonics): the
selection keeps only the harmonics the gap supports, and the report gathers them under the effect.
Stage k: for every candidate not yet chosen, least squares of the gap g on [chosen, S_e]; with SSR
the residual sum of squares, N points and P parameters in all,
    F = ((SSR_k − SSR_e)/p_e) / (SSR_e/(N − P)),   p = P(F_{p_e, N−P} > F),
    ΔBIC = N ln(SSR_e/SSR_k) + p_e ln N.
A candidate enters if p < α/m (Bonferroni over the m candidates of the stage, every harmonic one of
them; for the vibration the search over N/2 frequencies counts too) and ΔBIC < −10 (strong evidence,
Kass & Raftery); of those, the one of lowest ΔBIC is the best fit.
Ambiguity: another entering candidate whose fit is statistically as good (SSR_o − SSR_e <
σ² χ²_{0.999}(max(p_e, p_o))) cannot be told apart on this scan path. Of such a tie the named effect
is the physical one before a catch-all (volumetric), then the one with fewer parameters (a
vibration's frequency counts as one), then the lower ΔBIC — a quadratic field that fits as well as a
one-parameter tip radius is not preferred to it; the others are reported as `ambiguous_with`, with
the measurement that would separate them. A vibration that is an integer multiple of the spindle
frequency on a scan whose spindle turns at constant speed is synchronous — a spindle error motion of
that order as much as a vibration — and is reported ambiguous with one. Once all effects are in, each
vibration line within a quarter cycle over the record of k × the spindle frequency is judged again
against the axial harmonic k (_synchronous_lines): below 33 upr the spindle error is named when it fits
as well; a line kept as a vibration is always reported synchronous.
Noise: σ from second differences along the scan, σ = 1.4826·MAD(Δ²g)/√6, which a smooth gap does not
inflate but a strong vibration does; it is therefore estimated again on the residual once the found
effects are removed, and the selection repeated with it (its ties depend on σ) until it settles.
Correlated noise: the tests above assume white noise; when the residual is correlated along the scan
(|lag-1 autocorrelation| above RHO_GATE), each chosen effect is tested again on data whitened for the
residual's AR(3) model (Cochrane–Orcutt: generalised least squares), then — when all still enter —
under a flicker model (power-law noise fitted to the residual's periodogram above the frequencies the
effects took, extrapolated below them: power_law_gls), and the least supported of those that no
longer enter is dropped, one at a time (_correlated_noise_gate).
At the end: VIF of every chosen column, a χ² test of the residual against σ, the lag-1
autocorrelation of the residual along the scan (whiteness), regions where the residual's local mean
is significant, and a block bootstrap of the selection (stability of each choice).

Sums over points are done once: the Gram matrix AᵀA and Aᵀg of all columns, then every candidate
fit is a small solve — the whole library on 290,011 points costs a few passes over the data.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats

from ..simulate.effects import (
    LIBRARY,
    SPINDLE_HARMONICS,
    ScanContext,
    Vibration,
    _Harmonics,
    resolved_harmonics,
)

ALPHA = 0.01
BIC_STRONG = -10.0
#: an effect whose SSR gain comes for more than this share from the 10 % best cells is local
LOCAL_LIMIT = 0.6
#: …and more than this many times the share of the effect's own fitted energy in those cells. An
#: effect that explains the gap gains where its shape has its energy (gain share ≈ energy share: a
#: quadratic drift at the centre of an inward spiral 0.62 against 0.61); one that fits part of a local
#: bump gains far more there than its shape holds (straightness 0.84 against 0.52, pose 0.89 against 0.25)
SHAPE_RATIO = 1.3
#: vibration lines (frequencies) the selection may name
MAX_VIBRATION_LINES = 3
#: the σ re-estimated on the residual replaces the gap's when it differs by more than this share
SIGMA_SETTLED = 0.05
#: the residual's lag-1 autocorrelation along the scan beyond which (either sign, and beyond 4/√N, its
#: white-noise spread ×4) the chosen effects are tested again under the residual's AR noise (_correlated_noise_gate).
#: 0.2 until 2026-11-28: white noise plus a random walk of the same RMS (an instrument's drift) left
#: ρ̂ 0.08–0.13 once the chosen low-frequency effects had taken the walk's wander, the gate never fired
#: and 14 of 20 such null gaps on a 5,000-point spiral named effects (one "explained" by straightness
#: and three vibrations — a review); at 0.05: 4 of 20; the 204 white-noise cases and the power on
#: white and AR(1) 0.15 / 0.3 noise unchanged (benchmarks/README.md)
RHO_GATE = 0.05


def local_fraction(ctx: ScanContext, r_old: np.ndarray, r_new: np.ndarray, cells: int = 24
                   ) -> tuple[float, float, float]:
    """Share of the SSR gain r_old² − r_new² that the best 10 % of occupied cells hold (of the gain of
    the cells that gain: where other unmodelled signal crosses the fit, cells gain and lose), the share
    of the points in those cells (a spiral samples its centre more densely: a global effect gains most
    where the points are, a local one where the defect is), and the share of the fitted contribution's
    own energy, Σ(r_old − r_new)², in them (an effect whose shape is concentrated there — a quadratic
    drift at the end of an inward spiral — gains there by its shape, not because a defect is local)."""
    x, y = ctx.x, ctx.y
    span = max(np.ptp(x), np.ptp(y)) or 1.0
    ix = np.clip(((x - x.min()) / span * cells).astype(int), 0, cells - 1)
    iy = np.clip(((y - y.min()) / span * cells).astype(int), 0, cells - 1)
    k = iy * cells + ix
    m = r_old - r_new
    gain = np.bincount(k, weights=r_old * r_old - r_new * r_new, minlength=cells * cells)
    count = np.bincount(k, minlength=cells * cells)
    energy = np.bincount(k, weights=m * m, minlength=cells * cells)
    occ = count > 0
    rank = np.argsort(gain[occ])[::-1]
    gain, count, energy = gain[occ][rank], count[occ][rank], energy[occ][rank]
    total = gain[gain > 0].sum()  # where the fit gains (unmodelled signal makes others lose)
    if total <= 0:
        return 1.0, 0.0, 0.0
    top = max(int(np.ceil(0.1 * gain.size)), 1)
    return (float(gain[:top].sum() / total), float(count[:top].sum() / count.sum()),
            float(energy[:top].sum() / max(energy.sum(), 1e-300)))


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
    frozenset({"probe_radius", "volumetric"}): "measure with a second tip radius (a tip radius follows "
    "the slope, a machine field does not), or a sphere of known radius",
    frozenset({"z_scale", "volumetric"}): "measure a step artefact: a z-scale error follows the height",
    frozenset({"dynamic_lag", "spindle_axial"}): "change the spindle speed: a lag scales with speed, "
    "an axial motion does not",
    frozenset({"dynamic_lag", "pose"}): "change the scan speed or direction: a lag follows the velocity",
    frozenset({"dynamic_lag", "squareness"}): "scan at another feed or run the spiral outward: a lag "
    "follows the velocity (on a turned part only the radial feed moves the probe up the slope), a cone "
    "does not",
    frozenset({"dynamic_lag", "thermal_drift"}): "scan at another feed or in the other direction: a lag "
    "follows the velocity, a drift the clock",
    frozenset({"dynamic_lag", "straightness"}): "scan at another feed or run the spiral outward: a lag "
    "follows the velocity, the slide's straightness the radius",
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
    """One candidate of the selection: a whole effect, one harmonic of a spindle error motion, or the
    vibration at one frequency. ``params`` names its columns in the effect's parameters; ``scale`` is
    the factor each raw column was divided by; ``n_params`` counts what the fit chooses (a
    vibration's frequency too)."""
    name: str
    cols: np.ndarray          # (N, p) scaled
    scale: np.ndarray         # (p,)
    effect: str = ""
    params: tuple = ()
    frequency: float | None = None
    harmonic: int | None = None
    n_params: int = 0
    catch_all: bool = False

    def __post_init__(self):
        self.effect = self.effect or self.name
        self.n_params = self.n_params or self.cols.shape[1]


@dataclass
class Stage:
    effect: str
    ssr_before: float
    ssr_after: float
    F: float
    p: float
    delta_bic: float
    ambiguous_with: list = field(default_factory=list)
    candidate: str = ""
    harmonic: int | None = None
    n_candidates: int = 1


def _independent(S: np.ndarray) -> np.ndarray:
    """Indices of the columns of S (unit RMS) that do not repeat others (rank-revealing QR)."""
    from scipy.linalg import qr

    _, rr, piv = qr(S, mode="economic", pivoting=True)
    rank = int(np.sum(np.abs(np.diag(rr)) > 1e-9 * abs(rr[0, 0])))
    return np.sort(piv[:rank])


def _group(name, effect, params, S, **kw) -> Group | None:
    """Columns S scaled to unit RMS, those that vanish or repeat others within the group dropped (e.g.
    a cos lobe that is constant on this scan), and those that are a constant: the design always
    holds the piston (``design``), which such a column repeats — the pose's dz was split evenly with
    it (half its value, with an uncertainty of 10⁻⁸ mm that meant nothing); a constant offset is the
    piston's. None when none is left."""
    s = np.sqrt(np.mean(S * S, axis=0))
    spread = np.std(S, axis=0)
    keep = np.flatnonzero((s > 1e-18) & (spread > 1e-9 * s))
    if keep.size == 0:
        return None
    S = S[:, keep] / s[keep]
    g = S.T @ S / S.shape[0]
    w = np.linalg.eigvalsh(g)
    sel = np.arange(S.shape[1]) if w[0] > 1e-9 * w[-1] else _independent(S)
    idx = keep[sel]
    return Group(name, S[:, sel], s[idx], effect=effect, params=tuple(params[i] for i in idx), **kw)


def linear_groups(ctx: ScanContext) -> tuple[list[Group], list[str]]:
    """The linear candidates: one per effect, one per resolved harmonic of a spindle error motion;
    and the effects with no observable column on this scan."""
    groups, unobservable = [], []
    kmax = resolved_harmonics(ctx)
    for name, eff in LIBRARY.items():
        if not eff.linear:
            continue
        if isinstance(eff, _Harmonics):
            ks = [k for k in eff.harmonics if k <= kmax]
            block = eff.harmonic_block(ctx, ks) if ks else None
            got = [_group(f"{name}[{k}]", name, eff.harmonic_params(k), block[:, 2 * j:2 * j + 2], harmonic=k)
                   for j, k in enumerate(ks)]
        else:
            got = [_group(name, name, eff.params, eff.columns(ctx), catch_all=eff.catch_all)]
        got = [g for g in got if g is not None]
        if not got:
            unobservable.append(name)
        groups.extend(got)
    return groups, unobservable


def _time_grid(t: np.ndarray) -> tuple[float, np.ndarray] | None:
    """The scan's clock: its typical step dt (the median) and each sample's index on the grid t₀ + k·dt
    — exact for uniform stamps, the nearest slot where a path pauses or jumps (a raster's row
    changes). None when the stamps do not support a spectrum (too few, or mostly gaps)."""
    if t.size < 64 or np.ptp(t) == 0:
        return None
    dt = float(np.median(np.diff(t)))
    if not dt > 0 or np.ptp(t) / dt > 8 * t.size:
        return None
    return dt, np.rint((t - t[0]) / dt).astype(np.int64)


#: a second vibration line within this many bins (1/T, T the record's duration) of a line already
#: chosen is not searched for: two tones closer than the Hann window's main lobe (±2 bins; the
#: Rayleigh limit is one) cannot be told apart on this record, and lines packed that close fit a
#: transient — a zone or bump the scan crosses once — not a machine's resonance (a ring on a spiral
#: read as four "vibrations" at 0.200, 0.212, 0.222 and 0.233 Hz over a 30 s record)
LINE_RESOLUTION_BINS = 2.0


def vibration_group(ctx: ScanContext, resid_t_order: np.ndarray, order: np.ndarray,
                    chosen_hz=()) -> Group | None:
    """cos/sin at the strongest spectral line of the residual: the windowed FFT of the residual on the
    scan's clock (empty slots zero), the peak interpolated, then refined on the exact time stamps to
    the frequency of greatest periodogram power within half a bin. ``n_search`` is the number of
    frequencies searched (the Bonferroni family of the vibration). ``chosen_hz``: the lines chosen
    already; the search leaves out LINE_RESOLUTION_BINS bins around each."""
    from scipy.optimize import minimize_scalar

    t = ctx.t[order]
    grid = _time_grid(t)
    if grid is None:
        return None
    dt, k_of = grid
    n = int(k_of[-1]) + 1
    r = resid_t_order - resid_t_order.mean()
    w = np.hanning(n)
    x = np.zeros(n)
    np.add.at(x, k_of, r * w[k_of])
    F = np.abs(np.fft.rfft(x))
    f = np.fft.rfftfreq(n, dt)
    low = f < 5.0 / np.ptp(t)
    df = 1.0 / (n * dt)
    for fc in chosen_hz:
        low |= np.abs(f - fc) < LINE_RESOLUTION_BINS * df
    F[low] = 0.0
    k = int(np.argmax(F))
    if k == 0 or k >= len(F) - 1 or F[k] == 0.0:
        return None
    a, b, c = np.log(F[k - 1] + 1e-300), np.log(F[k] + 1e-300), np.log(F[k + 1] + 1e-300)
    shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 and F[k - 1] > 0 and F[k + 1] > 0 else 0.0
    fk = (k + shift) * df
    tt = t - t[0]
    power = lambda fr: -abs(np.sum(r * np.exp(-2j * np.pi * fr * tt)))  # noqa: E731
    fk = float(minimize_scalar(power, bounds=(fk - 0.5 * df, fk + 0.5 * df), method="bounded",
                               options={"xatol": 1e-3 * df}).x)
    V = Vibration().columns_at(ctx, fk)
    s = np.sqrt(np.mean(V * V, axis=0))
    g = Group("vibration", V / s, s, params=("cos", "sin"), frequency=fk, n_params=3)
    g.n_search = int(np.count_nonzero(~low))
    return g


def spindle_frequency(ctx: ScanContext, order: np.ndarray) -> float | None:
    """The spindle's turns per second when its angle c is linear in time along the scan (a spiral at
    constant speed: then time and angle are tied and a synchronous vibration is a spindle harmonic),
    else None."""
    t = ctx.t[order]
    if t.size < 8 or np.ptp(t) == 0:
        return None
    c = np.unwrap(np.deg2rad(ctx.c[order]))
    A = np.column_stack([np.ones_like(t), t - t.mean()])
    coef, *_ = np.linalg.lstsq(A, c, rcond=None)
    if abs(coef[1]) < 1e-12 or np.max(np.abs(c - A @ coef)) > 1e-3:
        return None
    return float(abs(coef[1]) / (2 * np.pi))


class _Design:
    """All candidate columns A (scaled), Aᵀg, and the Gram matrix AᵀA filled as the search needs it:
    each candidate's own block at once, a column's cross products with every other column once it is
    chosen (a fit of [chosen, candidate] needs no more) — N·P·(chosen + 2) operations instead of N·P²
    for the ~150 columns of the library with its spindle harmonics. Columns found later (the vibration
    at each stage's line) are kept beside A and bordered onto the Gram matrix whole."""

    def __init__(self, groups, g):
        self.g = g
        self.gg = float(g @ g)
        self.index = {}
        k = 0
        for gr in groups:
            self.index[gr.name] = list(range(k, k + gr.cols.shape[1]))
            k += gr.cols.shape[1]
        self.A = np.hstack([gr.cols for gr in groups]) if groups else np.zeros((g.size, 0))
        for gr in groups:  # the groups' columns become views of A (one copy in memory)
            gr.cols = self.A[:, self.index[gr.name]]
        self.base = self.A.shape[1]
        self.extra = []  # (first index, columns)
        self.G = np.full((self.base, self.base), np.nan)
        for gr in groups:
            ix = self.index[gr.name]
            self.G[np.ix_(ix, ix)] = gr.cols.T @ gr.cols
        self.full = np.zeros(self.base, bool)
        self.b = self.A.T @ g

    def ensure(self, idx) -> None:
        """Fill the Gram matrix's rows and columns idx (cross products with every column)."""
        todo = [i for i in idx if not self.full[i]]
        if not todo:
            return
        X = self.X(todo)
        col = np.r_[self.A.T @ X, *[V.T @ X for _, V in self.extra]] if self.extra else self.A.T @ X
        self.G[:, todo] = col
        self.G[todo, :] = col.T
        self.full[todo] = True

    def add(self, name, cols):
        """Columns found later: their own block and their products with the chosen (full) columns now,
        the rest when they are chosen (ensure)."""
        k0 = self.G.shape[0]
        G = np.full((k0 + cols.shape[1],) * 2, np.nan)
        G[:k0, :k0] = self.G
        done = list(np.flatnonzero(self.full))
        if done:
            border = self.X(done).T @ cols
            G[done, k0:] = border
            G[k0:, done] = border.T
        G[k0:, k0:] = cols.T @ cols
        self.G = G
        self.full = np.r_[self.full, np.zeros(cols.shape[1], bool)]
        self.b = np.r_[self.b, cols.T @ self.g]
        self.extra.append((k0, cols))
        self.index[name] = list(range(k0, k0 + cols.shape[1]))

    def X(self, idx) -> np.ndarray:
        """The columns idx (base and added) as one matrix."""
        idx = list(idx)
        X = np.empty((self.g.size, len(idx)))
        at = {i: j for j, i in enumerate(idx)}
        base = [i for i in idx if i < self.base]
        if base:
            X[:, [at[i] for i in base]] = self.A[:, base]
        for k0, V in self.extra:
            for j in range(V.shape[1]):
                if k0 + j in at:
                    X[:, at[k0 + j]] = V[:, j]
        return X

    def fresh(self) -> "_Design":
        """The same design without the columns added since it was built (a new search on it)."""
        D = object.__new__(_Design)
        D.g, D.gg, D.A, D.base = self.g, self.gg, self.A, self.base
        D.index = {k: v for k, v in self.index.items() if v and v[0] < self.base}
        D.extra = []
        D.G, D.b = self.G[:self.base, :self.base].copy(), self.b[:self.base]
        D.full = self.full[:self.base].copy()
        return D

    def gram(self, idx) -> np.ndarray:
        Gs = self.G[np.ix_(idx, idx)]
        if np.isnan(Gs).any():
            self.ensure(idx)
            Gs = self.G[np.ix_(idx, idx)]
        return Gs

    def ssr(self, idx):
        if not idx:
            return self.gg, np.zeros(0)
        beta = np.linalg.lstsq(self.gram(idx), self.b[idx], rcond=1e-12)[0]
        return float(self.gg - self.b[idx] @ beta), beta

    def resid(self, idx) -> np.ndarray:
        _, beta = self.ssr(idx)
        return self.g - self.X(idx) @ beta if idx else self.g.copy()


@dataclass
class Candidate:
    """The evidence for adding one candidate to those already chosen (module doc):
        F = ((SSR_k − SSR_e)/p_e) / (SSR_e/(N − P)),   p = P(F_{p_e, N−P} > F),
        ΔBIC = N ln(SSR_e/SSR_k) + p_e ln N,
    and m, the size of the Bonferroni family its p is judged in."""
    effect: str
    ssr: float
    F: float
    p: float
    delta_bic: float
    m: float
    n_params: int = 1
    catch_all: bool = False


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


def candidate(D: _Design, chosen_cols: list[int], gr: Group, ssr_cur: float, n_candidates: int) -> Candidate:
    """F-test and ΔBIC of adding candidate ``gr`` to the columns already chosen (Candidate's equations)."""
    N = D.g.size
    cand = chosen_cols + D.index[gr.name]
    ssr, _ = D.ssr(cand)
    pe = len(D.index[gr.name])
    dof = N - len(cand)
    ssr = max(ssr, 1e-300)
    F = ((ssr_cur - ssr) / pe) / (ssr / dof) if dof > 0 else 0.0
    pval = float(special.fdtrc(pe, dof, F)) if dof > 0 and F > 0 else 1.0  # P(F_{pe,dof} > F)
    dbic = N * np.log(ssr / max(ssr_cur, 1e-300)) + pe * np.log(N)
    m = n_candidates * (getattr(gr, "n_search", N / 2) if gr.effect == "vibration" else 1)
    return Candidate(gr.name, ssr, F, pval, dbic, m, gr.n_params, gr.catch_all)


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
    spindle_hz: float | None = None
    stages: list = field(default_factory=list)

    @property
    def chosen(self) -> list[str]:
        """The candidates chosen (one per harmonic)."""
        return [st.candidate for st in self.stages]

    @property
    def effects(self) -> list[str]:
        """The effects chosen, each once, in the order they first entered."""
        return list(dict.fromkeys(st.effect for st in self.stages))


def design(g: np.ndarray, groups: list) -> _Design:
    """The piston and every linear candidate."""
    return _Design([Group("_piston", np.ones((g.size, 1)), np.ones(1))] + groups, g)


def _start(ctx: ScanContext, g: np.ndarray, order: np.ndarray, groups: list, D: _Design | None = None) -> _Search:
    """Stage 0: the piston alone (the absolute height offset is a nuisance of every measurement,
    never an effect)."""
    D = design(g, groups) if D is None else D.fresh()
    cols = list(D.index["_piston"])
    D.ensure(cols)
    ssr, beta0 = D.ssr(cols)
    return _Search(ctx, g, order, groups, D, {gr.name: gr for gr in groups}, cols, ssr, g - beta0[0],
                   spindle_frequency(ctx, order))


def _candidates(s: _Search, max_effects: int) -> list[str]:
    """The candidates not chosen yet (no new effect once max_effects are chosen); the vibration at the
    strongest spectral line of what is left, found anew at every stage (up to MAX_VIBRATION_LINES
    lines chosen, each an effect of its own in the report)."""
    full = len(s.effects) >= max_effects
    names = [gr.name for gr in s.groups if gr.name not in s.chosen and not (full and gr.effect not in s.effects)]
    lines = sum(st.effect == "vibration" for st in s.stages)
    if lines < MAX_VIBRATION_LINES and not full:
        # the strongest spectral line of what is left, again after a line was chosen: a machine has
        # more than one resonance (a review: 170.3 Hz at 30 nm and 61.7 Hz at 6 nm, one line named,
        # the second left as 2.6 σ of "noise" with nothing said)
        vib = vibration_group(s.ctx, s.resid[s.order], s.order,
                              [s.by_name[st.candidate].frequency for st in s.stages if st.effect == "vibration"])
        if vib is not None:
            name = f"vibration@{len(s.stages)}"
            s.D.add(name, vib.cols)
            vib.name = name
            s.by_name[name] = vib
            names.append(name)
    return names


def _is_local(s: _Search, name: str, entering=()) -> bool:
    """Every library effect acts over the whole part: one whose SSR gain comes from a small area (more
    than LOCAL_LIMIT of it from the best 10 % of the cells, more than twice their share of the points
    and more than SHAPE_RATIO × their share of the effect's own fitted energy) is fitting a local defect,
    which no effect explains (→ unexplained, located). A harmonic of a spindle error motion is judged
    with the other entering harmonics of its effect: harmonics in phase add up in one sector, where
    each one alone gains most (2…8 upr in phase were refused as "local" and the search stopped)."""
    me = s.by_name[name]
    cols = s.cols + s.D.index[name]
    if me.harmonic is not None:
        for c in entering:
            o = s.by_name[c.effect]
            if o.effect == me.effect and o.name != name:
                cols = cols + s.D.index[o.name]
        s.D.ensure(cols)
    gain, points, shape = local_fraction(s.ctx, s.resid, s.D.resid(cols))
    return gain > LOCAL_LIMIT and gain > 2.0 * points and gain > SHAPE_RATIO * shape


#: a candidate whose columns beside those chosen have a variance inflation above this cannot be
#: estimated: it would enter with an absurd value cancelled by another (a 4 nm step in time read
#: straightness 0.32 mm and a tip radius of −36 mm, VIF 1e11). An unresolved but honest parameter
#: (a pose decentre on a near-sphere) has ~5e4.
VIF_LIMIT = 1e8


def _collinear(s: _Search, name: str) -> bool:
    cols = s.cols + s.D.index[name]
    return bool(np.max(uncentred_vif(s.D.gram(cols))) > VIF_LIMIT)


#: an effect whose fitted part (RMS, piston aside) is more than this many times the gap's own RMS is
#: cancelled by another: two look-alikes entered with absurd, opposite values (a review: thermal drift
#: + straightness on a raster over a rotational asphere read z_scale 0.0099 and a tip radius of
#: −1.96 mm, each ~300 × the 5.3 nm gap, VIF 1.7e6 — below VIF_LIMIT). Effects that explain the gap
#: are at most about its size. (Each part against its own share of the fit would be √VIF for one
#: column: 10 there is VIF 100, and a true drift had VIF 98.)
CANCEL_LIMIT = 10.0


def _cancels(s: _Search, cols: list[int]) -> bool:
    """Whether any chosen candidate in the fit on ``cols`` (the piston first) has a fitted part above
    CANCEL_LIMIT × the gap's RMS (both about their means), from the Gram matrix."""
    D = s.D
    piston = D.index["_piston"][0]
    G = D.gram(cols)
    beta = np.linalg.lstsq(G, D.b[cols], rcond=1e-12)[0]
    N = D.g.size
    gap2 = D.gg - D.b[piston] ** 2 / N
    at = {c: j for j, c in enumerate(cols)}
    names = [nm for nm, ix in D.index.items() if nm != "_piston" and ix and ix[0] in at and all(c in at for c in ix)]
    for nm in names:
        j = [at[c] for c in D.index[nm]]
        m = G[at[piston], j] / N  # the columns' means (the piston is a column of ones)
        part2 = float(beta[j] @ (G[np.ix_(j, j)] - N * np.outer(m, m)) @ beta[j])
        if part2 > CANCEL_LIMIT ** 2 * max(gap2, 1e-300):
            return True
    return False


def _tie_threshold(sigma: float, a: Candidate, b: Candidate) -> float:
    return sigma * sigma * stats.chi2.ppf(0.999, max(a.n_params, b.n_params))


def _choose(s: _Search, entering: list[Candidate], sigma: float) -> tuple[Candidate, list[Candidate]]:
    """Of the entering candidates (sorted by ΔBIC), the best fit and those that fit statistically as
    well; the one named is the physical one before a catch-all, then the one with fewer parameters,
    then the lower ΔBIC. Returns it and the others of the tie."""
    best = entering[0]
    tie = [best] + [o for o in entering[1:] if o.ssr - best.ssr < _tie_threshold(sigma, best, o)]
    named = min(tie, key=lambda c: (c.catch_all, c.n_params, c.delta_bic))
    return named, [o for o in tie if o is not named]


def _ambiguous_with(s: _Search, named: Candidate, tie: list[Candidate], sigma: float) -> list[dict]:
    """The others of the tie (another harmonic of the same effect is no ambiguity), and for a vibration
    at an integer multiple k of the spindle frequency, the spindle's axial harmonic k when it fits as
    well: this scan path cannot tell them from the named one."""
    me = s.by_name[named.effect]
    out = []
    for o in tie:
        gr = s.by_name[o.effect]
        if gr.effect == me.effect:
            continue
        out.append({"effect": gr.effect, "harmonic": gr.harmonic, "ssr_excess": float(o.ssr - named.ssr),
                    "candidate": gr.name})
    k = _sync_harmonic(s, me.frequency) if me.effect == "vibration" else None
    if k is not None and not any(a["effect"] == "spindle_axial" for a in out):
        gr = _axial_group(s, k)
        if gr is not None:
            ssr, _ = s.D.ssr(s.cols + s.D.index[gr.name])
            o = Candidate(gr.name, ssr, 0.0, 1.0, 0.0, 1.0, 2)
            if ssr - named.ssr < _tie_threshold(sigma, named, o):
                out.append({"effect": "spindle_axial", "harmonic": k, "ssr_excess": float(ssr - named.ssr),
                            "note": f"the vibration is at {k} × the spindle frequency: synchronous"})
                # judged again once all effects are in, and swapped in below 33 upr (_synchronous_lines)
    return out


#: a vibration within this many cycles over the record of k × the spindle frequency is synchronous:
#: the scan cannot resolve it from the spindle's harmonic k
SYNC_CYCLES = 0.25


def _sync_harmonic(s: _Search, frequency: float | None) -> int | None:
    """k when ``frequency`` lies within SYNC_CYCLES/T (T the record's duration) of k × the spindle
    frequency on a scan whose spindle turns at constant speed, else None."""
    if not s.spindle_hz or frequency is None:
        return None
    k = int(round(frequency / s.spindle_hz))
    T = float(np.ptp(s.ctx.t))
    return k if k >= 1 and abs(frequency - k * s.spindle_hz) * T < SYNC_CYCLES else None


def _axial_group(s: _Search, k: int) -> Group | None:
    """The spindle's axial harmonic k as a candidate: the library's when the scan resolves it, else its
    columns built here (added to the design)."""
    if f"spindle_axial[{k}]" in s.by_name:
        return s.by_name[f"spindle_axial[{k}]"]
    name = f"spindle_axial[{k}]~sync"
    if name not in s.by_name:
        eff = LIBRARY["spindle_axial"]
        gr = _group(name, "spindle_axial", eff.harmonic_params(k), eff.harmonic_columns(s.ctx, k), harmonic=k)
        if gr is None:
            return None
        s.by_name[name] = gr
    if name not in s.D.index:
        s.D.add(name, s.by_name[name].cols)
    return s.by_name[name]


def _synchronous_lines(s: _Search, sigma: float) -> None:
    """Once all effects are in: each vibration line within SYNC_CYCLES/T of k × the spindle frequency
    is judged again against the spindle's axial harmonic k, the other chosen effects in both fits. At
    its stage the line's frequency was refined freely within half a bin, and a line detuned by a small
    fraction of a cycle over the record also takes part of an effect found later (an axial and a tilt
    harmonic 6 on a spiral: a line at 6.004 × the spindle frequency beat spindle_axial[6] and left the
    tilt at half its value, z ≈ −37 — an independent review). Below 33 upr the spindle error is named
    when it fits as well (the tie rule of _choose: fewer parameters) or better, the vibration reported
    ambiguous with it; a line kept as a vibration is always reported synchronous with the harmonic."""
    piston = list(s.D.index["_piston"])
    changed = False
    for i, st in enumerate(s.stages):
        if st.effect != "vibration":
            continue
        k = _sync_harmonic(s, s.by_name[st.candidate].frequency)
        ax = _axial_group(s, k) if k is not None else None
        if ax is None:
            continue
        others = piston + [c for j, o in enumerate(s.stages) if j != i for c in s.D.index[o.candidate]]
        vib = s.by_name[st.candidate]
        cv = Candidate(vib.name, s.D.ssr(others + s.D.index[vib.name])[0], 0.0, 0.0, 0.0, 1.0, vib.n_params)
        ca = Candidate(ax.name, s.D.ssr(others + s.D.index[ax.name])[0], 0.0, 0.0, 0.0, 1.0, ax.n_params)
        tie = abs(ca.ssr - cv.ssr) < _tie_threshold(sigma, cv, ca)
        taken = any(o.effect == "spindle_axial" and o.harmonic == k for o in s.stages)
        note = f"the vibration is at {k} × the spindle frequency: synchronous"
        if k <= SPINDLE_HARMONICS and not taken and (tie or ca.ssr < cv.ssr):
            kept = [a for a in st.ambiguous_with if a["effect"] not in ("spindle_axial", "vibration")]
            st.ambiguous_with = kept + [{"effect": "vibration", "harmonic": k, "ssr_excess": float(min(cv.ssr - ca.ssr, 0.0)),
                                         "note": f"a vibration at {k} × the spindle frequency is a synchronous line"}]
            st.candidate, st.effect, st.harmonic = ax.name, ax.effect, k
            changed = True
        elif not any(a["effect"] == "spindle_axial" for a in st.ambiguous_with):
            st.ambiguous_with = st.ambiguous_with + [{"effect": "spindle_axial", "harmonic": k,
                                                      "ssr_excess": float(ca.ssr - cv.ssr), "note": note,
                                                      "tie": bool(tie)}]
    if changed:
        _restate_evidence(s)


def _add(s: _Search, best: Candidate, ambiguous: list[dict], n_candidates: int) -> None:
    """Record the stage and refit the gap on the chosen columns."""
    gr = s.by_name[best.effect]
    s.stages.append(Stage(gr.effect, s.ssr, best.ssr, float(best.F), best.p, float(best.delta_bic), ambiguous,
                          candidate=gr.name, harmonic=gr.harmonic, n_candidates=n_candidates))
    s.cols = s.cols + s.D.index[best.effect]
    s.D.ensure(s.cols)
    s.ssr, _ = s.D.ssr(s.cols)
    s.resid = s.D.resid(s.cols)


def _refine(s: _Search, sigma: float) -> None:
    """Each choice made among a tie is judged again with every other chosen effect in the fit (at its
    stage, effects found later were still in the gap and could favour a look-alike): of the tie, those
    that still fit as well as the best form the tie now, named by the same rule (_choose); those that
    fit worse by more than the χ² threshold are no longer ambiguous — the scan tells them apart once the
    other effects are modelled. An alternative whose fit beside the others cancels one of them
    (_cancels) is not swapped in, as it could not have entered. The stages' evidence is then computed
    again in their order."""
    piston = list(s.D.index["_piston"])
    for i, st in enumerate(s.stages):
        alts = [a["candidate"] for a in st.ambiguous_with if "candidate" in a]
        taken = {o.candidate for j, o in enumerate(s.stages) if j != i}
        if s.by_name[st.candidate].catch_all:
            # a catch-all named at its stage may have won only because an effect found later was still
            # in the gap (squareness + a tip radius: volumetric took part of the squareness cone and the
            # tip radius was never in that stage's tie): every physical candidate is judged again
            alts = alts + [g.name for g in s.groups if not g.catch_all and g.name in s.D.index
                           and g.name not in alts and g.name != st.candidate]
        alts = [a for a in alts if a not in taken]
        if not alts:
            continue
        others = piston + [c for j, o in enumerate(s.stages) if j != i for c in s.D.index[o.candidate]]
        fits = []
        for nm in [st.candidate] + alts:
            if nm != st.candidate and _cancels(s, others + s.D.index[nm]):
                continue  # a look-alike swapped in against another chosen effect (as at entry: CANCEL_LIMIT)
            gr = s.by_name[nm]
            fits.append(Candidate(nm, s.D.ssr(others + s.D.index[nm])[0], 0.0, 0.0, 0.0, 1.0, gr.n_params,
                                  gr.catch_all))
        best = min(fits, key=lambda c: c.ssr)
        tie = [c for c in fits if c.ssr - best.ssr < _tie_threshold(sigma, best, c)]
        named = min(tie, key=lambda c: (c.catch_all, c.n_params, c.ssr))
        gr = s.by_name[named.effect]
        kept = [a for a in st.ambiguous_with if "candidate" not in a]
        st.ambiguous_with = [{"effect": s.by_name[c.effect].effect, "harmonic": s.by_name[c.effect].harmonic,
                              "ssr_excess": float(c.ssr - named.ssr), "candidate": c.effect}
                             for c in tie if s.by_name[c.effect].effect != gr.effect] + kept
        st.candidate, st.effect, st.harmonic = gr.name, gr.effect, gr.harmonic
    _restate_evidence(s)


def _physical_set(s: _Search, i: int, sigma: float) -> tuple[list[str], float, float, list[list[str]]] | None:
    """For the catch-all named at stage i: sets of two or three physical candidates, each of which
    enters beside the other stages alone, with no more parameters in all than the catch-all; of those
    that fit as well as the catch-all (the χ² tie threshold of the larger parameter count), in which
    every member still enters beside the others (the stage's test, Bonferroni over the physical
    candidates) and none cancels another (_cancels), the one of fewest parameters, then lowest SSR.
    Returns its candidates' names, its SSR, the catch-all's SSR and the other such sets that fit as well
    as it (names, SSR); else None."""
    from itertools import combinations

    st = s.stages[i]
    catch = s.by_name[st.candidate]
    piston = list(s.D.index["_piston"])
    others = piston + [c for j, o in enumerate(s.stages) if j != i for c in s.D.index[o.candidate]]
    taken = {o.candidate for j, o in enumerate(s.stages) if j != i}
    pool = [g for g in s.groups if not g.catch_all and g.name in s.D.index and g.name not in taken]
    ssr0 = s.D.ssr(others)[0]
    ssr_catch = s.D.ssr(others + s.D.index[catch.name])[0]
    single = [g for g in pool if g.n_params < catch.n_params and enters(candidate(s.D, others, g, ssr0, len(pool)))]
    fits = []
    for k in (2, 3):
        for combo in combinations(single, k):
            n = sum(g.n_params for g in combo)
            if n > catch.n_params:
                continue
            cols = others + [c for g in combo for c in s.D.index[g.name]]
            ssr = s.D.ssr(cols)[0]
            if not ssr - ssr_catch < sigma * sigma * stats.chi2.ppf(0.999, catch.n_params):
                continue
            if all(_enters_beside(s, cols, g, len(pool)) for g in combo) and not _cancels(s, cols):
                fits.append((n, ssr, [g.name for g in combo]))
    if not fits:
        return None
    fits.sort(key=lambda f: (f[0], f[1]))
    n, ssr, named = fits[0]
    # the other sets that fit as well as this one (not only as well as the catch-all)
    rivals = [(f[2], f[1]) for f in fits[1:] if f[1] - ssr < sigma * sigma * stats.chi2.ppf(0.999, max(n, f[0]))]
    return named, ssr, ssr_catch, rivals


def _enters_beside(s: _Search, cols: list[int], g, family: int) -> bool:
    """Whether candidate ``g`` passes the stage's entry test beside the rest of ``cols`` (its own columns
    taken out)."""
    own = set(s.D.index[g.name])
    rest = [c for c in cols if c not in own]
    return enters(candidate(s.D, rest, g, s.D.ssr(rest)[0], family))


def _catch_all_sets(s: _Search, sigma: float) -> None:
    """A catch-all still named after _refine is judged against several physical effects together: its
    field can hold two of them at once (a review: z_scale + a tip radius on an anamorphic asphere,
    x²/Rx + y²/Ry and x²/Rx² + y²/Ry² — the 5-parameter volumetric was named alone, 6 of 6 cases).
    Where a set of physical effects with no more parameters fits as well (_physical_set), the set is
    named in the catch-all's place, each member reported ambiguous with the catch-all, and with the
    member that takes its place in another set that fits as well (one swapped)."""
    i = 0
    changed = False
    while i < len(s.stages):
        st = s.stages[i]
        got = _physical_set(s, i, sigma) if s.by_name[st.candidate].catch_all else None
        if got is None:
            i += 1
            continue
        chosen, ssr, ssr_catch, rivals = got
        names = [s.by_name[c].effect for c in chosen]
        new = []
        for c in chosen:
            gr = s.by_name[c]
            amb = [{"effect": st.effect, "harmonic": None, "ssr_excess": float(ssr_catch - ssr),
                    "note": f"{' + '.join(names)} together fit as well as {st.effect}"}]
            for r, ssr_r in rivals:  # another set that fits as well, with this member swapped for another
                rest = set(r) - set(chosen)
                if set(chosen) - set(r) == {c} and len(rest) == 1:
                    o = s.by_name[rest.pop()]
                    if o.effect not in names and all(a["effect"] != o.effect for a in amb):
                        amb.append({"effect": o.effect, "harmonic": o.harmonic, "ssr_excess": float(ssr_r - ssr),
                                    "note": f"in place of {gr.effect} beside the others"})
            amb += [a for a in st.ambiguous_with if a["effect"] not in names and "candidate" not in a]
            new.append(Stage(gr.effect, 0.0, 0.0, 0.0, 0.0, 0.0, amb, candidate=gr.name, harmonic=gr.harmonic,
                             n_candidates=st.n_candidates))
        s.stages[i:i + 1] = new
        i += len(new)
        changed = True
    if changed:
        _restate_evidence(s)


def _restate_evidence(s: _Search) -> None:
    """Each stage's evidence (F, p, ΔBIC against the stages before it) computed again in their order,
    and the fit on them all — after _refine swapped a choice, or _correlated_noise_gate dropped a stage."""
    cols = list(s.D.index["_piston"])
    ssr = s.D.ssr(cols)[0]
    for st in s.stages:
        c = candidate(s.D, cols, s.by_name[st.candidate], ssr, st.n_candidates)
        st.ssr_before, st.ssr_after, st.F, st.p, st.delta_bic = ssr, c.ssr, float(c.F), c.p, float(c.delta_bic)
        cols = cols + s.D.index[st.candidate]
        s.D.ensure(cols)
        ssr = s.D.ssr(cols)[0]
    s.cols, s.ssr, s.resid = cols, ssr, s.D.resid(cols)


def forward_search(s: _Search, sigma: float, max_effects: int) -> _Search:
    """Greedy group-forward selection: at each stage, of the candidates that are significant and
    strong, the named one of the best-fitting tie (_choose) enters unless its gain is local; stops
    when none enters, or when max_effects effects (harmonics of one effect count once) are chosen
    and none of their harmonics is left to enter."""
    for _ in range(max_effects + 2 * len(s.groups)):
        names = _candidates(s, max_effects)
        if not names:
            break
        results = sorted((candidate(s.D, s.cols, s.by_name[name], s.ssr, len(names)) for name in names),
                         key=lambda c: c.delta_bic)
        entering = [c for c in results if enters(c)]
        if not entering:
            break
        named, tie = _choose(s, entering, sigma)
        # cannot be estimated beside the chosen, or cancels one of them: never enters
        while _collinear(s, named.effect) or _cancels(s, s.cols + s.D.index[named.effect]):
            entering = [c for c in entering if c is not named]
            if not entering:
                break
            named, tie = _choose(s, entering, sigma)
        if not entering:
            break
        if _is_local(s, named.effect, entering):  # a local defect: what enters after it would fit it
            break
        _add(s, named, _ambiguous_with(s, named, tie, sigma), len(names))
    _refine(s, sigma)
    _catch_all_sets(s, sigma)
    _synchronous_lines(s, sigma)
    return s


def uncentred_vif(G: np.ndarray) -> np.ndarray:
    """Variance inflation of each column, uncentred (the design holds a constant column): the diagonal
    of the inverse of the Gram matrix normalised to unit diagonal."""
    dn = np.sqrt(np.diag(G))
    return np.diag(np.linalg.pinv(G / np.outer(dn, dn)))


def _raw_params(gr: Group, beta: np.ndarray, sd: np.ndarray, cov3: np.ndarray | None = None) -> tuple[dict, dict]:
    """A candidate's fitted coefficients in the library's parameters and units, with their standard
    deviations. For a vibration, ``cov3`` is the covariance of its raw cos and sin coefficients and of
    its frequency (``_vibration_covariances``)."""
    raw, raw_sd = beta / gr.scale, sd / gr.scale
    if gr.effect == "vibration":
        # A = √(a² + b²), φ = atan2(b, a): first-order propagation of the covariance of a, b and the
        # frequency f. The frequency is estimated from the same record, and φ is quoted at t = 0 (the
        # record's edge), where an error δf moves the phase by 2π·δf·T/2 on average: with f taken as
        # known, u(φ) was half the scatter (a review: 0.246° reported, 0.53° observed on a spiral).
        (a, b) = raw[:2]
        C = np.diag(np.r_[raw_sd[:2] ** 2, 0.0]) if cov3 is None else cov3
        p = Vibration.from_columns(gr.frequency, raw)
        u = {"frequency_hz": float(np.sqrt(max(C[2, 2], 0.0)))} if cov3 is not None else {}
        A = float(np.hypot(a, b))
        if A > 0:
            jA = np.array([a / A, b / A, 0.0])
            jphi = np.array([-b / (A * A), a / (A * A), 0.0])
            u["amplitude"] = float(np.sqrt(max(jA @ C @ jA, 0.0)))
            u["phase_deg"] = float(np.degrees(np.sqrt(max(jphi @ C @ jphi, 0.0))))
        else:
            u["amplitude"] = float(np.hypot(*raw_sd[:2]))
        return p, u
    return ({n: float(v) for n, v in zip(gr.params, raw)}, {n: float(v) for n, v in zip(gr.params, raw_sd)})


def _vibration_covariances(s: "_Search", idx: list, X: np.ndarray, beta: np.ndarray, s2: float) -> dict:
    """Each chosen vibration line's 3×3 covariance of its raw cos and sin coefficients and its
    frequency: the final fit's design bordered by each line's derivative in its frequency,
    ∂/∂f [a cos ωt − b sin ωt] = −2πt·(a sin ωt + b cos ωt), so that the frequency's uncertainty
    (estimated from the same record) and its correlation with the phase at t = 0 and with every other
    column enter (the linearised model at the fitted frequency, the least-squares optimum)."""
    lines = [st.candidate for st in s.stages if st.effect == "vibration"]
    if not lines:
        return {}
    pos = {i: j for j, i in enumerate(idx)}
    t = np.asarray(s.ctx.t, float)
    cols, js = [], []
    for name in lines:
        gr = s.by_name[name]
        j = [pos[i] for i in s.D.index[name]]
        a, b = beta[j][:2] / gr.scale[:2]
        w = 2 * np.pi * gr.frequency * t
        cols.append(-2 * np.pi * t * (a * np.sin(w) + b * np.cos(w)))
        js.append(j)
    Dc = np.column_stack(cols)
    sc = np.sqrt(np.mean(Dc * Dc, axis=0))
    sc[~(sc > 0)] = 1.0
    Xa = np.hstack([X, Dc / sc])
    Ca = np.linalg.pinv(Xa.T @ Xa) * s2
    P = X.shape[1]
    out = {}
    for k, (name, j) in enumerate(zip(lines, js)):
        gr = s.by_name[name]
        jj = list(j[:2]) + [P + k]
        unscale = np.r_[1.0 / gr.scale[:2], 1.0 / sc[k]]
        out[name] = Ca[np.ix_(jj, jj)] * np.outer(unscale, unscale)
    return out


def _fitted_effects(s: _Search) -> tuple[list[dict], np.ndarray]:
    """The final least-squares fit on all chosen columns, gathered by effect in the order each first
    entered: its parameters in the library's units and their standard deviations (σ̂² (AᵀA)⁻¹, σ̂² =
    SSR/(N − P)), the harmonics kept (spindle error motions), its largest VIF, its fitted part, the gap
    left after the effects up to it, and its stages (the evidence of each candidate that entered);
    and the final residual."""
    D, g, idx = s.D, s.g, s.cols
    N, P = g.size, len(idx)
    X = D.X(idx)
    Gs = D.gram(idx)
    beta = np.linalg.lstsq(Gs, D.b[idx], rcond=1e-12)[0]
    resid = g - X @ beta
    s2 = float(resid @ resid) / max(N - P, 1)
    cov = np.linalg.pinv(Gs) * s2
    vif = uncentred_vif(Gs)
    pos = {i: j for j, i in enumerate(idx)}
    vib_cov = _vibration_covariances(s, idx, X, beta, s2)
    found, upto = [], list(D.index["_piston"])
    # an effect's harmonics are one entry; each vibration line is an entry of its own (its frequency)
    groups = list(dict.fromkeys(st.candidate if st.effect == "vibration" else st.effect for st in s.stages))
    for key in groups:
        stages = [st for st in s.stages if (st.candidate if st.effect == "vibration" else st.effect) == key]
        eff = stages[0].effect
        params, unc, js, vifs = {}, {}, [], []
        for st in stages:
            j = [pos[i] for i in D.index[st.candidate]]
            p, u = _raw_params(s.by_name[st.candidate], beta[j], np.sqrt(np.clip(np.diag(cov)[j], 0, None)),
                               vib_cov.get(st.candidate))
            params.update(p)
            unc.update(u)
            js += j
            vifs.append(float(np.max(vif[j])))
            upto += D.index[st.candidate]
        harmonics = sorted(st.harmonic for st in stages) if stages[0].harmonic is not None else None
        found.append({"effect": eff, "params": params, "uncertainty": unc, "harmonics": harmonics,
                      "stage": stages[0], "stages": stages, "vif_max": max(vifs),
                      "fitted": X[:, js] @ beta[js], "resid_upto": D.resid(list(upto))})
    return found, resid


def residual_checks(resid: np.ndarray, sigma: float, order: np.ndarray, P: int) -> dict:
    """What is left against the noise: its RMS, the χ² test of Σr²/σ² with N − P degrees of freedom,
    and the lag-1 autocorrelation along the scan (whiteness)."""
    N = resid.size
    rms = float(np.sqrt(np.mean(resid**2)))
    chi2_p = float(stats.chi2.sf(float(resid @ resid) / max(sigma, 1e-300) ** 2, max(N - P, 1)))
    return {"rms": rms, "chi2_p": chi2_p, "rho1": lag1(resid[order])}


def lag1(r: np.ndarray) -> float:
    """The lag-1 autocorrelation of a series (0 for fewer than 4 values or a constant one)."""
    return float(np.corrcoef(r[:-1], r[1:])[0, 1]) if r.size > 3 and np.std(r) > 0 else 0.0


def select(ctx: ScanContext, g: np.ndarray, max_effects: int = 6, bootstrap: int = 10,
           seed: int = 0) -> dict:
    """The forward selection (module doc). Returns a dict of plain results (see workflow): σ of the
    gap as found (sigma_gap) and re-estimated on the residual once the found effects are removed
    (sigma, the one every check uses)."""
    order = scan_order(ctx, g.size)
    sigma_gap = sigma = gap_noise(g, order)
    groups, unobservable = linear_groups(ctx)
    D = design(g, groups)
    s = forward_search(_start(ctx, g, order, groups, D), sigma, max_effects)
    for _ in range(3):  # σ again without the effects found; the ties depend on it
        if not s.stages:
            break
        s_new = gap_noise(s.resid, order)
        if abs(s_new - sigma) <= SIGMA_SETTLED * sigma:
            break
        sigma = s_new
        s = forward_search(_start(ctx, g, order, groups, D), sigma, max_effects)
    unsupported = _backward(s)
    dropped = _correlated_noise_gate(s, order)
    found, resid = _fitted_effects(s) if s.stages else ([], s.resid)
    checks = residual_checks(resid, sigma, order, len(s.cols))
    checks["dropped_under_correlated_noise"] = dropped
    checks["dropped_unsupported"] = unsupported
    stability = {}
    if s.stages and bootstrap > 0:
        stability = _bootstrap(ctx, g - resid, resid, s.effects, bootstrap, seed, max_effects)
    return {"sigma": sigma, "sigma_gap": sigma_gap, "found": found, "residual": resid, **checks,
            "unobservable": unobservable, "stability": stability, "order": order}


def _effect_key(st) -> str:
    """One entry of the report: an effect with all its harmonics, or one vibration line."""
    return st.candidate if st.effect == "vibration" else st.effect


#: terms of the autoregressive model of the noise, fitted to the residual (Yule–Walker): one is a
#: probe's or an interferometer's lag (AR(1)); three also take AR(2)-like noise and part of flicker
#: (1/f) noise (named in 4–20 of 40 gaps whitened so, against 8–26 whitened by AR(1); 8 or 16 terms
#: gain little more: its slowest wander is a polynomial in time, an effect's signature on a spiral)
#: and change nothing on AR(1) noise (the extra terms fit ~0); benchmarks/README.md
AR_ORDER = 3


def ar_coefficients(r: np.ndarray, p: int = AR_ORDER) -> np.ndarray:
    """φ₁…φ_p of an AR(p) model of the series r (Yule–Walker: the Toeplitz system of its
    autocovariances, whose solution is always a stationary model)."""
    from scipy.linalg import solve_toeplitz

    r = r - r.mean()
    n = r.size
    acov = np.array([r[: n - k] @ r[k:] for k in range(p + 1)]) / n
    if not acov[0] > 0:
        return np.zeros(p)
    return solve_toeplitz(acov[:p], acov[1: p + 1])


def whiten(X: np.ndarray, order: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Rows of X (or a vector) in scan order, whitened for AR(p) noise of coefficients φ (Cochrane &
    Orcutt 1949): x̃ᵢ = xᵢ − Σ φ_k·xᵢ₋ₖ for i ≥ p. Least squares on whitened data is generalised
    least squares under that noise: its F tests hold their α again."""
    Xs = np.asarray(X, dtype=np.float64)[order]
    p = phi.size
    W = Xs[p:].copy()
    for k in range(1, p + 1):
        W -= phi[k - 1] * Xs[p - k: Xs.shape[0] - k]
    return W


#: the exponent range of the power-law (flicker) noise model S(f) = w + A·f^−β
FLICKER_BETA = (0.3, 2.5)
#: up to this many points the power-law model's generalised least squares uses the Cholesky factor of
#: its Toeplitz covariance (O(n³): 0.2 s at 3,000); above, conjugate gradients on the Toeplitz system
#: (products by FFT), preconditioned by its optimal circulant (T. Chan 1988). The circulant alone —
#: Whittle's frequency-domain shortcut — wraps the scan around: it left 15 of 40 spiral gaps of
#: 1/f^1.5 noise naming an effect (benchmarks/README.md, "flicker")
FLICKER_CHOLESKY_POINTS = 3000


def _power_law_fit(f: np.ndarray, I: np.ndarray) -> tuple[float, float, float]:
    """(w, A, β) of S(f) = w + A·f^−β fitted to periodogram ordinates I at frequencies f by Whittle's
    likelihood, Σ ln S + I/S (β within FLICKER_BETA)."""
    from scipy.optimize import minimize

    m = float(np.mean(I))
    lf = np.log(f)

    def nll(q):
        S = np.exp(q[0]) + np.exp(q[1] - q[2] * lf)
        return float(np.sum(np.log(S) + I / S)) / I.size

    best = None
    for b0 in (0.8, 1.5):
        q0 = np.array([np.log(0.3 * m), np.log(0.3 * m) + b0 * np.log(np.median(f)), b0])
        res = minimize(nll, q0, method="L-BFGS-B", bounds=[
            (np.log(m) - 30, np.log(m) + 5), (np.log(m) - 40, np.log(m) + 40), FLICKER_BETA])
        if best is None or res.fun < best.fun:
            best = res
    return float(np.exp(best.x[0])), float(np.exp(best.x[1])), float(best.x[2])


class ToeplitzGLS:
    """Generalised least squares under stationary noise of autocovariance γ (γ₀…γ_{n−1}) along the
    scan: ``gram(X, g)`` gives XᵀΣ⁻¹X, XᵀΣ⁻¹g and gᵀΣ⁻¹g, Σ the Toeplitz matrix of γ, rows of X and g
    taken in scan order (``order``). Σ⁻¹ is applied by the Cholesky factor up to
    FLICKER_CHOLESKY_POINTS, else by preconditioned conjugate gradients (FLICKER_CHOLESKY_POINTS)."""

    def __init__(self, gamma: np.ndarray, order: np.ndarray):
        self.gamma = np.asarray(gamma, dtype=np.float64)
        self.order = order
        n = self.gamma.size
        self.L = None
        if n <= FLICKER_CHOLESKY_POINTS:
            from scipy.linalg import cholesky, toeplitz

            self.L = cholesky(toeplitz(self.gamma), lower=True)
            return
        # Σ·v by FFT: Σ embedded in a circulant of 2n (first column γ, 0, γ reversed)
        c = np.concatenate([self.gamma, [0.0], self.gamma[:0:-1]])
        self._eig = np.fft.rfft(c).real
        # T. Chan's optimal circulant preconditioner: c_k = ((n − k)·γ_k + k·γ_{n−k}) / n
        k = np.arange(n)
        ck = ((n - k) * self.gamma + k * np.concatenate([[0.0], self.gamma[:0:-1]])) / n
        lam = np.fft.rfft(ck).real
        self._pinv = 1.0 / np.maximum(lam, 1e-12 * lam.max())

    def _matvec(self, V):
        n = self.gamma.size
        F = np.fft.rfft(V, 2 * n, axis=0) * self._eig[:, None]
        return np.fft.irfft(F, 2 * n, axis=0)[:n]

    def _precond(self, V):
        n = self.gamma.size
        return np.fft.irfft(np.fft.rfft(V, axis=0) * self._pinv[:, None], n, axis=0)

    def solve(self, B: np.ndarray, tol: float = 1e-8, max_iter: int = 400) -> np.ndarray:
        """Σ⁻¹·B for the columns of B (rows in scan order): conjugate gradients, every column at once."""
        X = np.zeros_like(B)
        R = B.copy()
        Z = self._precond(R)
        P = Z.copy()
        rz = np.einsum("ij,ij->j", R, Z)
        stop = tol * np.sqrt(np.einsum("ij,ij->j", B, B)) + 1e-300
        for _ in range(max_iter):
            Q = self._matvec(P)
            alpha = rz / np.maximum(np.einsum("ij,ij->j", P, Q), 1e-300)
            X += P * alpha
            R -= Q * alpha
            if np.all(np.sqrt(np.einsum("ij,ij->j", R, R)) <= stop):
                break
            Z = self._precond(R)
            rz_new = np.einsum("ij,ij->j", R, Z)
            P = Z + P * (rz_new / np.maximum(rz, 1e-300))
            rz = rz_new
        return X

    def gram(self, X: np.ndarray, g: np.ndarray):
        Xs = np.asarray(X, dtype=np.float64)[self.order]
        gs = np.asarray(g, dtype=np.float64)[self.order]
        B = np.column_stack([Xs, gs])
        if self.L is not None:
            from scipy.linalg import solve_triangular

            W = solve_triangular(self.L, B, lower=True)
            M = W.T @ W
        else:
            M = B.T @ self.solve(B)
            M = 0.5 * (M + M.T)
        p = Xs.shape[1]
        return M[:p, :p], M[:p, p], float(M[p, p])


def power_law_gls(r: np.ndarray, order: np.ndarray, skip: int = 0) -> ToeplitzGLS | None:
    """Generalised least squares for flicker noise — power-law noise S(f) = w + A·f^−β, an
    interferometer's or a probe's drift — fitted to the residual r (scan order); None for a scan
    shorter than 64. The model is fitted by Whittle's likelihood to r's periodogram above its lowest
    1 + ``skip`` frequencies — the chosen effects took r's slowest wander (a drift fitted as an
    effect leaves r short of it) — and extrapolated below them, which an AR model cannot do (its
    spectrum flattens there: AR(3), 8 or 16 left 8–20 of 40 gaps of 1/f noise naming an effect).
    The covariance is the Toeplitz one of S (its autocovariance from S on a circle 16 n long): exact
    GLS for a window of the noise, not a periodic one (ToeplitzGLS). Measured (benchmarks/README.md,
    "flicker"): on 1/f^1.5 noise along a 400-point spiral 16 of 40 gaps named an effect under the AR
    gate alone, 0 with the true covariance and 0 with this fitted one."""
    n = r.size
    if n < 64:
        return None
    rc = r - r.mean()
    I = np.abs(np.fft.rfft(rc)) ** 2 / n
    f = np.arange(I.size, dtype=np.float64) / n
    j0 = min(1 + int(skip), I.size // 8)
    stop = I.size - 1 if n % 2 == 0 else I.size  # no Nyquist ordinate (real: half the others' weight)
    fi, Ii = f[j0:stop], I[j0:stop]
    if not Ii.mean() > 0:
        return None
    w, A, beta = _power_law_fit(fi, Ii)
    M = 16 * n
    fg = np.arange(M // 2 + 1, dtype=np.float64) / M
    fg[0] = fg[1]
    S = A * fg ** -beta
    # a white floor of at least 10⁻⁸ of the slowest term's power: Σ's condition number stays below
    # ~10⁸ (β 2.4 without one: 10¹⁴ at 10⁵ points, and the conjugate gradients did not converge)
    S += max(w, 1e-8 * float(S[0]))
    gamma = np.fft.irfft(S, M)[:n]
    try:
        return ToeplitzGLS(gamma, order)
    except np.linalg.LinAlgError:
        return None


def _correlated_noise_gate(s: _Search, order: np.ndarray) -> list[str]:
    """The selection's F tests and ΔBIC assume white noise. Noise correlated along the scan (a probe's
    or an interferometer's lag, flicker) has a coloured spectrum, and its slow part reads as effects:
    on pure AR(1) noise of ρ = 0.5, 15 of 40 spiral gaps named one (a low "vibration" mostly). When
    the residual left by the chosen effects is correlated (|lag-1 autocorrelation| ρ̂ > RHO_GATE and
    > 4/√N), every chosen effect (all its harmonics; each vibration line) is tested again beside the
    others on data and columns whitened for the residual's AR(AR_ORDER) model (whiten), and the
    least supported of those that no longer enter (Bonferroni over its stage's family, as it entered;
    ΔBIC < −10) is dropped — one at a time, the others tested again after each drop, with ρ̂ and the
    model fitted again on what is left (a review: dropping every failing effect at once lost a true
    squareness beside a spurious look-alike, each failing only beside the other). When every effect
    stands the AR noise, each is tested again under flicker noise (power_law_gls): an AR model's
    spectrum flattens at the frequencies the effects took out of the residual, where a power law
    goes on rising. Measured (benchmarks/README.md, "flicker"): 1/f and 1/f^1.5 noise, 40 gaps each on
    a 400-point spiral, a 1,505-point raster and a 5,000-point spiral: 8–26 named an effect under
    the AR gate alone, 0 with the flicker test; true effects at 3 and 6 σ named as often as before
    under white, AR(1) 0.5 and flicker noise, 3 of 27 fewer at 3 σ under AR(1) 0.8. Effects the gap
    holds well above the noise stay; on white noise ρ̂ stays below the gate and nothing changes.
    Returns the dropped effects' names."""
    N = s.g.size
    dropped: list[str] = []
    while s.stages:
        r = s.resid[order]
        rho = lag1(r)
        if not (abs(rho) > max(RHO_GATE, 4.0 / np.sqrt(N))) or N <= 4 * AR_ORDER + len(s.cols):
            break
        phi = ar_coefficients(r, AR_ORDER)
        worst = _least_supported(s, order, lambda A, phi=phi: whiten(A, order, phi))
        if worst is None:  # every effect stands the AR noise: does each stand flicker noise too?
            flicker = power_law_gls(r, order, skip=len(s.cols))
            if flicker is not None:
                worst = _least_supported(s, order, flicker)
        if worst is None:
            break
        dropped.append(s.by_name[worst].effect if worst in s.by_name else worst)
        s.stages = [st for st in s.stages if _effect_key(st) != worst]
        _restate_evidence(s)  # the stages left: their evidence without the dropped one
    return dropped


def _least_supported(s: _Search, order: np.ndarray, white=None):
    """The chosen effect (all its harmonics; one vibration line) least supported beside all the others,
    among those that would no longer enter (Bonferroni over its stage's family as it entered; ΔBIC <
    BIC_STRONG) — None when every one still would. ``white``: a map whitening data and columns for a
    noise model first (whiten; _correlated_noise_gate), or a ToeplitzGLS (power_law_gls) giving the
    generalised Gram matrices; None: as they are."""
    N = s.g.size
    piston = list(s.D.index["_piston"])
    keys = list(dict.fromkeys(_effect_key(st) for st in s.stages))
    cols_of = {k: [c for st in s.stages if _effect_key(st) == k for c in s.D.index[st.candidate]] for k in keys}
    allc = piston + [c for k in keys for c in cols_of[k]]
    s.D.ensure(allc)
    at = {c: j for j, c in enumerate(allc)}
    if isinstance(white, ToeplitzGLS):
        G, b, gg = white.gram(s.D.X(allc), s.g)
        n = s.g.size

        def ssr(cols):  # gᵀΣ⁻¹g − bᵀG⁻¹b over the columns kept (a pseudo-inverse: near-collinear ones)
            j = [at[c] for c in cols]
            return max(gg - float(b[j] @ np.linalg.lstsq(G[np.ix_(j, j)], b[j], rcond=1e-13)[0]), 1e-300)
    else:
        if white is None:
            Xw, gw = np.asarray(s.D.X(allc), dtype=np.float64), np.asarray(s.g, dtype=np.float64)
        else:
            Xw, gw = white(s.D.X(allc)), white(s.g)
        n = gw.size

        def ssr(cols):
            A = Xw[:, [at[c] for c in cols]]
            e = gw - A @ np.linalg.lstsq(A, gw, rcond=1e-12)[0]
            return max(float(e @ e), 1e-300)

    full = ssr(allc)
    dof = n - len(allc)
    worst, worst_score = None, 0.0
    for k in keys:
        pe = len(cols_of[k])
        without = ssr([c for c in allc if c not in set(cols_of[k])])
        F = ((without - full) / pe) / (full / dof) if dof > 0 else 0.0
        p = float(special.fdtrc(pe, dof, F)) if dof > 0 and F > 0 else 1.0
        dbic = n * np.log(full / without) + pe * np.log(n)
        m = max(st.n_candidates * (getattr(s.by_name[st.candidate], "n_search", N / 2)
                                   if st.effect == "vibration" else 1)
                for st in s.stages if _effect_key(st) == k)
        if not (significant(p, m) and dbic < BIC_STRONG):
            score = p * m / ALPHA + max(dbic - BIC_STRONG, 0.0)  # how far from entering
            if worst is None or score > worst_score:
                worst, worst_score = k, score
    return worst


def _backward(s: _Search) -> list[str]:
    """After the forward search and _refine: a chosen effect that no longer passes the entry test beside
    all the others is dropped — the least supported first, one at a time, the others judged again
    after each drop. An effect chosen early can be made redundant by those found after it (an
    independent review's two hidden effects: a catch-all's place re-judged by _refine went to a
    dynamic_lag of ΔBIC +8.7, F 0.47, named first while the true drift was left out; a 0.9 nm
    vibration at 3 × the spindle's frequency beside axial and tilt harmonics). Returns the dropped
    effects' names."""
    dropped: list[str] = []
    while s.stages:
        worst = _least_supported(s, s.order)
        if worst is None:
            break
        dropped.append(s.by_name[worst].effect if worst in s.by_name else worst)
        s.stages = [st for st in s.stages if _effect_key(st) != worst]
        _restate_evidence(s)
    return dropped


def _bootstrap(ctx, fitted, resid, names, B, seed, max_effects) -> dict:
    """How often each chosen effect is chosen again when the residual is resampled in blocks along the
    scan (moving-block bootstrap; the scan itself, every k-th point down to ≤ 50,000, is kept)."""
    rng = np.random.default_rng(seed)
    order = np.argsort(ctx.t, kind="stable")
    k = max(order.size // 50_000, 1)
    keep = np.sort(order[::k])
    sub = ScanContext(ctx.x[keep], ctx.y[keep], ctx.f[keep], ctx.fx[keep], ctx.fy[keep], ctx.t[keep],
                      ctx.c[keep], ctx.r_norm, ctx.t0, ctx.t_span)
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
        got = {f["effect"] for f in res["found"]}
        for nm in names:
            count[nm] += nm in got
    return {nm: c / B for nm, c in count.items()}
