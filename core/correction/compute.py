"""The correction the next run takes, from a form-error map (docs/conventions.md, Correction).

    E      form error on the map grid, residual = z − sag (part frame, mm), piston and tilt removed
           over the clear aperture (set-up, not form); scattered points: only at nodes inside the
           points' hull (as bspline_map's map), none beyond the outermost point
    E_ext  E continued past the data's edge and the clear aperture: each node without a measured
           value takes the value of the nearest measured node (constant along the rim's normal),
           so the filter and the tool path have data to the run-out
    F      E_ext low-passed by the areal Gaussian filter of ISO 16610-61 (the 1-D weighting function
           of ISO 16610-21 in x and in y: σ = α λc / √(2π), α = √(ln 2 / π); 50 % transmission at the
           cutoff wavelength λc)
    dz     = −gain · F, its plane over the aperture removed: the height to ADD to the programmed
           surface (cutting); removal = gain · F − min + bias ≥ 0: material to remove (polishing)
    E'     = E + dz, plane removed: the error predicted after the correction — what the filter
           (detail finer than λc), the edge (the continuation inside one cutoff of the rim) and a gain
           below 1 leave behind.

The radial program is the azimuthal mean of dz about the surface's axis, sampled on rings every map
spacing (bilinear on the filtered grid, ≥ 8 and ~1.5 samples per spacing of circumference, so no
lobe below the sampling leaks into it); for a part off the axis (an off-axis zone of the parent,
turned about the parent's axis) each ring's mean is over its arc on the part, and rings with no arc
on it are left out. ``refit_surface`` turns nominal + that mean into the recipe's own surface syntax
(even asphere or Forbes Q-con).

An annular clear aperture (an `aperture` annulus: ``inner`` > 0) is the ring inner ≤ r ≤ radius: the
coverage, the plane and the statistics are over it; its hole is continued like the run-out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: ISO 16610-21 Gaussian constant α = √(ln 2 / π)
ALPHA = float(np.sqrt(np.log(2.0) / np.pi))
#: the share of clear-aperture nodes that must carry measured data
MIN_COVERAGE = 0.99


class CorrectionInputError(ValueError):
    """Bad input for a correction (the step turns it into a one-line StepError)."""


def gaussian_sigma(cutoff_mm: float) -> float:
    """σ (mm) of the ISO 16610-61 areal Gaussian filter with cutoff λc (mm)."""
    return ALPHA * cutoff_mm / np.sqrt(2.0 * np.pi)


def regular_grid(x, y, v, rtol: float = 1e-3):
    """(xs, ys, Z (ny, nx) NaN where absent, spacing) when the points lie on one square lattice with
    each node at most once (a map.csv read back, an instrument's map, a raster in the part frame);
    else None. A point may lie ``rtol`` of the pitch off its node: a raster measured on a machine's
    lattice and moved into the part frame by a tilt β of the part is off by z·β (2 mm × 10⁻³ rad =
    2 µm on a 0.5 mm pitch, 0.4 %) — its value taken at the node is off by the form's slope times
    that, far below the noise; 10⁻⁶ of the pitch sent such rasters through the B-spline."""
    x, y, v = (np.asarray(a, dtype=np.float64) for a in (x, y, v))
    if x.size < 16:
        return None
    out = []
    sub = np.random.default_rng(0).choice(x.size, 20_000, replace=False) if x.size > 20_000 else slice(None)
    for u in (x, y):
        # the lattice step from a subsample's distinct values (no hashing of a million floats),
        # then every point checked against it
        uu = np.unique(u[sub])
        if uu.size < 4:
            return None
        # values within 10⁻⁶ of the span are one node's: a raster moved by the pose fit (a rotation
        # of 10⁻⁶ rad) spreads each column over picometres, and the median step of the distinct
        # values was 10⁻¹¹ mm — the raster then went through the B-spline at twice its pitch and a
        # 1 mm ripple on a 0.5 mm raster was left as "unresolved" (a review)
        gap = np.flatnonzero(np.diff(uu) > 1e-6 * (uu[-1] - uu[0]))
        if gap.size < 3:
            return None
        centres = np.array([c.mean() for c in np.split(uu, gap + 1)])  # one a node
        h = float(np.median(np.diff(centres)))
        if not h > 0:
            return None
        u0 = float(np.median(u[u < u.min() + 0.5 * h]))  # the first node's centre
        i = np.rint((u - u0) / h)
        if np.max(np.abs(u - u0 - i * h)) > rtol * h:
            return None
        if i.max() > 20_000:
            return None
        out.append((u0, h, i.astype(np.intp)))
    (x0, hx, ix), (y0, hy, iy) = out
    if abs(hx - hy) > 1e-6 * hx:
        return None
    nx, ny = int(ix.max()) + 1, int(iy.max()) + 1
    if nx * ny > 4 * x.size:
        return None
    flat = iy * nx + ix
    if np.bincount(flat, minlength=nx * ny).max() > 1:
        return None
    Z = np.full(ny * nx, np.nan)
    Z[flat] = v
    return x0 + hx * np.arange(nx), y0 + hx * np.arange(ny), Z.reshape(ny, nx), float(hx)


@dataclass
class ErrorMap:
    """The form error E (mm) on the working grid xs × ys (mm): NaN where not measured (scattered
    points: outside the clear aperture, or beyond the points — grid_map's hull rule). ``covered``
    marks the nodes the measurement supports (cells of a knot: for the coverage check)."""

    xs: np.ndarray
    ys: np.ndarray
    E: np.ndarray
    covered: np.ndarray
    spacing: float
    source: str
    #: scattered input: the B-spline's knot spacing (mm) and the RMS (mm) of the points less the map
    #: at the points — noise and detail finer than the knots, which no correction of the map removes
    knot_spacing: float | None = None
    unresolved_rms: float | None = None


def working_axes(lo: float, hi: float, x0: float, h: float) -> np.ndarray:
    """Nodes x0 + i·h covering [lo, hi]."""
    i0 = int(np.floor((lo - x0) / h + 1e-9))
    i1 = int(np.ceil((hi - x0) / h - 1e-9))
    if i1 - i0 + 1 > MAX_GRID_NODES:  # refused before numpy is asked for the nodes
        raise CorrectionInputError(f"a working grid {hi - lo:.6g} mm wide at spacing {h:g} mm has more "
                                   f"than {MAX_GRID_NODES:,} nodes along one side — check cutoff_mm and "
                                   "extend_mm (they widen the grid beyond the aperture)")
    return x0 + h * np.arange(i0, i1 + 1, dtype=np.float64)


def error_map(x, y, v, *, center, radius: float, outer, spacing: float | None,
              knot_spacing: float | None = None, smoothing: float = 1e-3, reg=False) -> ErrorMap:
    """The error on a grid covering the disk of radius ``outer`` (mm, or a function of the spacing)
    about ``center``. Points on a regular lattice (and no other ``spacing`` asked) are taken node for
    node; scattered points are fitted by the smoothing bicubic B-spline of core.maps over the clear
    aperture. ``reg``: regular_grid's answer when already known."""
    from .. import maps

    cx, cy = center
    if reg is False:
        reg = regular_grid(x, y, v)
    if reg is not None and (spacing is None or abs(spacing - reg[3]) <= 1e-9 * reg[3]):
        gx, gy, Z, h = reg
        outer = outer(h) if callable(outer) else outer
        xs = working_axes(cx - outer, cx + outer, gx[0], h)
        ys = working_axes(cy - outer, cy + outer, gy[0], h)
        _check_grid_size(xs, ys, h)
        E = np.full((ys.size, xs.size), np.nan)
        ox = int(np.rint((gx[0] - xs[0]) / h))
        oy = int(np.rint((gy[0] - ys[0]) / h))
        # the overlap of the input lattice and the working grid
        sx0, sy0 = max(0, -ox), max(0, -oy)
        dx0, dy0 = max(0, ox), max(0, oy)
        nx = min(Z.shape[1] - sx0, xs.size - dx0)
        ny = min(Z.shape[0] - sy0, ys.size - dy0)
        if nx > 0 and ny > 0:
            E[dy0:dy0 + ny, dx0:dx0 + nx] = Z[sy0:sy0 + ny, sx0:sx0 + nx]
        return ErrorMap(xs, ys, E, np.isfinite(E), h, f"the input's {h:g} mm grid, node for node")
    x, y, v = (np.asarray(a, dtype=np.float64) for a in (x, y, v))
    inside = (x - cx) ** 2 + (y - cy) ** 2 <= radius * radius
    if inside.sum() < 16:
        raise CorrectionInputError(f"{int(inside.sum())} points lie inside the {2 * radius:g} mm clear "
                                   "aperture: too few for a map")
    try:
        spline = maps.fit_bspline(x[inside], y[inside], v[inside], knot_spacing=knot_spacing,
                                  smoothing=smoothing,
                                  bounds=(cx - radius, cx + radius, cy - radius, cy + radius))
    except ValueError as e:
        raise CorrectionInputError(str(e)) from None
    from ..maps.grid import nice_spacing

    h = spacing if spacing is not None else nice_spacing(spline.h / 2)
    outer = outer(h) if callable(outer) else outer
    xs = working_axes(cx - outer, cx + outer, 0.0, h)
    ys = working_axes(cy - outer, cy + outer, 0.0, h)
    _check_grid_size(xs, ys, h)
    from ..maps.grid import coverage_mask, hull_reach, inside_the_points

    px, py = x[inside], y[inside]
    # a node is supported when its knot cell (or a neighbour, closed) holds points: the spline is
    # determined there by data — a star pattern's rim between spokes is, a missing sector is not
    covered = coverage_mask(px, py, xs, ys, spline.h)
    E = spline.grid(xs, ys)
    disk = (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2 <= radius * radius
    # the measured nodes: supported, and inside the convex hull of the points around them — as
    # bspline_map's map (core.maps.grid.grid_map: the same reach, HULL_REACH × the sampling scale).
    # The cells alone took the spline's values up to a knot beyond the outermost point, where it is
    # extrapolated noise (30 nm noise on a 100 mm disk: those nodes erred by up to 0.9 µm and put it
    # into dz); the nodes between the data's edge and the aperture's rim are continued from the
    # nearest measured node like the run-out (compute_correction), the coverage check still counts
    # the cells (a rim within a knot of the data is covered)
    reach = hull_reach(spline, px, py)
    measured = inside_the_points(px, py, xs, ys, covered & disk, reach)
    E = np.where(measured, E, np.nan)
    miss = v[inside] - spline(px, py)
    return ErrorMap(xs, ys, E, covered & disk, float(h),
                    f"smoothing B-spline of the points (knots every {spline.h:.4g} mm)",
                    float(spline.h), float(np.sqrt(np.mean(miss * miss))))


#: nodes of a correction's working grid at most (as bspline_map's map: core/maps/grid.py)
MAX_GRID_NODES = 25_000_000


def _check_grid_size(xs, ys, h: float) -> None:
    """Refuse a working grid beyond MAX_GRID_NODES before it is allocated: a cutoff or extend_mm far
    beyond the part (cutoff_mm 1e6) asked numpy for 284 TiB on a gridded input ("internal error")."""
    if xs.size * ys.size > MAX_GRID_NODES:
        raise CorrectionInputError(
            f"a {xs.size:,} × {ys.size:,} working grid at spacing {h:g} mm is too large (at most "
            f"{MAX_GRID_NODES:,} nodes): the aperture plus extend_mm and the filter's margin span "
            f"{(xs[-1] - xs[0]):.6g} mm — check cutoff_mm and extend_mm, or give a larger spacing")


def plane_fit(X, Y, Z):
    """(piston, slope x, slope y) of the least-squares plane z = p + a x + b y."""
    A = np.column_stack([np.ones_like(X), X, Y])
    return np.linalg.lstsq(A, Z, rcond=None)[0]


@dataclass
class Correction:
    """Everything the outputs are written from (lengths mm; grids (ny, nx), NaN outside)."""

    xs: np.ndarray
    ys: np.ndarray
    spacing: float
    center: tuple[float, float]
    radius: float              # clear aperture radius
    outer: float               # radius of the written region (aperture + extension)
    cutoff: float
    gain: float
    E: np.ndarray              # the error, plane removed, over the aperture (NaN outside)
    dz: np.ndarray             # the correction over the written region
    predicted: np.ndarray      # the error predicted after it, over the aperture
    filtered: np.ndarray       # F over the whole working grid (no NaN)
    plane_error: tuple         # piston (mm), slopes of the error's plane
    plane_dz: tuple            # what was removed from −gain·F
    info: dict = field(default_factory=dict)
    inner: float = 0.0         # inner radius of an annular clear aperture (0: a disk)

    @property
    def aperture_mask(self):
        R2 = (self.xs[None, :] - self.center[0]) ** 2 + (self.ys[:, None] - self.center[1]) ** 2
        return (R2 <= self.radius ** 2) & (R2 >= self.inner ** 2)


def _aperture_words(radius: float, inner: float) -> str:
    return (f"{2 * radius:g} mm clear aperture" if inner <= 0 else
            f"{2 * radius:g} mm clear aperture (annulus, inner diameter {2 * inner:g} mm)")


def coverage_message(cov: float, R2, inside, covered, radius: float, inner: float, center) -> str:
    """The one line refusing a map that covers too little of the clear aperture, with advice that can
    help: a smaller diameter only when a smaller one is covered, a larger inner diameter only when a
    ring is (a review: "give a smaller diameter" for a zone whose data lay off the centre, or for an
    annulus counted as a full disk, where no smaller diameter could ever be covered)."""
    rr = np.sqrt(R2[inside])
    ok = covered[inside]
    order = np.argsort(rr, kind="stable")
    rs, oks = rr[order], ok[order]
    rmiss = float(rr[~ok].min())
    # the share rounded down: 98.97 % read "99.0 % … (≥ 99 % needed)" beside a refusal (a review)
    shown = math.floor(cov * 1000.0) / 10.0
    head = (f"the map covers {shown:.1f} % of the {_aperture_words(radius, inner)} about ({center[0]:g}, "
            f"{center[1]:g}) mm (≥ {MIN_COVERAGE * 100:.0f} % needed): no data from r = {rmiss:.4g} mm")

    def widest(radii, flags):
        """Index of the last node at which the nodes so far (all of each radius, ≥ 16) are covered."""
        c, n = np.cumsum(flags), np.arange(1, radii.size + 1)
        good = np.r_[radii[1:] != radii[:-1], True] & (n >= 16) & (c >= MIN_COVERAGE * n)
        return int(np.flatnonzero(good).max()) if good.any() else None

    helps = []
    i = widest(rs, oks)  # a disk (ring) from the centre (the inner rim) out
    if i is not None and np.floor(2.0 * rs[i] * 100.0) / 100.0 > 2.0 * inner:
        helps.append(f"give diameter ≤ {np.floor(2.0 * rs[i] * 100.0) / 100.0:g} mm (covered)")
    k = widest(rs[::-1], oks[::-1])  # a ring from the rim in
    if k is not None and np.ceil(2.0 * rs[::-1][k] * 100.0) / 100.0 < 2.0 * radius:
        helps.append(f"apply an `aperture` annulus with inner_diameter ≥ "
                     f"{np.ceil(2.0 * rs[::-1][k] * 100.0) / 100.0:g} mm before correction (the ring is covered)")
    if helps:
        return f"{head} — measure the whole aperture, or " + ", or ".join(helps)
    if rmiss <= inner + 0.05 * (radius - inner):  # nothing about this centre is covered, its middle neither
        return (f"{head} — the measured zone does not lie about this centre: give `centre: [x, y]` (the "
                "zone's centre)")
    return f"{head} — measure the whole aperture (no smaller disk or ring about this centre is covered)"


def compute_correction(em: ErrorMap, *, center, radius: float, extend: float, cutoff: float,
                       gain: float = 1.0, inner: float = 0.0) -> Correction:
    """The correction of module doc from the error map ``em`` (which covers ``radius + extend``);
    ``inner`` > 0: an annular clear aperture (its hole continued like the run-out)."""
    from scipy import ndimage

    xs, ys, h = em.xs, em.ys, em.spacing
    cx, cy = center
    X = xs[None, :] - cx
    Y = ys[:, None] - cy
    R2 = X * X + Y * Y
    inside = R2 <= radius * radius
    if inner > 0:
        inside &= R2 >= inner * inner
    n_in = int(inside.sum())
    if n_in < 16:
        raise CorrectionInputError(f"the {_aperture_words(radius, inner)} holds {n_in} nodes at "
                                   f"spacing {h:g} mm: too few")
    cov = float(np.count_nonzero(em.covered & inside)) / n_in
    if cov < MIN_COVERAGE:
        raise CorrectionInputError(coverage_message(cov, R2, inside, em.covered, radius, inner, center))
    E = np.where(inside, em.E, np.nan)
    holes = inside & ~np.isfinite(E)
    known = inside & np.isfinite(E)
    Xi = np.broadcast_to(X, E.shape)[known]
    Yi = np.broadcast_to(Y, E.shape)[known]
    # piston and tilt removed over the measured nodes first, then the nearest-node continuation
    # (holes inside — ≤ 1 % of the aperture uncovered, plus a scattered map's band between the
    # outermost points and the rim — and everything outside): continued the other way round, the
    # rim's tilted values minus the plane extrapolated made a ramp outside the aperture (a review: a
    # 1 µm bump on 2e-4 rad of tilt wrote dz −0.43…+0.53 µm beyond the rim, and a removal map
    # ≥ 0.36 µm deep everywhere)
    p = plane_fit(Xi, Yi, E[known])
    E = E - (p[0] + p[1] * X + p[2] * Y)
    idx = ndimage.distance_transform_edt(~known, return_distances=False, return_indices=True)
    Ef = E[idx[0], idx[1]]
    sigma_px = gaussian_sigma(cutoff) / h
    F = ndimage.gaussian_filter(Ef, sigma_px, mode="nearest", truncate=4.0) if sigma_px > 0 else Ef
    raw = -gain * F
    q = plane_fit(Xi, Yi, raw[known])
    written = R2 <= (radius + extend) ** 2 + 1e-9 * h * h
    dz_full = raw - (q[0] + q[1] * X + q[2] * Y)
    dz = np.where(written, dz_full, np.nan)
    Ein = np.where(inside, Ef, np.nan)
    pred = Ein + dz_full
    w = plane_fit(Xi, Yi, pred[known])
    pred = np.where(inside, pred - (w[0] + w[1] * X + w[2] * Y), np.nan)
    info = {"coverage": cov, "holes_filled": int(holes.sum()), "nodes_aperture": n_in,
            "nodes_written": int(written.sum()), "sigma_mm": gaussian_sigma(cutoff)}
    return Correction(xs, ys, h, (cx, cy), radius, radius + extend, cutoff, gain, Ein, dz, pred,
                      F, tuple(float(t) for t in p), tuple(float(t) for t in q), info, float(inner))


def rms(a) -> float:
    a = np.asarray(a)[np.isfinite(a)]
    return float(np.sqrt(np.mean((a - a.mean()) ** 2))) if a.size else float("nan")


def pv(a) -> float:
    a = np.asarray(a)[np.isfinite(a)]
    return float(np.ptp(a)) if a.size else float("nan")


def azimuthal_mean(cor: Correction, axis=(0.0, 0.0), field_name: str = "dz", return_share: bool = False):
    """(r, mean of dz on the ring of radius r about ``axis``[, share]), r on multiples of the map
    spacing; bilinear on the full (unmasked) correction field, ~1.5 samples per spacing of arc (≥ 8).

    Clear aperture centred on ``axis``: whole rings, r = 0 … the written region's radius (aperture +
    extension: the tool's run-out). Off the axis (an off-axis zone of the parent surface, turned
    about the parent's axis): each ring's mean is over the arc of it that lies on the part (the clear
    aperture, an annulus's hole excepted), and rings with no arc on the part are left out — no value
    comes from beyond the part (a review: rings about the parent's axis edge-clamped off the grid,
    r = 0 with no data). ``share``: the fraction of each ring the mean is over (1 for whole rings)."""
    from scipy import ndimage

    h = cor.spacing
    full = (-cor.gain * cor.filtered - (cor.plane_dz[0] + cor.plane_dz[1] * (cor.xs[None, :] - cor.center[0])
                                       + cor.plane_dz[2] * (cor.ys[:, None] - cor.center[1])))
    cx, cy = cor.center
    d = float(np.hypot(cx - axis[0], cy - axis[1]))
    on_axis = d <= 1e-9 * h
    if on_axis:
        r = h * np.arange(int(np.floor(cor.outer / h + 1e-9)) + 1, dtype=np.float64)
        half = np.full(r.size, np.pi)
        phi = 0.0
    else:
        R = cor.radius
        k0 = max(0, int(np.ceil((d - R) / h - 1e-9)))
        k1 = int(np.floor((d + R) / h + 1e-9))
        r = h * np.arange(k0, k1 + 1, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            cosa = (r * r + d * d - R * R) / (2.0 * r * d)
        cosa = np.where(r > 0, cosa, -1.0)  # r = 0: the axis itself, on the part (d ≤ R here)
        half = np.arccos(np.clip(cosa, -1.0, 1.0))  # half-angle of the ring's arc on the disk
        phi = float(np.arctan2(cy - axis[1], cx - axis[0]))
    nth = np.maximum(8, np.ceil(2.0 * half * r / h * 1.5)).astype(np.intp)
    ring = np.repeat(np.arange(r.size), nth)
    start = np.concatenate([[0], np.cumsum(nth)[:-1]])
    k = np.arange(ring.size) - start[ring]
    if on_axis:
        th = 2 * np.pi * k / nth[ring]
    else:  # the arc's midpoints: symmetric about the part's centre, never on its rim
        th = phi - half[ring] + (k + 0.5) * (2.0 * half[ring] / nth[ring])
    px = axis[0] + r[ring] * np.cos(th)
    py = axis[1] + r[ring] * np.sin(th)
    ci = (px - cor.xs[0]) / h
    ri = (py - cor.ys[0]) / h
    vals = ndimage.map_coordinates(full, [ri, ci], order=1, mode="constant", cval=np.nan)
    keep = np.isfinite(vals)  # never a value from beyond the grid
    if not on_axis and cor.inner > 0:
        keep &= (px - cx) ** 2 + (py - cy) ** 2 >= cor.inner ** 2
    cnt = np.bincount(ring[keep], minlength=r.size)
    tot = np.bincount(ring[keep], weights=vals[keep], minlength=r.size)
    has = cnt > 0
    if not on_axis:  # a ring that only touches the part's rim (a zero-length arc) holds one rim point
        has &= (r == 0) | (2.0 * half * r >= 1e-3 * h)
    mean = tot[has] / cnt[has]
    share = (half / np.pi * cnt / nth)[has]
    r = r[has]
    return (r, mean, share) if return_share else (r, mean)


def radial_remainder(cor: Correction, r, mean, axis=(0.0, 0.0)):
    """dz minus its azimuthal mean over the clear aperture (the non-symmetric part: slow/fast tool
    servo or polishing)."""
    rr = np.hypot(cor.xs[None, :] - axis[0], cor.ys[:, None] - axis[1])
    sym = np.interp(rr, r, mean)
    return np.where(cor.aperture_mask, cor.dz - sym, np.nan)


def removal_map(cor: Correction, bias_mm: float = 0.0, side: int = 1):
    """Material to remove (mm, ≥ 0) over the written region: side·gain·F about its minimum over the
    clear aperture, plus bias; the run-out ring beyond the aperture is clipped at 0 there (no part to
    polish: its minimum, where a turned-down edge continues, had set the zero and added 51 nm of
    removal everywhere, +21 % of the volume, for nothing — a review).
    ``side``: where the surface is seen from (the probe's side, docs/conventions.md Correction): +1
    from +z (the material lies below the surface: a high spot, residual > 0, is excess), −1 from below
    (the material lies above it: a low spot is excess). dz itself is geometric and the same for both."""
    m = -float(side) * cor.dz  # side 1: gain·F less its plane, what is high is removed
    inside = cor.aperture_mask
    low = np.nanmin(np.where(inside, m, np.nan)) if np.isfinite(m[inside]).any() else np.nanmin(m)
    return np.maximum(m - low, 0.0) + bias_mm
