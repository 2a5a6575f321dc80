"""`method: robust` — outliers against a leave-one-out local plane, judged in robust σ (issue 16).

For every point P the reference is the least-squares plane through the other points of its 2a × 2a
window (P itself and the points already set aside do not count), and

    s(P) = D(P) − plane(P),    z(P) = s(P) / √(1 + h(P))

with h = gᵀ M⁻¹ g the leverage of P in that fit (g = (1, x_P, y_P), M = Σ g gᵀ over the window): z is s
scaled to the noise of one point wherever P sits — in the middle of its window or at the rim, where
the window is one-sided and the plane extrapolates (h grows there). A plane, not a mean, follows a
slope: steep regions and the rim do not look like outliers.

σ. σ_g = 1.4826 · median |z − median z| over the cloud (outliers do not inflate it), and a local σ_l:
the RMS of z over the window's points within 3 σ of their plane, corrected for that truncation
(÷ 0.9733). A point is judged against σ(P) = max(σ_g, σ_l(P)): never below the cloud's noise, above it
where the neighbourhood is rougher (a ripple or a curved region the plane cannot follow).

Rounds (iteratively trimmed least squares). A point with |z| ≥ 3 σ(P) does not enter the planes of the
next round, so a spike no longer lifts its neighbours' reference and the points of a dig stop pulling
their plane toward the dig; the planes and σ are computed again, until the set of trimmed points
stops changing. The outliers are then the points with

    |z| > max(threshold_sigma · σ(P), floor)

and, from them, a dig or scratch is grown: a neighbour (within 1.5 mean point spacings) of an outlier
whose z has the same sign and exceeds 3 σ(P) is an outlier too, repeated until no point joins (a few
points on a dig's edge are only partly deep). `floor` is an absolute limit: a point nearer than that
to its plane is never removed, so noise-free data (form error alone, σ → 0) loses nothing.

Two windows decide. A dig whose depth falls off smoothly (a round pit: a Gaussian profile) is partly
followed by the 2a quadratic — its shallow flanks are never trimmed and slope into it, and the fit
bends down so that points 10 σ deep read 3–5 σ against it. The coarse pass's windows (COARSE · a)
follow a tenth of it at most: a point the coarse pass finds beyond threshold_sigma times its own σ
(which holds the form the larger window cannot follow), and that the form tests below leave in the
coarse windows, joins the dig it belongs to when the dig is grown from its flagged points — never on
its own (counted alone, form a 9 mm window cannot follow — a 50 mm part's order-6 residual — lost 4
points of noise-free data). Measured on an independent review's Gaussian pits (1 µm deep, 20 nm
noise, 1.9 points/mm², seeds 1–3): points deeper than 10 σ found 0.89–0.98 → 0.999–1.00, deeper
than 5 σ 0.61–0.80 → 0.82–0.93; flat-bottomed digs unchanged.

Form, not outlier. The quadratic of a 2a window cannot follow every smooth surface: at a cone tip
(a polishing residual's centre), a crest, a turned-down edge or the end of a star's line its error
reaches 0.04–0.4 µm, far above the floor on noise-free data. A candidate is kept when (i) the
quadratics of the windows around it disagree at it by about its deviation (|z| ≤ AGREE · their
spread), or (ii) some window holding it, the point inside that window's data (leverage ≤ H_MAX),
predicts it within TRIM σ(P) (`_best_window_z`). An outlier is trimmed from every window and stands
out in all of them; model error stands out only in the windows whose quadratic cannot follow it.
Measured (issue 16): noise-free cases (scattered, dense, raster, star, ripple, steep edge and ridge;
seeds 40–45) lose 1 point in 42 runs, against 61 points in 18 of them before (ii); the issue's
mixture keeps F1 0.99 (tests/test_knn_denoise.py, benchmarks/README.md).

Ramps, not bumps (review 7). Where the floor sets the threshold (noise-free data: σ → 0), the trim
sets aside every point of a kink narrower than the window, and a cone tip or a crease reads as a bump
that neither test above saves (a 0.4 µm centre cone of 0.75 mm radius on a 0.18 mm raster lost 49
points). A flagged group judged against the floor whose deviation runs on into its surroundings — the
step across its edge within 3 σ, the floor or twice its own inner steps, and its edge points at most
half its peak — is form (`_keep_tapered`). A spike's edge step is its height; the issue's digs keep
≥ 0.57 of their depth at the edge. Not with noise: a round pit tapers as well, and the fine fit bends
into it. Measured: the reviewer's noise-free centre + roll-off part 52 points lost per seed → 0, the
cone part 49 → 0; its 10 mm hex part (10 / 12 / 9, σ set by a ripple the window cannot follow, not by
the floor) and the noisy centre + roll-off mixture's 36–38 false removals are unchanged; the issue's
classes too (benchmarks/bench_denoise.py --classes).

On Gaussian noise the false-positive rate claimed is erfc(threshold_sigma / √2) (5.7e-7 at 5 σ);
`false_positive_rate` in the report says it.

Vectorised on a grid of cells of `spacing`: the window sums Σ w·(1, x, y, x², xy, y², D, xD, yD) of
every cell come from one box filter each (the box of (2·round(a/h) + 1)² cells around the point's
cell), and each point's own term is subtracted from its window's sums (leave-one-out), then a closed-form
solve per cell. No neighbour search, no loop over points. Speed (issue 16: 12 s → ≤ 2 s at 10⁶ points,
the same decisions): the points are taken in the order of their fine cells; the per-cell sums over all
points are formed once per pass and each round subtracts its trimmed points (weights are 0 or 1); the
box of cells is summed separably (x, then y); the monomials are formed slice by slice (not stored) and
the per-point and per-cell work runs in slices on up to THREADS threads.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TRIM = 3.0             # |z| ≥ TRIM σ: not used in the next round's planes; also the growth threshold
TRUNCATED_VAR = 0.9733  # variance of a unit normal truncated at ±3
MAX_ROUNDS = 10
COARSE = 3.0          # the first pass: windows this many times larger
COARSE_ROUNDS = 3
RIDGE = 1e-6           # relative ridge on the slope and curvature terms: a window of collinear points
                       # (a star's line) gets no slope across the line instead of a singular system
MIN_QUADRATIC = 12     # fewer points in a window: a plane
AGREE = 1.25
COARSE_JOIN = 2.0      # a coarse-pass candidate joins a dig only beyond this many σ of the fine fit too
NOISE_FREE = 1e-4      # _keep_tapered acts where the flagged points' σ is below this × the floor
STEP_NOISE = 3.0       # _keep_tapered: an edge step within this many σ, or within STEP_RAMP times the
STEP_RAMP = 2.0        # group's own steps, continues the surface (form) …
TAPER = 0.5            # … when its edge points also keep at most this of its peak deviation
H_MAX = 1.0            # a window judges a point when its leverage there is at most this
CHUNK = 1 << 15        # points per slice of the per-point work (a slice's arrays stay in cache)
CELL_CHUNK = 1 << 13   # cells per slice of the per-cell solves
THREADS = 8              # at most; and never more than this process's budget (core.parallel.thread_count:
                         # 1 in a batch pool's worker, whose N processes already fill the N cores)


@dataclass
class RobustResult:
    flagged: np.ndarray      # bool per point
    z: np.ndarray            # s / √(1 + h), mm (NaN where the window held fewer than 3 other points)
    sigma: np.ndarray        # σ(P) = max(σ_g, σ_l), mm
    sigma_global: float      # σ_g, mm
    threshold: np.ndarray    # max(threshold_sigma · σ(P), floor), mm
    rounds: int
    grown: int               # points added by growing digs
    unjudged: int            # points whose window held fewer than 3 other points
    kept_as_form: int = 0    # flagged points kept as form on noise-free data (_keep_tapered)


@dataclass
class _CellFits:
    """The local quadratics of one pass: per cell its coefficients (ncell × 6, in the cell's own
    coordinates), its inverse normal matrix folded for the leverage (15 × ncell, see _LEV), the window's
    point count, and the weights (0/1 per point) the fits were made with."""
    beta: np.ndarray
    levT: np.ndarray
    count: np.ndarray
    w: np.ndarray


MONO = [(a, k - a) for k in range(5) for a in range(k, -1, -1)]       # u^a v^b, a + b ≤ 4 (15)
BASIS = MONO[:6]                                                      # 1, u, v, u², uv, v²
_MI = {m: i for i, m in enumerate(MONO)}
_MMAT = np.array([[_MI[(p[0] + q[0], p[1] + q[1])] for q in BASIS] for p in BASIS])


def _shift_matrix(monos, dx, dy):
    """T with (u + dx)^a (v + dy)^b = Σ T[.., j] u^i v^k over the monomials `monos`."""
    from math import comb

    idx = {m: i for i, m in enumerate(monos)}
    T = np.zeros((len(monos), len(monos)))
    for r, (a, b) in enumerate(monos):
        for i in range(a + 1):
            for k in range(b + 1):
                T[r, idx[(i, k)]] += comb(a, i) * comb(b, k) * dx ** (a - i) * dy ** (b - k)
    return T


def _cell_grid(x, y, c):
    """(cell index per point, nx, ny, the cells' origin x0, y0) of a grid of square cells of side c."""
    x0, y0 = x.min(), y.min()
    nx = int(np.floor((x.max() - x0) / c)) + 1
    ny = int(np.floor((y.max() - y0) / c)) + 1
    ix = np.clip(np.floor((x - x0) / c).astype(np.int64), 0, nx - 1)
    iy = np.clip(np.floor((y - y0) / c).astype(np.int64), 0, ny - 1)
    return iy * nx + ix, ix, iy, nx, ny, x0, y0


def _monomials(u, v) -> np.ndarray:
    """u^a v^b for MONO, as a (15, n) array (rows contiguous: one bincount or product per monomial);
    its first six rows are BASIS. Integer powers by products (no pow)."""
    up, vp = [None, u], [None, v]
    for k in range(2, 5):
        up.append(up[-1] * u)
        vp.append(vp[-1] * v)
    out = np.empty((len(MONO), len(u)))
    for r, (a, b) in enumerate(MONO):
        if a == 0 and b == 0:
            out[r] = 1.0
        elif b == 0:
            out[r] = up[a]
        elif a == 0:
            out[r] = vp[b]
        else:
            np.multiply(up[a], vp[b], out=out[r])
    return out


# leverage gᵀ M⁻¹ g = Σ_k mono_k · (M⁻¹ summed over the pairs (i, j) whose product is monomial k)
_LEV = np.zeros((36, len(MONO)))
_LEV[np.arange(36), _MMAT.ravel()] = 1.0


class _Windows:
    """Cells of side 2a / CELLS (the window = CELLS × CELLS cells around the point's cell) and the
    window sums of per-cell moments, computed in each cell's own coordinates (units of a) and shifted
    to the target cell's centre exactly (binomial expansion): no large coordinates, no cancellation."""

    CELLS = 5

    def __init__(self, x, y, window):
        self.a = float(window)
        self.c = 2.0 * self.a / self.CELLS
        self.cell, ix, iy, self.nx, self.ny, x0, y0 = _cell_grid(x, y, self.c)
        self.ncell = self.nx * self.ny
        # coordinates relative to the own cell's centre, in units of a
        self.u = (x - (x0 + (ix + 0.5) * self.c)) / self.a
        self.v = (y - (y0 + (iy + 0.5) * self.c)) / self.a
        half = self.CELLS // 2
        self.shifts = [(sx, sy) for sy in range(-half, half + 1) for sx in range(-half, half + 1)]
        step = self.c / self.a
        self.T = [_shift_matrix(MONO, sx * step, sy * step) for sx, sy in self.shifts]
        self.Tb = [_shift_matrix(BASIS, sx * step, sy * step) for sx, sy in self.shifts]

    def mono(self, idx):
        """The monomials MONO (15 × k) of the points ``idx`` (a slice or indices), computed when needed
        (not stored: 120 bytes a point); the first six rows are BASIS."""
        return _monomials(self.u[idx], self.v[idx])

    def cell_sums(self, w, vals):
        """Per-cell Σ w · vals[j] (ncell × m) of the rows of ``vals`` (m × n)."""
        out = np.empty((self.ncell, len(vals)))
        for j in range(len(vals)):
            out[:, j] = np.bincount(self.cell, weights=w * vals[j], minlength=self.ncell)
        return out

    def full_sums(self, d):
        """(per-cell Σ of the monomials MONO, per-cell Σ d · BASIS) over all points: ncell × 15 and
        ncell × 6, summed slice by slice (a slice's cells are a short range: the points are in the
        order of the fine cells)."""
        mom = np.zeros((self.ncell, len(MONO)))
        dat = np.zeros((self.ncell, len(BASIS)))

        def part(sl):
            cell = self.cell[sl]
            lo = int(cell.min())
            c = cell - lo
            size = int(c.max()) + 1
            m = self.mono(sl)
            pm = np.stack([np.bincount(c, weights=m[k], minlength=size) for k in range(len(MONO))], axis=1)
            dd = d[sl]
            pd = np.stack([np.bincount(c, weights=m[k] * dd, minlength=size) for k in range(len(BASIS))],
                          axis=1)
            return lo, size, pm, pd

        for lo, size, pm, pd in _in_chunks(part, len(d)):
            mom[lo:lo + size] += pm
            dat[lo:lo + size] += pd
        return mom, dat

    def binary_sums(self, w, full, d=None):
        """The per-cell sums of ``full_sums`` for weights of 0 or 1: the few points of weight 0 (the
        trimmed ones) subtracted, instead of summing every point again. d None: the monomials' sums
        (``full`` the first of full_sums); else the sums of d · BASIS (``full`` the second)."""
        off = np.flatnonzero(w == 0)
        out = full.copy()
        if off.size == 0:
            return out
        cell = self.cell[off]
        m = self.mono(off)
        if d is not None:
            m = m[:len(BASIS)] * d[off]
        for j in range(out.shape[1]):
            out[:, j] -= np.bincount(cell, weights=m[j], minlength=self.ncell)
        return out

    def window(self, per_cell, T=None):
        """Window sums at every cell: Σ over the box of the neighbour cells' sums, each shifted to the
        target cell's coordinates by T (None: plain sums). The box is summed separably — along x, then
        along y — since a shift by (sx, sy) is the shift by (sx, 0) followed by the one by (0, sy):
        2 · CELLS shifted sums instead of CELLS²."""
        g = per_cell.reshape(self.ny, self.nx, -1)
        half = self.CELLS // 2
        for axis in (1, 0):
            out = np.zeros_like(g)
            n = g.shape[axis]
            for s in range(-half, half + 1):
                if abs(s) >= n:
                    continue
                lo_src, hi_src = max(s, 0), n + min(s, 0)
                lo_dst, hi_dst = max(-s, 0), n + min(-s, 0)
                if axis == 1:
                    src = g[:, lo_src:hi_src]
                else:
                    src = g[lo_src:hi_src]
                if T is not None:
                    src = src @ T[self.shifts.index((s, 0) if axis == 1 else (0, s))].T
                if axis == 1:
                    out[:, lo_dst:hi_dst] += src
                else:
                    out[lo_dst:hi_dst] += src
            g = out
        return g.reshape(self.ncell, -1)


def _plane_loo(win: _Windows, d, w, full):
    """z = leave-one-out residual of the weighted local quadratic (a plane where the window holds
    fewer than MIN_QUADRATIC points), scaled to one point's noise, for every point. w: 0 or 1 per
    point; ``full``: the per-cell sums of the monomials and of d · g over all points (_full_sums)."""
    mom = win.window(win.binary_sums(w, full[0]), win.T)                 # ncell × 15
    dat = win.window(win.binary_sums(w, full[1], d), win.Tb)             # ncell × 6
    S0 = mom[:, 0]
    live = S0 > 0
    quad = S0 >= MIN_QUADRATIC
    scale = np.where(live, S0, 1.0)
    ridge = np.where(quad, RIDGE, 1e6)[:, None] * np.array([0, 0, 0, 1, 1, 1.0]) + RIDGE * np.array(
        [0, 1, 1, 0, 0, 0.0])
    ridge *= scale[:, None]
    beta = np.empty((win.ncell, len(BASIS)))
    betaT = np.empty((len(BASIS), win.ncell))
    levT = np.empty((len(MONO), win.ncell))
    diag = np.arange(6)

    def cells(sl):
        M = mom[sl][:, _MMAT]                                            # cells × 6 × 6
        M[:, diag, diag] += ridge[sl]
        M[~live[sl]] = np.eye(6)
        Minv = np.linalg.inv(M)
        beta[sl] = np.einsum("cij,cj->ci", Minv, dat[sl])
        betaT[:, sl] = beta[sl].T
        levT[:, sl] = (Minv.reshape(-1, 36) @ _LEV).T

    _in_chunks(cells, win.ncell, CELL_CHUNK)
    z = np.empty(len(d))

    def chunk(sl):
        # the point's own cell's quadratic and leverage, term by term (a chunk stays in cache)
        cell = win.cell[sl]
        mono = win.mono(sl)
        fit = mono[0] * np.take(betaT[0], cell)
        for k in range(1, 6):
            fit += mono[k] * np.take(betaT[k], cell)
        lev = mono[0] * np.take(levT[0], cell)
        for k in range(1, len(MONO)):
            lev += mono[k] * np.take(levT[k], cell)
        ws = w[sl]
        # in the fit (w = 1): LOO residual e / (1 − h), its variance σ² / (1 − h);
        # out of it (w = 0): prediction residual e, variance σ² (1 + h)
        den = np.where(ws > 0, np.clip(1.0 - lev, 1e-12, None), 1.0 + lev)
        zz = (d[sl] - fit) / np.sqrt(den)
        ok = np.take(S0, cell) - ws >= 3 - 1e-9
        z[sl] = np.where(ok, zz, np.nan)

    _in_chunks(chunk, len(d))
    return z, _CellFits(beta, levT, S0, w), live


def _in_chunks(fn, n, size=None):
    """[fn(slice)] over consecutive slices of ``size`` (CHUNK) points, on up to THREADS threads (numpy's gathers
    and arithmetic release the GIL); each slice writes its own part of an output or returns it."""
    from pointspro.core.parallel import in_chunks

    return in_chunks(fn, n, size or CHUNK, THREADS)


def _best_window_z(win: _Windows, fits: _CellFits, live, pos, d):
    """min over the windows that hold each point of `pos` — the 5 × 5 cells around its cell, each
    window the CELLS × CELLS box around its own cell — of |z_W|, the point's leave-one-out residual
    against that window's quadratic scaled to one point's noise (the own cell's is the z judged first):

        z_W = e_W / √(1 − h_W)  (the point in the fit, w = 1),   z_W = e_W / √(1 + h_W)  (w = 0)

    with e_W = D − fit_W and h_W its leverage there; a window counts where it holds at least 3 other
    points and the point is inside its data (h_W ≤ H_MAX: an interpolation, not an extrapolation).

    Why: an outlier stands out in every neighbourhood (it is trimmed from all of them, none predicts
    it); the model error of a quadratic at a crest, a cone tip or a turned-down edge stands out only
    in the windows whose quadratic cannot follow it — some window holding the point predicts it."""
    c = win.cell[pos]
    ix, iy = c % win.nx, c // win.nx
    step = win.c / win.a
    half = win.CELLS // 2
    wp = fits.w[pos]
    best = np.full(len(pos), np.inf)
    for sy in range(-half, half + 1):
        for sx in range(-half, half + 1):
            jx, jy = ix + sx, iy + sy
            inside = (jx >= 0) & (jx < win.nx) & (jy >= 0) & (jy < win.ny)
            cc = np.where(inside, jy * win.nx + jx, 0)
            ok = inside & live[cc] & (fits.count[cc] - wp >= 3 - 1e-9)
            mono = _monomials(win.u[pos] - sx * step, win.v[pos] - sy * step)
            fit = np.einsum("ip,pi->p", mono[:len(BASIS)], fits.beta[cc])
            lev = np.einsum("ip,ip->p", mono, fits.levT[:, cc])
            ok &= lev <= H_MAX
            den = np.where(wp > 0, np.clip(1.0 - lev, 1e-12, None), 1.0 + lev)
            zw = np.abs(d[pos] - fit) / np.sqrt(den)
            best = np.where(ok, np.fmin(best, zw), best)
    return best


def _disagreement(win: _Windows, fits, live, pos):
    """max − min, at the points `pos`, of the quadratics of the point's own cell and of the cells around
    it (every window that holds the point): where the surface is locally quadratic they agree to the
    noise; at a kink or a crest too sharp for the window they differ by about the model error."""
    c = win.cell[pos]
    ix, iy = c % win.nx, c // win.nx
    step = win.c / win.a
    preds = []
    for sx, sy in [(sx, sy) for sy in (-1, 0, 1) for sx in (-1, 0, 1)]:
        jx, jy = ix + sx, iy + sy
        inside = (jx >= 0) & (jx < win.nx) & (jy >= 0) & (jy < win.ny)
        cc = np.where(inside, jy * win.nx + jx, 0)
        ok = inside & live[cc]
        u, v = win.u[pos] - sx * step, win.v[pos] - sy * step
        g = np.stack([u ** a * v ** b for a, b in BASIS], axis=1)
        preds.append(np.where(ok, np.einsum("pi,pi->p", g, fits.beta[cc]), np.nan))
    preds = np.array(preds)
    return np.nanmax(preds, axis=0) - np.nanmin(preds, axis=0)


def _robust_sigma(z):
    z = z[np.isfinite(z)]
    if z.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(z - np.median(z))))


