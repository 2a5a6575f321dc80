"""Smoothing bicubic B-spline surface of scattered points (penalised least squares, "P-spline").

    z(x, y) = Σ_ij c_ij B_i(x) B_j(y)          uniform cubic B-splines, knot spacing h (mm)
    min_c  Σ_p w_p (z_p − z(x_p, y_p))²  +  λ (‖D₂ˣ c‖² + ‖D₂ʸ c‖²)

D₂ are second differences of the coefficients along x and along y (Eilers & Marx, "Flexible
smoothing with B-splines and penalties", Statist. Sci. 11, 1996; the 2-D form in Eilers, Currie &
Durbán, Comput. Stat. Data Anal. 50, 2006). The knot spacing sets the finest detail the map can
hold; the penalty removes the freedom the data do not pin down (cells with few or no points: holes,
the gaps of a star pattern, the rim), so the solve is never singular and the map never rings there.
λ = smoothing · trace(BᵀWB) / trace(P): ``smoothing`` is dimensionless and does not depend on the
number of points.

Why not scipy's FITPACK (``SmoothBivariateSpline``/``bisplrep``): its knot placement by rank-revealing
QR costs 13 s for 50,000 points here and grows with the number of knots; this normal-equation form
is sparse (16 basis products per point, a banded system of (nx+3)(ny+3) unknowns) and does 10⁶
points in about a second (benchmarks/bench_maps.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

#: dimensionless default of ``smoothing`` (see module doc); small: the knot spacing does the smoothing
DEFAULT_SMOOTHING = 1e-3
#: the default knot spacing keeps at most this many intervals across (a 153² system solves in < 1 s)
MAX_INTERVALS = 150


def _basis(u: np.ndarray, deriv: int = 0) -> np.ndarray:
    """(N, 4) values of the four uniform cubic B-spline pieces at local coordinate u ∈ [0, 1]
    (d/du when deriv = 1)."""
    u = np.asarray(u, dtype=np.float64)
    out = np.empty((len(u), 4))
    if deriv == 0:
        v = 1.0 - u
        u2 = u * u
        u3 = u2 * u
        out[:, 0] = v * v * v / 6.0
        out[:, 1] = (3 * u3 - 6 * u2 + 4) / 6.0
        out[:, 2] = (-3 * u3 + 3 * u2 + 3 * u + 1) / 6.0
        out[:, 3] = u3 / 6.0
        return out
    if deriv == 1:
        u2 = u * u
        out[:, 0] = -0.5 * (1 - u) ** 2
        out[:, 1] = 1.5 * u2 - 2 * u
        out[:, 2] = -1.5 * u2 + u + 0.5
        out[:, 3] = 0.5 * u2
        return out
    raise ValueError("deriv must be 0 or 1")


@dataclass(frozen=True)
class TensorBSpline:
    """z(x, y) on [x0, x0 + nx·h] × [y0, y0 + ny·h]; coef shape (nx + 3, ny + 3). Lengths in mm."""

    x0: float
    y0: float
    h: float
    coef: np.ndarray
    #: automatic knots: the bounds they were chosen from (knot_spacing_terms), else None
    knot_terms: dict | None = field(default=None, compare=False, repr=False)

    @property
    def intervals(self) -> tuple[int, int]:
        return self.coef.shape[0] - 3, self.coef.shape[1] - 3

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        nx, ny = self.intervals
        return self.x0, self.x0 + nx * self.h, self.y0, self.y0 + ny * self.h

    def _local(self, v, origin, n):
        s = (np.asarray(v, dtype=np.float64) - origin) / self.h
        k = np.clip(np.floor(s), 0, n - 1).astype(np.intp)
        return k, s - k  # outside the domain u leaves [0, 1]: polynomial continuation of the rim

    def __call__(self, x, y, dx: int = 0, dy: int = 0) -> np.ndarray:
        """Values (or ∂/∂x with dx=1, ∂/∂y with dy=1) at points, in chunks of CHUNK points: the
        result is the only full-length array (issue 26)."""
        nx, ny = self.intervals
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        flat = self.coef.ravel()
        my = self.coef.shape[1]
        out = np.empty(len(x))
        for s in range(0, len(x), CHUNK):
            e = s + CHUNK
            kx, ux = self._local(x[s:e], self.x0, nx)
            ky, uy = self._local(y[s:e], self.y0, ny)
            bx = _basis(ux, dx)
            by = _basis(uy, dy)
            if dx:
                bx /= self.h**dx
            if dy:
                by /= self.h**dy
            acc_x = np.zeros(len(ky))
            for a in range(4):
                base = (kx + a) * my + ky
                acc = flat[base] * by[:, 0]
                for b in range(1, 4):
                    acc += flat[base + b] * by[:, b]
                acc *= bx[:, a]
                acc_x += acc
            out[s:e] = acc_x
        return out

    def gradient(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(∂z/∂x, ∂z/∂y) at points: the same numbers as ``self(x, y, dx=1)`` and
        ``self(x, y, dy=1)`` (the same operations in the same order), the 16 coefficients of each
        point gathered once for both (the gathers are most of the cost: 12.6 M points 3.0 → ~1.8 s)."""
        nx, ny = self.intervals
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        flat = self.coef.ravel()
        my = self.coef.shape[1]
        gx, gy = np.empty(len(x)), np.empty(len(x))
        for s in range(0, len(x), CHUNK):
            e = s + CHUNK
            kx, ux = self._local(x[s:e], self.x0, nx)
            ky, uy = self._local(y[s:e], self.y0, ny)
            bx, dbx = _basis(ux, 0), _basis(ux, 1)
            by, dby = _basis(uy, 0), _basis(uy, 1)
            dbx /= self.h
            dby /= self.h
            acc_x, acc_y = np.zeros(len(ky)), np.zeros(len(ky))
            for a in range(4):
                base = (kx + a) * my + ky
                c = flat[base]
                sx = c * by[:, 0]
                sy = c * dby[:, 0]
                for b in range(1, 4):
                    c = flat[base + b]
                    sx += c * by[:, b]
                    sy += c * dby[:, b]
                sx *= dbx[:, a]
                sy *= bx[:, a]
                acc_x += sx
                acc_y += sy
            gx[s:e], gy[s:e] = acc_x, acc_y
        return gx, gy

    def design_1d(self, v, origin, n, deriv=0) -> sp.csr_matrix:
        k, u = self._local(v, origin, n)
        m = len(k)
        vals = _basis(u, deriv) / self.h**deriv
        cols = k[:, None] + np.arange(4)
        return sp.csr_matrix((vals.ravel(), cols.ravel(), np.arange(0, 4 * m + 1, 4)), shape=(m, n + 3))

    def grid(self, xs, ys, dx: int = 0, dy: int = 0) -> np.ndarray:
        """Values on the grid xs × ys, shape (len(ys), len(xs)): Z = By · Cᵀ · Bxᵀ."""
        nx, ny = self.intervals
        Bx = self.design_1d(xs, self.x0, nx, dx)
        By = self.design_1d(ys, self.y0, ny, dy)
        return np.asarray((By @ (Bx @ self.coef).T))


