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


def _gauss_newton(make, values: dict, free: list, columns, r, T, w, iters=5):
    """Least squares of T(r) ≈ make(values).sag_r(r) + p over the parameters ``free`` and a piston p
    (the vertex's z offset: set-up, which no sag with z(0) = 0 can carry), Jacobian
    ``columns(surface, free)``; returns (surface, weighted RMS) of the best iterate, or (None, inf);
    the surface's ``piston`` attribute is p."""
    best = (None, float("inf"))
    vals = {**values, "_p": float(values.get("_p", 0.0))}
    for _ in range(iters + 1):
        try:
            surf = make(vals)
            res = T - surf.sag_r(r) - vals["_p"]
            e = _wrms(res, w)
            if e < best[1]:
                surf.piston = vals["_p"]
                best = (surf, e)
            J = np.column_stack([columns(surf, free), np.ones_like(r)])
        except DomainError:
            break
        d = _solve(J, res, w)
        vals = {**vals, **{n: vals[n] + d[i] for i, n in enumerate([*free, "_p"])}}
    return best


def fit_even_asphere(r, T, base, w, aperture, max_power=40):
    """(EvenAsphere, weighted RMS mm) of T(r): c and A4 … A<max_power> first (k kept: it and A4 are
    nearly the same function), then k freed too when that lowers the RMS."""
    A0 = dict(getattr(base, "A", {}) or {})
    powers = sorted(set(A0) | set(range(4, max_power + 1, 2)))
    values = {"c": float(base.c), "k": float(base.k), **{f"A{n}": A0.get(n, 0.0) for n in powers}}

    def make(v):
        s = EvenAsphere(v["c"], v["k"], {}, aperture)
        s.A = {n: v[f"A{n}"] for n in powers}  # zero terms stay unknowns
        return s

    def columns(s, free):
        d = s.parameter_derivatives(r, free)
        return np.column_stack([d[n] for n in free])

    free = ["c"] + [f"A{n}" for n in powers]
    s1, e1 = _gauss_newton(make, values, free, columns, r, T, w)
    if s1 is not None:
        start = {"c": s1.c, "k": s1.k, "_p": s1.piston, **{f"A{n}": s1.A[n] for n in powers}}
        s2, e2 = _gauss_newton(make, start, ["k"] + free, columns, r, T, w)
        if s2 is not None and e2 < 0.9 * e1:
            s1, e1 = s2, e2
    if s1 is None:
        return None, float("inf")
    s1.A = {n: a for n, a in s1.A.items() if a != 0.0}
    return s1, e1


def _qcon_columns(r, rn, M):
    v = (r / rn) ** 2
    cols = []
    for m in range(M):
        a = np.zeros(m + 1)
        a[m] = 1.0
        cols.append(v * v * qcon_series(a, v)[0])
    return np.column_stack(cols)


def fit_qcon(r, T, base, w, aperture, norm_radius, terms):
    """(QConAsphere, weighted RMS mm) with ``terms`` coefficients a_0…a_{terms−1} on u = r/norm_radius:
    c and the a_m (k kept; then freed when that lowers the RMS)."""
    a0 = np.zeros(terms)
    if isinstance(base, QConAsphere) and abs(base.rn - norm_radius) < 1e-12 * norm_radius:
        a0[: min(terms, len(base.a))] = base.a[:terms]
    Q = _qcon_columns(r, norm_radius, terms)
    names = [f"a{m}" for m in range(terms)]
    values = {"c": float(base.c), "k": float(base.k), **{n: a0[i] for i, n in enumerate(names)}}

    def make(v):
        return QConAsphere(v["c"], v["k"], [v[n] for n in names], norm_radius, aperture)

    def columns(s, free):
        d = EvenAsphere(s.c, s.k).parameter_derivatives(r, [n for n in free if n in ("c", "k")])
        return np.column_stack([d[n] if n in d else Q[:, int(n[1:])] for n in free])

    free = ["c"] + names
    s1, e1 = _gauss_newton(make, values, free, columns, r, T, w)
    if s1 is not None:
        start = {"c": s1.c, "k": s1.k, "_p": s1.piston, **{n: s1.a[i] for i, n in enumerate(names)}}
        s2, e2 = _gauss_newton(make, start, ["k"] + free, columns, r, T, w)
        if s2 is not None and e2 < 0.9 * e1:
            s1, e1 = s2, e2
    return (None, float("inf")) if s1 is None else (s1, e1)


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
    cols = np.column_stack([v * (1 - v) * Q / phi for Q, _, _ in qbfs_polynomials(terms - 1, v)]
                           + [np.ones_like(r)])
    a = _solve(cols, res, w)
    surf = QBfsAsphere(c, list(a[:-1]), norm_radius, aperture)
    surf.piston = float(a[-1])
    return surf, _wrms(T - surf.sag_r(r) - surf.piston, w)


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
                  tol_mm: float = 1e-6, extension_weight: float = 0.1, share=None,
                  inner: float = 0.0) -> dict:
    """Fit programmed + dz(r) over every ring (r ≤ norm_radius), the rings past the clear aperture
    (the run-out) weighted by ``extension_weight`` so the polynomial stays on the correction there
    without costing the aperture its accuracy; the RMS judged is over r ≤ radius. ``share``: the
    fraction of each ring on the part (an off-axis part's arcs; None: whole rings), so the weights
    stay ∝ the area each ring stands for; ``inner``: an annular aperture's inner radius (its hole's
    rings weighted as the run-out). Returns {"surface", "type", "rms_mm", "tried": {...},
    "why"}; "surface" is None when no form could be fitted (a domain problem)."""
    sel = r <= norm_radius + 1e-9 * spacing  # piston: see _gauss_newton
    rr, target = r[sel], programmed.sag_r(r[sel]) + dz[sel]
    sh = np.ones(rr.size) if share is None else np.asarray(share, dtype=np.float64)[sel]
    ins = (rr <= radius + 1e-9 * spacing) & (rr >= inner - 1e-9 * spacing)
    w = _weights(rr, spacing) * sh * np.where(ins, 1.0, extension_weight)
    w = w / w.sum()
    wi = _weights(rr[ins], spacing)
    if share is not None:
        wi = wi * sh[ins] / np.sum(wi * sh[ins])
    aperture = programmed.aperture
    tried = {}
    cands = {}
    own = getattr(programmed, "kind", "")
    # even asphere: add powers until within a quarter of the tolerance, up to A20 — beyond it the
    # monomials cancel each other (A40·r⁴⁰ of a 650 mm radius is 1e-110 × 1e112), which a CAM
    # printing coefficients to a fixed number of digits cannot take; Forbes Q-con (orthogonal,
    # coefficients of the size of the sag they add) takes over there
    if own != "qbfs":
        for top in range(8, 21, 4):
            s, e = fit_even_asphere(rr, target, programmed if own == "even_asphere" else
                                    EvenAsphere(programmed.c, getattr(programmed, "k", 0.0)), w,
                                    aperture, top)
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
        e = _wrms(target[ins] - srf.sag_r(rr[ins]) - srf.piston, wi)
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
               "".join(f"; {n} {e * 1e6:.3g} nm" for n, (_, e) in cands.items() if n != kind) + ")")
    s, e = cands[kind]
    return {"surface": s, "type": kind, "rms_mm": e, "tried": tried, "why": why}
