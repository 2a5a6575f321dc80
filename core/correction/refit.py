"""The corrected nominal for a turning program: nominal + the radial correction, re-fitted in the
recipe's own surface syntax.

Target T(r) = f_prog(r) + dz(r) at the rings of the radial correction inside the clear aperture
(weights ∝ r: the RMS is over the aperture's area). Two forms are fitted by Gauss–Newton on the
conic (c, k) and linear least squares on the polynomial, each with more terms until it meets the
tolerance:

- even asphere: c, k and A4, A6, … up to A40 (powers the recipe syntax takes), the nominal's own
  A_n kept as starting values; columns scaled to unit norm and solved by SVD (rcond 1e-13), since
  the monomials are far from orthogonal;
- Forbes Q-con: c, k and a_0 … a_M on u = r / r_n with r_n the written region's radius (Jacobi
  P_m^(0,4): orthogonal, so many terms stay well conditioned).

The nominal's own type is kept when it meets the tolerance; otherwise the form with the lower RMS.
"""
from __future__ import annotations

import numpy as np

from ..errors import DomainError
from ..surfaces import EvenAsphere, QBfsAsphere, QConAsphere
from ..surfaces.forbes import qcon_series


def _weights(r, h):
    w = np.maximum(r, h / 4.0)
    return w / w.sum()


def _wrms(res, w):
    return float(np.sqrt(np.sum(w * res * res)))


def _solve(J, res, w):
    sw = np.sqrt(w)[:, None]
    A = J * sw
    norm = np.linalg.norm(A, axis=0)
    norm[norm == 0] = 1.0
    step = np.linalg.lstsq(A / norm, res * sw[:, 0], rcond=1e-13)[0] / norm
    return step


def fit_even_asphere(r, T, base, w, aperture, max_power=40, fit_conic=True):
    """(EvenAsphere, weighted RMS mm) of T(r) with powers up to ``max_power``."""
    c, k = float(base.c), float(base.k)
    A = dict(getattr(base, "A", {}) or {})
    powers = sorted(set(A) | set(range(4, max_power + 1, 2)))
    names = (["c", "k"] if fit_conic else []) + [f"A{n}" for n in powers]
    surf = EvenAsphere(c, k, {n: A.get(n, 0.0) for n in powers}, aperture)
    surf.A = {n: A.get(n, 0.0) for n in powers}  # keep zero terms as unknowns
    best = None
    for _ in range(4):
        try:
            res = T - surf.sag_r(r)
            J = np.column_stack([surf.parameter_derivatives(r, [nm])[nm] for nm in names])
        except DomainError:
            break
        d = _solve(J, res, w)
        vals = {}
        if fit_conic:
            vals["c"] = surf.c + d[0]
            vals["k"] = surf.k + d[1]
        off = 2 if fit_conic else 0
        for i, n in enumerate(powers):
            vals[f"A{n}"] = surf.A.get(n, 0.0) + d[off + i]
        new = EvenAsphere(vals.get("c", surf.c), vals.get("k", surf.k),
                          {n: vals[f"A{n}"] for n in powers}, aperture)
        new.A = {n: vals[f"A{n}"] for n in powers}
        try:
            e = _wrms(T - new.sag_r(r), w)
        except DomainError:
            break
        surf = new
        if best is None or e < best[1]:
            best = (surf, e)
        if np.max(np.abs(d)) == 0 or (best and e < 1e-12):
            break
    if best is None:
        return None, float("inf")
    s = best[0]
    s.A = {n: a for n, a in s.A.items() if a != 0.0}
    return s, best[1]


def _qcon_columns(r, rn, M):
    v = (r / rn) ** 2
    cols = []
    for m in range(M):
        a = np.zeros(m + 1)
        a[m] = 1.0
        cols.append(v * v * qcon_series(a, v)[0])
    return np.column_stack(cols)


def fit_qcon(r, T, base, w, aperture, norm_radius, terms):
    """(QConAsphere, weighted RMS mm) with ``terms`` coefficients a_0…a_{terms−1}; c and k re-fitted."""
    c, k = float(base.c), float(base.k)
    a = np.zeros(terms)
    if isinstance(base, QConAsphere) and abs(base.rn - norm_radius) < 1e-12 * norm_radius:
        a[: min(terms, len(base.a))] = base.a[:terms]
    Q = _qcon_columns(r, norm_radius, terms)
    best = None
    for _ in range(4):
        surf = QConAsphere(c, k, a, norm_radius, aperture)
        try:
            res = T - surf.sag_r(r)
            conic = EvenAsphere(c, k)
            d = conic.parameter_derivatives(r, ["c", "k"])
        except DomainError:
            break
        J = np.column_stack([d["c"], d["k"], Q])
        step = _solve(J, res, w)
        c, k, a = c + step[0], k + step[1], a + step[2:]
        try:
            surf = QConAsphere(c, k, a, norm_radius, aperture)
            e = _wrms(T - surf.sag_r(r), w)
        except DomainError:
            break
        if best is None or e < best[1]:
            best = (surf, e)
    return (None, float("inf")) if best is None else best