def default_knot_spacing(x, y, extent: float | None = None) -> float:
    """The largest of ``knot_spacing_terms`` (mm)."""
    return max(knot_spacing_terms(x, y, extent).values())


def knot_spacing_terms(x, y, extent: float | None = None) -> dict[str, float]:
    """The three lower bounds of the automatic knot spacing (mm), by name — ``points`` (2 × the mean
    point spacing), ``gaps`` (2 × the widest gaps of the pattern) and ``size`` (the system's bound);
    the spacing is the largest. The largest of
       2 × the mean point spacing sqrt(area/N)  (each cell then holds ~4 points),
       2 × the 95th percentile of the distance from places inside the points' hull to the nearest
           point (the half-width of the widest gaps: between the spokes of a star pattern, between
           the turns of a coarse spiral), so the cells over the measured region hold points,
       extent / MAX_INTERVALS                   (bounds the system's size)."""
    from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

    npts = len(x)
    step = max(npts // 200_000, 1)  # the hull of every k-th point: same area within a fraction
    sub = np.column_stack([x[::step], y[::step]])  # never all N points as one (N, 2) copy
    try:
        hull = ConvexHull(sub) if len(sub) >= 3 else None
    except QhullError:
        hull = None
    span = extent if extent is not None else float(max(np.ptp(x), np.ptp(y)))
    if hull is None or hull.volume <= 0 or span <= 0:
        raise ValueError("the points do not span an area (all on a line or one point)")
    mean_spacing = np.sqrt(hull.volume / npts)
    lo, hi = sub.min(axis=0), sub.max(axis=0)
    g = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], PLACES), np.linspace(lo[1], hi[1], PLACES)),
                 -1).reshape(-1, 2)
    inside = Delaunay(sub[hull.vertices]).find_simplex(g) >= 0
    gap = 0.0
    if inside.any():
        d = np.full(len(g), np.nan)
        d[inside] = cKDTree(sub).query(g[inside])[0]
        sampling = inside & ~_holes(d.reshape(PLACES, PLACES), inside.reshape(PLACES, PLACES)).ravel()
        gap = float(np.percentile(d[sampling], 95))
    if step > 1:  # the subsample's gaps are wider by about √step where points are dense
        gap /= np.sqrt(step)
    return {"points": float(2.0 * mean_spacing), "gaps": float(2.0 * gap), "size": float(span / MAX_INTERVALS)}