def _trim_rounds(win, d, w, max_rounds, progress, offset):
    """Iteratively trimmed local fits: returns the final weights, z, σ(P), σ_g, the cells' fits."""
    n = len(d)
    full = win.full_sums(d)
    prev = None
    last = None
    sig = None
    rounds = 0
    while rounds < max_rounds:
        rounds += 1
        if progress is not None:
            progress.update(min(0.85, 0.1 + 0.06 * (rounds + offset)), f"round {rounds + offset}")
        z, beta, live = _plane_loo(win, d, w, full)
        sg = _robust_sigma(z)
        # local σ: RMS of z over the window's points inside the trim (w), truncation corrected
        fin = np.isfinite(z)
        zf = np.where(fin, z, 0.0)
        # (without the point itself: an outlier does not inflate its own σ)
        inside = w * fin
        z2 = zf * zf
        cw = win.window(np.column_stack([win.binary_sums(inside, full[0][:, :1])[:, 0],
                                         win.cell_sums(inside, z2[None, :])[:, 0]]))
        c0 = np.take(np.ascontiguousarray(cw[:, 0]), win.cell) - inside
        c1 = np.take(np.ascontiguousarray(cw[:, 1]), win.cell) - inside * z2
        with np.errstate(invalid="ignore", divide="ignore"):
            sl = np.sqrt(np.clip(c1, 0, None) / c0 / TRUNCATED_VAR)
        sig = np.fmax(sg, np.where(c0 >= 8, sl, 0.0))
        # ≤: a point exactly on its local fit is never trimmed — on an exactly constant residual σ is 0
        # and "<" trimmed every point; the next round saw empty windows and judged none (a review: 0 of
        # 20 spikes of 1–20 µm found, and "fewer than 3 others in their window" said of every point)
        trimmed = fin & ~(np.abs(zf) <= TRIM * sig)
        trimmed |= ~fin & (w == 0)  # an unjudged point keeps its weight (a dig's emptied windows)
        changed = None if prev is None else int(np.count_nonzero(trimmed != prev))
        if changed is not None and changed <= max(0, n // 100_000):
            break
        # stalled: a few points at the TRIM boundary flip back and forth for ever (review 7, 10⁶ random
        # points: 71, 17, 16, 17, 16, … changes in the fine pass, all 10 rounds run: 20 s on 2 busy
        # cores); they sit at 3 σ, far below the 5 σ decision, so the rounds stop once the changes stop
        # falling and are below 0.01 % of the points
        if changed is not None and last is not None and changed >= last and changed <= n // 10_000:
            break
        last = changed
        prev = trimmed
        w = (~trimmed).astype(np.float64)
    return w, z, sig, sg, beta, live, rounds


def robust_outliers(x, y, d, window, spacing, threshold_sigma, floor, progress=None) -> RobustResult:
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    n = len(d)
    # the points in the order of their fine cells: the per-cell sums and the gathers run through
    # memory in order (2–3× faster at 10⁶ points); the results are put back in the input's order
    order = np.argsort(_cell_grid(x, y, 2.0 * float(window) / _Windows.CELLS)[0], kind="stable")
    x, y, d = x[order], y[order], d[order]
    # a coarse pass first (window COARSE · a): a dig or scratch that fills a good part of the 2a window
    # is a small part of the larger one, so its points are trimmed before the fine planes see them
    coarse = _Windows(x, y, COARSE * window)
    w, zc, sigc, _, betac, livec, _ = _trim_rounds(coarse, d, np.ones(n), COARSE_ROUNDS, progress, 0)
    win = _Windows(x, y, window)
    w, z, sig, sg, beta, live, rounds = _trim_rounds(win, d, w, MAX_ROUNDS, progress, COARSE_ROUNDS)
    # where the 2a window is too sparse to judge (the end of a star's line), the coarse window judges
    sparse = ~np.isfinite(z)
    z, sig = np.where(sparse, zc, z), np.where(sparse, sigc, sig)
    thr = np.maximum(threshold_sigma * sig, floor)
    fin = np.isfinite(z)
    flagged = fin & (np.abs(np.where(fin, z, 0.0)) > thr)
    zz = np.where(fin, z, 0.0)
    # candidates for growing a dig: beyond TRIM σ (and the floor)
    growable = fin & ~flagged & (np.abs(zz) > np.maximum(TRIM * sig, floor))
    # form, not outlier: where the windows holding a candidate disagree by its size, or one of them
    # predicts it within TRIM σ (module doc, "Form, not outlier")
    for wn, b, lv, sel in ((win, beta, live, ~sparse), (coarse, betac, livec, sparse)):
        for mask in (flagged, growable):
            cand = np.flatnonzero(mask & sel)
            spread = _disagreement(wn, b, lv, cand)
            mask[cand[np.abs(z[cand]) <= AGREE * spread]] = False
            cand = np.flatnonzero(mask & sel)
            best = _best_window_z(wn, b, lv, cand, d)
            mask[cand[best <= np.maximum(TRIM * sig[cand], floor)]] = False
    # a dig whose depth falls off smoothly (a round pit) is followed in part by the fine window's
    # quadratic: its flanks slope into it and bend the fit down, so that deep points 10 σ below the
    # surface read 3–5 σ against it (an independent review: a Gaussian pit's points recalled 0.66
    # against 1.00 for a flat-bottomed one). The coarse window (COARSE · a) follows a tenth of it at
    # most: its decision, against its own σ (which holds the form it cannot follow) and through the
    # same form tests in its windows, names candidates
    fin_c = np.isfinite(zc)
    zcz = np.where(fin_c, zc, 0.0)
    cflag = fin_c & ~sparse & ~flagged & (np.abs(zcz) > np.maximum(threshold_sigma * sigc, floor))
    # … and only where the fine fit sees the point beyond COARSE_JOIN σ too: the round pit's deep points
    # read 3–5 σ there, a bump of the window's size that the fine quadratic follows 0.5–2.7 σ — a true
    # spike on such a bump grew into 4–17 of its points through the coarse candidates (a review)
    cflag &= np.abs(zz) > COARSE_JOIN * sig
    cand = np.flatnonzero(cflag)
    spread = _disagreement(coarse, betac, livec, cand)
    cflag[cand[np.abs(zc[cand]) <= AGREE * spread]] = False
    cand = np.flatnonzero(cflag)
    best = _best_window_z(coarse, betac, livec, cand, d)
    cflag[cand[best <= np.maximum(TRIM * sigc[cand], floor)]] = False
    # … as part of a dig the fine pass found: the coarse candidates join by growth from its flagged
    # points, never alone (form the coarse quadratic cannot follow — a 50 mm part's order-6 residual
    # under a 9 mm window — lost 4 points of noise-free data when they counted alone)
    grown = kept = 0
    if flagged.any():
        grown = _grow(x, y, np.where(cflag, zc, z), growable | cflag, flagged)
        # a group whose deviation ramps into its surroundings is form (a cone tip, a crease, a roll-off),
        # not a spike or a dig (review 7; _keep_tapered) — on noise-free data only
        kept = _keep_tapered(x, y, np.where(cflag, zc, z), sig, thr, floor, flagged)
    back = np.empty_like(order)
    back[order] = np.arange(n)
    return RobustResult(flagged[back], z[back], sig[back], sg, thr[back], rounds, grown, int((~fin).sum()),
                        kept)


def local_spacing(x, y, k: int = 12, sample: int = 20_000, tree=None) -> float:
    """The points' typical spacing (mm) from their local density: the median distance r_k to the k-th
    nearest neighbour, as √(π r_k² / k) — the side of the square each point stands for. A square raster
    of pitch h gives 1.02 h (k = 12: 4 neighbours at h, 4 at √2 h, 4 at 2 h), random points 1/√density.
    The bounding box's √(area / n) read an annulus's spacing 2.6× too large and a disc's with one stray
    point 5× (a review: the window warning named 1.2 spacings where the window held 13).

    ``tree``: a cKDTree of all the points, when the caller has one; else the density is taken on every
    m-th point (m = n / 4·sample) and scaled by √m — a tree of 10⁶ points took 0.4–0.65 s of a 2 s step."""
    from scipy.spatial import cKDTree

    pts = np.column_stack([x, y])
    n = len(pts)
    if n <= 4 * k:
        return float(np.sqrt(max(np.ptp(x) * np.ptp(y), 1e-300) / max(n, 1)))
    if tree is None:
        m = max(1, n // (4 * sample))
        sub = pts[::m]
        r = cKDTree(sub).query(sub[:: max(1, len(sub) // sample)], k=k + 1)[0][:, k]
        return float(np.median(r) * np.sqrt(np.pi / k) / np.sqrt(m))
    r = tree.query(pts[:: max(1, n // sample)], k=k + 1)[0][:, k]
    return float(np.median(r) * np.sqrt(np.pi / k))


def _keep_tapered(x, y, z, sig, thr, floor, flagged) -> int:
    """Unflag (in place) the connected flagged groups whose deviation runs on continuously into their
    surroundings: the median step of |z| across the group's edge (a flagged point to an unflagged
    neighbour within 1.5 point spacings, ``local_spacing``) is at most the larger of STEP_NOISE · σ, the floor and
    STEP_RAMP times the median step between the group's own neighbouring points, and the median |z| of
    its edge points is at most TAPER times its peak |z|.

    Why: the trim sets every point of a kink narrower than the window aside, so the form error of a
    cone tip stands out like a bump (review 7: a 0.4 µm diamond-turning centre cone, 0.75 mm radius,
    on a 0.18 mm raster, noise-free, lost 49 points; on a 10 mm part, where an unfollowed ripple sets
    σ = 20 nm, 9–12). Its deviation ramps down to the surface: the step across its edge is the ramp's
    step inside it. A spike has no ramp (its edge step is its height), and a dig or dust particle is cut
    out of the surface — the issue's profiles, flat or 0.5 + 0.5·exp(−2 r²/r_max²), drop by at least
    0.57 of their depth at the edge.

    Only on noise-free data (σ below 1e-4 of the floor, as the floor warning's test): with 1 nm noise the
    floor sets the threshold too, and smooth pits and bumps of any depth taper — a review of this rule's
    first version saw 30-point Gaussian pits and bumps 50–1000 nm deep found 0 of 480 (362–480 before).
    Returns how many points it kept."""
    from scipy.spatial import cKDTree

    zz = np.where(np.isfinite(z), z, 0.0)
    fi = np.flatnonzero(flagged)
    if fi.size == 0 or not float(np.median(sig[fi])) < NOISE_FREE * floor:
        return 0
    pts = np.column_stack([x, y])
    tree = cKDTree(pts)
    reach = 1.5 * local_spacing(x, y, tree=tree)
    # neighbours of the flagged points (pairs), and the groups they form
    src, dst = [], []
    for a, hs in zip(fi, tree.query_ball_point(pts[fi], reach)):
        hs = np.asarray(hs, dtype=np.int64)
        hs = hs[hs != a]
        src.append(np.full(len(hs), a))
        dst.append(hs)
    src, dst = np.concatenate(src), np.concatenate(dst)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    inner = flagged[dst]
    pos = np.full(len(x), -1)
    pos[fi] = np.arange(fi.size)
    m = fi.size
    g = coo_matrix((np.ones(inner.sum()), (pos[src[inner]], pos[dst[inner]])), shape=(m, m))
    _, label = connected_components(g, directed=False)
    step = np.abs(zz[src] - zz[dst])
    lab = label[pos[src]]
    order = np.argsort(lab, kind="stable")
    kept = 0
    for c in np.unique(lab):
        sel = order[np.searchsorted(lab[order], c):np.searchsorted(lab[order], c, side="right")]
        edge = sel[~inner[sel]]
        if edge.size == 0:
            continue
        ramp = np.median(step[sel[inner[sel]]]) if inner[sel].any() else 0.0
        allow = max(STEP_NOISE * float(np.median(sig[src[edge]])), floor, STEP_RAMP * ramp)
        grp = fi[label == c]
        peak = float(np.abs(zz[grp]).max())
        t = float(np.median(thr[grp]))
        # only where the floor sets the threshold (noise-free): with noise a round pit tapers too, and
        # the fine fit bends into it (an earlier review's Gaussian pits, 1 µm = 50 σ deep, read 1.6–3.5 ×
        # the threshold at their peak, as the 10 mm hex part's cone, whose σ an unfollowed ripple sets,
        # does: 3.3 ×; clearing both lost 97 % of the pits' deep points)
        if t > floor * (1 + 1e-9):
            continue
        if np.median(step[edge]) <= allow and np.median(np.abs(zz[src[edge]])) <= TAPER * peak:
            flagged[grp] = False
            kept += grp.size
    return kept


def _grow(x, y, z, cand, flagged) -> int:
    """Add to `flagged` (in place) the `cand` points next to a flagged point whose z has the same sign,
    until none joins; returns how many joined."""
    from scipy.spatial import cKDTree

    zz = np.where(np.isfinite(z), z, 0.0)
    if not cand.any():
        return 0
    ci = np.flatnonzero(cand)
    # mean point spacing from the density: the box of a cloud's extent over its points
    area = max(np.ptp(x) * np.ptp(y), 1e-300)
    reach = 1.5 * np.sqrt(area / len(x))
    tree = cKDTree(np.column_stack([x[ci], y[ci]]))
    grown = 0
    front = np.flatnonzero(flagged)
    while front.size:
        hits = tree.query_ball_point(np.column_stack([x[front], y[front]]), reach)
        new = []
        for f, hs in zip(front, hits):
            for j in hs:
                p = ci[j]
                if not flagged[p] and np.sign(zz[p]) == np.sign(zz[f]):
                    flagged[p] = True
                    new.append(p)
        grown += len(new)
        front = np.asarray(new, dtype=np.int64)
    return grown


def claimed_rate(threshold_sigma: float) -> float:
    """Two-sided normal tail beyond threshold_sigma: the false-positive rate on Gaussian noise."""
    from math import erfc, sqrt

    return erfc(threshold_sigma / sqrt(2.0))