def fit_qbfs(r, T, base, w, aperture, norm_radius, terms):
    """(QBfsAsphere, weighted RMS mm): c fixed to the nominal's best-fit sphere, a_m linear."""
    from ..surfaces.forbes import qbfs_polynomials

    c = float(base.c)
    try:
        sphere = EvenAsphere(c, 0.0)
        res = T - sphere.sag_r(r)
    except DomainError:
        return None, float("inf")
    v = (r / norm_radius) ** 2
    phi = np.sqrt(1.0 - c * c * r * r)
    cols = np.column_stack([v * (1 - v) * Q / phi for Q, _, _ in qbfs_polynomials(terms - 1, v)])
    a = _solve(cols, res, w)
    surf = QBfsAsphere(c, list(a), norm_radius, aperture)
    return surf, _wrms(T - surf.sag_r(r), w)


def spec_of(surface) -> dict:
    """The recipe's `surface:` mapping of a fitted surface (floats written exactly)."""
    if isinstance(surface, QConAsphere):
        d = {"type": "qcon", "c": surface.c, "k": surface.k, "norm_radius": surface.rn,
             "a": [float(x) for x in surface.a]}
    elif isinstance(surface, QBfsAsphere):
        d = {"type": "qbfs", "c": surface.c, "norm_radius": surface.rn, "a": [float(x) for x in surface.a]}
    else:
        d = {"type": "even_asphere", "c": surface.c, "k": surface.k,
             "A": {int(n): float(a) for n, a in sorted(surface.A.items())}}
    if surface.aperture is not None:
        d["aperture"] = surface.aperture
    return d


def refit_surface(programmed, r, dz, radius: float, spacing: float, norm_radius: float,
                  tol_mm: float = 1e-6, extension_weight: float = 0.1) -> dict:
    """Fit programmed + dz(r) over every ring (r ≤ norm_radius), the rings past the clear aperture
    (the run-out) weighted by ``extension_weight`` so the polynomial stays on the correction there
    without costing the aperture its accuracy; the RMS judged is over r ≤ radius. Returns
    {"surface", "type", "rms_mm", "tried": {...}, "why"}; "surface" is None when no form could be
    fitted (a domain problem)."""
    sel = r <= norm_radius + 1e-9 * spacing
    rr, target = r[sel], programmed.sag_r(r[sel]) + dz[sel]
    w = _weights(rr, spacing) * np.where(rr <= radius + 1e-9 * spacing, 1.0, extension_weight)
    w = w / w.sum()
    ins = rr <= radius + 1e-9 * spacing
    wi = _weights(rr[ins], spacing)
    aperture = programmed.aperture
    tried = {}
    cands = {}
    own = getattr(programmed, "kind", "")
    # even asphere: add powers until within a quarter of the tolerance
    if own != "qbfs":
        for top in range(8, 41, 4):
            s, e = fit_even_asphere(rr, target, programmed if own == "even_asphere" else
                                    EvenAsphere(programmed.c, programmed.k), w, aperture, top)
            if s is not None and ("even_asphere" not in cands or e < cands["even_asphere"][1]):
                cands["even_asphere"] = (s, e)
            if e <= tol_mm / 4:
                break
    if own == "qbfs":
        for terms in (6, 10, 14, 20, 26, 32, 40):
            s, e = fit_qbfs(rr, target, programmed, w, aperture, norm_radius, terms)
            if s is not None and ("qbfs" not in cands or e < cands["qbfs"][1]):
                cands["qbfs"] = (s, e)
            if e <= tol_mm / 4:
                break
    if "even_asphere" not in cands or cands["even_asphere"][1] > tol_mm / 4 or own == "qcon":
        for terms in (6, 10, 14, 20, 26, 32, 40):
            s, e = fit_qcon(rr, target, programmed, w, aperture, norm_radius, terms)
            if s is not None and ("qcon" not in cands or e < cands["qcon"][1]):
                cands["qcon"] = (s, e)
            if e <= tol_mm / 4:
                break
    for name, (srf, _) in list(cands.items()):
        e = _wrms(target[ins] - srf.sag_r(rr[ins]), wi)
        cands[name] = (srf, e)
        tried[name] = e
    if not cands:
        return {"surface": None, "type": None, "rms_mm": float("inf"), "tried": tried,
                "why": "no form could be fitted (the conic's domain)"}
    if own in cands and cands[own][1] <= tol_mm:
        kind, why = own, f"the nominal's own type ({own}) fits within the tolerance"
    else:
        kind = min(cands, key=lambda n: cands[n][1])
        why = (f"{kind} fits best ({cands[kind][1] * 1e6:.3g} nm RMS" +
               "".join(f"; {n} {e * 1e6:.3g} nm" for n, e in cands.items() if n != kind) + ")")
    s, e = cands[kind]
    return {"surface": s, "type": kind, "rms_mm": e, "tried": tried, "why": why}