#: places across the points' box where default_knot_spacing measures the distance to the nearest point
PLACES = 120
#: a place farther from every point than this many times the median place's distance lies in a hole
HOLE_SEED = 5.0
#: …and so do the places around it, connected to it, farther than this many times the median
HOLE_EDGE = 2.0


def _holes(d, inside) -> np.ndarray:
    """Places (True) of the (PLACES × PLACES) grid that lie in a hole of the measured region — a
    central bore, a dropout strip, a missing sector — rather than in a gap of the sampling pattern.

    A scan pattern's gaps recur all over the region and are narrow: between raster rows or spiral
    turns the distance to the nearest point is uniform on [0, w/2] (at most 2× the median place's
    distance), between the spokes of a star it grows with the radius (at most 3.4× the median over
    the disc); random points leave a place 5× the median distance away with probability 2⁻²⁵. A hole
    holds places much farther out: those beyond HOLE_SEED × median seed it, and the connected places
    beyond HOLE_EDGE × median are its extent (hysteresis, 8-connected). Counted as a sampling gap, a
    30 mm bore in a 100 mm annulus measured on a 1 mm grid made the knots 8.3 mm instead of 2 mm and
    the map and slope RMS 5–6× too small (issue 16's review)."""
    from scipy.ndimage import label

    med = float(np.median(d[inside]))
    if not med > 0:
        return np.zeros_like(inside)
    with np.errstate(invalid="ignore"):
        seed = inside & (d > HOLE_SEED * med)
        if not seed.any():
            return np.zeros_like(inside)
        wide = inside & (d > HOLE_EDGE * med)
    comp, _ = label(wide, structure=np.ones((3, 3), bool))
    hole_ids = np.unique(comp[seed])
    return np.isin(comp, hole_ids[hole_ids > 0])


def _intervals(xmin, xmax, ymin, ymax, h) -> tuple[int, int]:
    return (max(int(np.ceil((xmax - xmin) / h - 1e-9)), 1),
            max(int(np.ceil((ymax - ymin) / h - 1e-9)), 1))


def _second_difference_gram(n: int) -> sp.csr_matrix:
    d = sp.diags([np.ones(n - 2), -2 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2], shape=(n - 2, n))
    return (d.T @ d).tocsr()


#: points per chunk of the normal equations and of evaluation: the chunk's (n, 116) products stay
#: in the cache, and memory is a few MB whatever the number of points
CHUNK = 1 << 15

