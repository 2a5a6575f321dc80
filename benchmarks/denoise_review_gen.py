"""Independent test generator for knn_denoise method: robust (issue 16 part 3), out of sample.

Does NOT import tests/denoise_cases.py. Units: mm (heights in mm, 1e-3 = 1 µm).

Ground truth:
 - small spikes (±6–10 σ_n, σ_n = the white noise σ; for the 'turned' family σ_eff = sqrt(σ_n² + ring rms²)),
   big spikes (±1–20 µm), rim outliers (outer max(2 % R, 1 mm): −0.5…−5 µm or +0.5…+3 µm): the point itself.
 - pits (round, Gaussian depth profile exp(-r²/2s²)), straight and curved scratches (width 0.2–0.6 mm,
   parabolic cross-section depth·(1-(2t/w)²)): only the points whose *added* depth exceeds 5 σ_n
   count as outliers; points with 0 < added depth ≤ 5 σ_n are recorded as 'edge' (counted as
   inliers in the strict F1, ignored in the lenient F1).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

BASE = {"small": 40, "pit": 4, "scratch": 3, "curved": 3, "rim": 20, "big": 30}
A200 = math.pi * 100.0 ** 2


# ---------------------------------------------------------------- sampling
def sample(kind, R, density, rng):
    if kind == "scattered":
        m = int(density * 4 * R * R * 1.0)
        x, y = rng.uniform(-R, R, m), rng.uniform(-R, R, m)
    elif kind == "raster":
        h = 1.0 / math.sqrt(density)
        g = np.arange(-R - h, R + h, h)
        gx, gy = np.meshgrid(g, g)
        th = rng.uniform(0, np.pi / 2)
        ox, oy = rng.uniform(0, h, 2)
        x0, y0 = gx.ravel() + ox, gy.ravel() + oy
        x = x0 * math.cos(th) - y0 * math.sin(th)
        y = x0 * math.sin(th) + y0 * math.cos(th)
    elif kind == "spiral":
        pitch = rng.uniform(0.5, 1.6) / math.sqrt(density) * 1.6  # track pitch (mm), anisotropic
        s = 1.0 / (density * pitch)                                 # along-track spacing
        # Archimedean spiral r = pitch*θ/2π, equal arc steps: θ(L) ≈ sqrt(4π L / pitch)
        Ltot = math.pi * R * R / pitch
        L = np.arange(s, Ltot, s)
        theta = np.sqrt(4 * math.pi * L / pitch)
        r = pitch * theta / (2 * math.pi)
        ph = rng.uniform(0, 2 * np.pi)
        x, y = r * np.cos(theta + ph), r * np.sin(theta + ph)
        x = x + rng.normal(0, 0.01 * s, len(x))
        y = y + rng.normal(0, 0.01 * s, len(y))
    else:
        raise ValueError(kind)
    keep = np.hypot(x, y) <= R
    return x[keep], y[keep]


# ---------------------------------------------------------------- surfaces
def zernike_radial(n, m, r):
    out = np.zeros_like(r)
    for k in range((n - m) // 2 + 1):
        c = (-1) ** k * math.factorial(n - k) / (
            math.factorial(k) * math.factorial((n + m) // 2 - k) * math.factorial((n - m) // 2 - k))
        out += c * r ** (n - 2 * k)
    return out


def zernike_sum(x, y, R, rms, rng, nmax=6):
    r, t = np.hypot(x, y) / R, np.arctan2(y, x)
    w = np.zeros_like(x)
    for n in range(2, nmax + 1):
        for m in range(n % 2, n + 1, 2):
            c = rng.normal() / (1 + 0.3 * n)
            rad = zernike_radial(n, m, r)
            w += c * rad * (np.cos(m * t) if m == 0 else (np.cos(m * t) if rng.random() < .5 else np.sin(m * t)))
    w -= w.mean()
    return w / math.sqrt(np.mean(w * w)) * rms


def surface(p, x, y, rng):
    """Smooth part (no noise) of the residual."""
    d = zernike_sum(x, y, p["R"], p["res_um"] * 1e-3, rng)
    th = rng.uniform(0, np.pi)
    d += p["ripple_um"] * 1e-3 * np.sin(2 * np.pi * (x * np.cos(th) + y * np.sin(th)) / p["ripple_lam"]
                                        + rng.uniform(0, 6))
    if p.get("ring_um", 0) > 0:
        d += p["ring_um"] * 1e-3 * math.sqrt(2) * np.sin(2 * np.pi * np.hypot(x, y) / p["ring_period"]
                                                        + rng.uniform(0, 6))
    return d


# ---------------------------------------------------------------- outliers
def inject(p, x, y, d, rng, counts=None, target=(3, 31)):
    """Adds outliers to d in place; returns truth {class: set}, edge set (shallow dig points).
    target: the range [lo, hi) of the number of points deeper than 5 σ_n wanted per dig."""
    R, sn = p["R"], p["noise_um"] * 1e-3
    s_eff = math.sqrt(sn ** 2 + (p.get("ring_um", 0) * 1e-3) ** 2)
    dens = p["density"]
    scale = float(np.clip(math.pi * R * R / A200, 0.25, 2.0))
    counts = {c: 0 for c in BASE} | counts if counts else {c: max(1, int(round(v * scale))) for c, v in BASE.items()}
    tree = cKDTree(np.column_stack([x, y]))
    r = np.hypot(x, y)
    taken = np.zeros(len(x), bool)   # outliers and their 3 mm exclusion zones
    truth, edge = {}, set()

    def free(idx, rad=3.0):
        nb = tree.query_ball_point(np.column_stack([x[idx], y[idx]]), rad)
        allnb = np.unique(np.concatenate([np.asarray(v, dtype=np.int64) for v in nb])) if len(nb) else []
        return not taken[allnb].any(), allnb

    def isolated(pool, k):
        out = []
        for q in rng.permutation(pool):
            if len(out) == k:
                break
            ok, nb = free(np.array([q]))
            if ok:
                out.append(q)
                taken[nb] = True
        return np.asarray(out, dtype=np.int64)

    inner = np.flatnonzero(r < R - 1.0)
    p_small = isolated(inner, counts["small"])
    d[p_small] += rng.choice([-1, 1], len(p_small)) * rng.uniform(6, 10, len(p_small)) * s_eff
    truth["small"] = set(p_small.tolist())
    p_big = isolated(inner, counts["big"])
    d[p_big] += rng.choice([-1, 1], len(p_big)) * rng.uniform(1, 20, len(p_big)) * 1e-3
    truth["big"] = set(p_big.tolist())
    band = max(0.02 * R, 1.0)
    p_rim = isolated(np.flatnonzero(r > R - band), counts["rim"])
    low = rng.random(len(p_rim)) < 0.7
    d[p_rim] += np.where(low, -rng.uniform(0.5, 5.0, len(p_rim)), rng.uniform(0.5, 3.0, len(p_rim))) * 1e-3
    truth["rim"] = set(p_rim.tolist())

    dmin = max(0.2e-3, 8 * sn)
    interior = np.flatnonzero(r < R - 4.0)
    for kind in ("pit", "scratch", "curved"):
        found = []
        for _ in range(counts[kind]):
            for _try in range(200):
                c0 = rng.choice(interior)
                cx, cy = x[c0], y[c0]
                depth = rng.uniform(dmin, 2e-3)
                want = rng.integers(*target)        # points deeper than 5σ wanted
                if kind == "pit":
                    lnr = math.log(depth / (5 * sn)) if sn > 0 else 5.0
                    # N5 = dens·π·2 s² ln(D/5σ) -> s
                    s = math.sqrt(want / (dens * math.pi * 2 * lnr))
                    rad = 3.5 * s
                    idx = np.asarray(tree.query_ball_point([cx, cy], rad), dtype=np.int64)
                    add = depth * np.exp(-((x[idx] - cx) ** 2 + (y[idx] - cy) ** 2) / (2 * s * s))
                    _geom = ("pit", round(s, 3))
                else:
                    w = rng.uniform(0.2, 0.6)
                    frac_deep = math.sqrt(max(0.0, 1 - 5 * sn / depth))
                    L = float(np.clip(want / (dens * w * frac_deep), 2.0, 20.0))
                    ang = rng.uniform(0, 2 * np.pi)
                    if kind == "scratch":
                        tt = np.linspace(0, L, max(2, int(L / 0.05)))
                        px, py = cx + tt * np.cos(ang), cy + tt * np.sin(ang)
                    else:
                        rc = rng.uniform(4.0, 25.0)            # radius of curvature
                        phi = np.linspace(0, L / rc, max(2, int(L / 0.05)))
                        ox, oy = cx - rc * np.cos(ang), cy - rc * np.sin(ang)
                        px, py = ox + rc * np.cos(ang + phi), oy + rc * np.sin(ang + phi)
                    if np.any(np.hypot(px, py) > R - 4.0):
                        continue
                    ptree = cKDTree(np.column_stack([px, py]))
                    cand = np.unique(np.concatenate([np.asarray(v, dtype=np.int64) for v in
                                                     tree.query_ball_point(np.column_stack([px, py]), w / 2)]))
                    if len(cand) == 0:
                        continue
                    dist, _ = ptree.query(np.column_stack([x[cand], y[cand]]))
                    idx = cand
                    add = depth * np.clip(1 - (2 * dist / w) ** 2, 0, None)
                    _geom = (kind, round(w, 2), round(L, 1))
                deep = idx[add > 5 * sn]
                if len(deep) < 3:
                    continue
                ok, nb = free(idx)
                if not ok:
                    continue
                taken[nb] = True
                d[idx] -= add
                found.extend(deep.tolist())
                edge |= set(idx[(add > 0) & (add <= 5 * sn)].tolist())
                break
        truth[kind] = set(found)
    return truth, edge