#: the 10 products of two of the four 1-D basis values (a ≤ c), and where each (a, c) lands
_PAIRS = [(a, c) for a in range(4) for c in range(a, 4)]
#: pair (a, c) in either order → its column among the 10
_PAIR_INDEX = {**{(a, c): i for i, (a, c) in enumerate(_PAIRS)}, **{(c, a): i for i, (a, c) in enumerate(_PAIRS)}}


def _basis_rows(u: np.ndarray) -> np.ndarray:
    """(4, n) values of the four cubic pieces at u ∈ [0, 1] (``_basis`` transposed: contiguous rows)."""
    out = np.empty((4, len(u)))
    v = 1.0 - u
    u2 = u * u
    u3 = u2 * u
    np.multiply(v * v, v * (1.0 / 6.0), out=out[0])
    np.multiply(u3, 0.5, out=out[1])
    out[1] -= u2
    out[1] += 2.0 / 3.0
    np.multiply(u3, -0.5, out=out[2])
    out[2] += 0.5 * (u2 + u)
    out[2] += 1.0 / 6.0
    np.multiply(u3, 1.0 / 6.0, out=out[3])
    return out


def _cell_moments(x, y, z, w, x0, y0, h, nx, ny, threads: int = 1):
    """Per knot cell (index ky·nx + kx): the moments Σ bx_a bx_c · by_b by_d (the 10 × 10 distinct
    pairs a ≤ c, b ≤ d, column 10·pair(a, c) + pair(b, d)) and Σ bx_a by_b z (column 100 + 4a + b),
    over the points in that cell — shape (nx·ny, 116).

    One pass over the points in chunks of CHUNK (``_chunk_moments``). Memory: a few chunk-sized
    columns and the (cells, 116) moments, whatever N (the earlier form made 116 passes of
    np.bincount over full-length products: 3× the time, ~200 bytes a point).

    ``threads`` > 1: chunks are computed by that many threads (numpy and scipy.sparse release the
    GIL in their loops) and added to the moments by this thread in chunk order, so the sums are
    bit for bit those of one thread (tests/test_large_map.py) and a batch's files do not depend on
    its worker count. At 10⁶ points on 2 threads 0.48 → 0.28 s. Chunks in flight are bounded so
    their partial moments stay under ~64 MB (a chunk of scattered points spans every cell)."""
    ncell = nx * ny
    mom = np.zeros((ncell, 116))
    starts = range(0, len(z), CHUNK)

    def one(s):
        return _chunk_moments(x, y, z, w, s, x0, y0, h, nx, ny)

    def add(part):
        c0, p = part
        mom[c0:c0 + len(p)] += p

    threads = max(1, min(int(threads), len(starts)))
    if threads == 1:
        for s in starts:
            add(one(s))
        return mom
    from concurrent.futures import ThreadPoolExecutor

    wave = max(1, min(2 * threads, int(64e6 // (ncell * 116 * 8))))
    with ThreadPoolExecutor(threads) as pool:
        for k in range(0, len(starts), wave):
            for part in pool.map(one, starts[k:k + wave]):  # in chunk order
                add(part)
    return mom


def _chunk_moments(x, y, z, w, s, x0, y0, h, nx, ny):
    """(first cell c0, moments (ncl, 116) of cells c0 … c0 + ncl − 1) of the points s … s + CHUNK.

    A sparse matrix holds each point's 10 x-products in its cell's 10 rows; its product with the
    points' 10 y-products sums the 100 moments per cell (BLAS-free but one pass, no (n, 100) outer
    product formed). Only the chunk's range of cells is touched: on a map read row by row (y-major)
    a chunk covers one band of cells."""
    e = s + CHUNK
    sx = (np.asarray(x[s:e], dtype=np.float64) - x0) / h
    kx = np.clip(np.floor(sx), 0, nx - 1).astype(np.intp)
    sx -= kx
    sy = (np.asarray(y[s:e], dtype=np.float64) - y0) / h
    ky = np.clip(np.floor(sy), 0, ny - 1).astype(np.intp)
    sy -= ky
    bx, by = _basis_rows(sx), _basis_rows(sy)
    zc = np.asarray(z[s:e], dtype=np.float64)
    if w is not None:
        # rows of B and z scaled by √w: BᵀWB and BᵀWz (the earlier form scaled bx and by
        # both, giving w² and w^1.5; no caller passed weights)
        sw = np.sqrt(np.asarray(w[s:e], dtype=np.float64))
        bx *= sw
        zc = zc * sw
    n = len(zc)
    cell = ky * nx + kx
    c0 = int(cell.min())
    ncl = int(cell.max()) - c0 + 1
    cell -= c0
    xx = np.empty((n, 10))
    yy = np.empty((n, 14))
    for i, (a, c) in enumerate(_PAIRS):
        np.multiply(bx[a], bx[c], out=xx[:, i])
        np.multiply(by[a], by[c], out=yy[:, i])
    for b in range(4):
        np.multiply(by[b], zc, out=yy[:, 10 + b])
    part = np.empty((ncl, 116))
    rows = cell[:, None] * 10 + np.arange(10)
    X = sp.csc_matrix((xx.ravel(), rows.ravel(), np.arange(0, 10 * n + 1, 10)), shape=(10 * ncl, n))
    part[:, :100] = (X @ yy[:, :10]).reshape(ncl, 100)  # row 10·cell + pair(a, c), column pair(b, d)
    rows = cell[:, None] * 4 + np.arange(4)
    B = sp.csc_matrix((bx.T.ravel(), rows.ravel(), np.arange(0, 4 * n + 1, 4)), shape=(4 * ncl, n))
    part[:, 100:] = (B @ yy[:, 10:]).reshape(ncl, 16)
    return c0, part


def _banded_normal_equations(mom, nx, ny):
    """BᵀB in LAPACK upper band storage and Bᵀz from the cells' moments (``_cell_moments``), for B
    the (N, (nx+3)(ny+3)) design matrix whose row p holds bx_a(p)·by_b(p) at column (kx+a)·my + (ky+b):
    each cell's 16 × 16 block (entry ((a,b), (c,d)) = Σ bx_a bx_c by_b by_d) is scattered into the
    band, never B itself (16 N entries) nor the sparse product BᵀB (256 N products)."""
    mx, my = nx + 3, ny + 3
    N = mx * my
    bw = 3 * my + 3
    ncell = nx * ny
    cky, ckx = np.divmod(np.arange(ncell), nx)  # cell index ky·nx + kx (_cell_moments)
    base = ckx * my + cky  # coefficient index of (a, b) = (0, 0) in each cell
    off = (np.arange(4)[:, None] * my + np.arange(4)[None, :]).ravel()  # (16,) offsets of (a, b)
    rows = base[None, :] + off[:, None]  # (16, ncell)
    rhs = np.bincount(rows.ravel(), weights=mom[:, 100:].T.ravel(), minlength=N)
    flat = []
    data = []
    for i in range(16):
        a, b = divmod(i, 4)
        for j in range(i, 16):  # upper triangle (col ≥ row: off[j] ≥ off[i])
            c, d = divmod(j, 4)
            row = base + off[i]
            col = base + off[j]
            flat.append((bw + row - col) * N + col)
            data.append(mom[:, 10 * _PAIR_INDEX[a, c] + _PAIR_INDEX[b, d]])
    ab = np.bincount(np.concatenate(flat), weights=np.concatenate(data),
                     minlength=(bw + 1) * N).reshape(bw + 1, N)
    return ab, rhs, bw


def fit_bspline(x, y, z, *, knot_spacing: float | None = None, smoothing: float = DEFAULT_SMOOTHING,
                weights=None, bounds: tuple[float, float, float, float] | None = None,
                progress=None) -> TensorBSpline:
    """Fit the smoothing spline (module doc). ``bounds`` (xmin, xmax, ymin, ymax, mm) defaults to the
    points' box; the spline covers it with whole intervals. Raises ValueError with the reason when the
    points cannot carry it."""

    x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
    good = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
    w = None if weights is None else np.asarray(weights, dtype=np.float64)
    if not good.all():  # copies only when some point must go
        x, y, z = x[good], y[good], z[good]
        w = None if w is None else w[good]
    del good
    if len(z) < 16:
        raise ValueError(f"{len(z)} points cannot carry a bicubic spline (16 coefficients at least)")
    if bounds is None:
        bounds = (x.min(), x.max(), y.min(), y.max())
    xmin, xmax, ymin, ymax = (float(b) for b in bounds)
    automatic = knot_spacing is None
    terms = None
    if automatic:
        terms = knot_spacing_terms(x, y, max(xmax - xmin, ymax - ymin))
        knot_spacing = max(terms.values())
    h = float(knot_spacing)
    if not h > 0:
        raise ValueError("knot spacing must be > 0")
    nx, ny = _intervals(xmin, xmax, ymin, ymax, h)
    while automatic and (nx + 3) * (ny + 3) > len(z):
        # the automatic spacing must always be feasible (a 4 × 4 map gives a map): coarsen until
        # the coefficients are no more than the points; the penalty settles what few points leave
        h = max(xmax - xmin, ymax - ymin) / max(max(nx, ny) - 1, 1) * (1 + 1e-9) \
            if max(nx, ny) > 1 else h * 2.0
        nx, ny = _intervals(xmin, xmax, ymin, ymax, h)
    if (nx + 3) * (ny + 3) > len(z):
        span = max(xmax - xmin, ymax - ymin)
        need = span / max(np.sqrt(len(z)) - 3.0, 1.0)
        raise ValueError(f"{len(z)} points are too few for knots every {h:g} mm "
                         f"({(nx + 3) * (ny + 3)} coefficients); use knot_spacing ≥ {need:.3g} mm")
    if (nx + 3) * (ny + 3) > 1_000_000:
        raise ValueError(f"knot spacing {h:g} mm gives {(nx + 3) * (ny + 3)} coefficients; "
                         "use a larger spacing")
    # centre the whole intervals on the requested box
    x0 = 0.5 * (xmin + xmax) - 0.5 * nx * h
    y0 = 0.5 * (ymin + ymax) - 0.5 * ny * h
    mx, my = nx + 3, ny + 3
    if progress is not None:
        progress(0.2, "normal equations")
    from ..parallel import thread_count

    mom = _cell_moments(x, y, z, w, x0, y0, h, nx, ny, thread_count())
    ab, rhs, bw = _banded_normal_equations(mom, nx, ny)
    # penalty λ P, P = D₂ˣᵀD₂ˣ ⊗ I + I ⊗ D₂ʸᵀD₂ʸ (coefficient k = ix·my + iy), into the same band
    P = (sp.kron(_second_difference_gram(mx), sp.identity(my))
         + sp.kron(sp.identity(mx), _second_difference_gram(my))).tocoo()
    diag_A = ab[bw]
    lam = smoothing * diag_A.sum() / max(P.diagonal().sum(), 1e-300)
    up = P.col >= P.row
    np.add.at(ab, (bw + P.row[up] - P.col[up], P.col[up]), lam * P.data[up])
    # a whisper of ridge keeps the null space of P (planes, twist) determined when the data leave
    # one of them free (e.g. all points on one line): 1e-12 of the data scale changes nothing else
    ab[bw] += 1e-12 * diag_A.mean()
    if progress is not None:
        progress(0.6, "solving")
    from scipy.linalg import LinAlgError, solveh_banded

    try:
        # banded Cholesky (LAPACK pbtrf): the system is SPD with bandwidth 3·my + 3
        c = solveh_banded(ab, rhs, check_finite=False)
    except LinAlgError:
        raise ValueError("the spline system is singular: too few points for the knots") from None
    if not np.all(np.isfinite(c)):
        raise ValueError("the spline system is singular: too few points for the knots")
    return TensorBSpline(x0, y0, h, c.reshape(mx, my), terms)
