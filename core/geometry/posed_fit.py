"""Fit of a nominal surface posed in the measuring frame to measured points (paper 002 §3–4).

Model (docs/conventions.md "Frames and signs"): a measured point q and its part-frame coordinates p are related by
    q = R p + t,  R = Rx(α) Ry(β),  t = (dx, dy, dz)   ⇒   p = Rᵀ (q − t).
Two residuals:
  * ``vertical`` (the `misalignment` step):  rᵢ = p_z − f(p_x, p_y), the form error sent to polishing;
  * ``normal``   (the `probe_radius` step):  rᵢ = dᵢ − s·ρ_ball, dᵢ the signed orthogonal distance of the
    probe centre from the surface: centres lie at exactly the ball radius from the part along its normal.
Analytic Jacobian. With u = q − t (rows), ∂p/∂α = u · (dRx Ry), ∂p/∂β = u · (Rx dRy), ∂p/∂t_j = −R[j, :];
then ∂r/∂θ = g · ∂p/∂θ with g = (−f_x, −f_y, 1) for the vertical residual and g = n̂(foot) for the
normal one (the foot point is stationary: envelope theorem). Design parameters (vertex radius, conic,
A_n) enter as ∂r/∂c = −∂f/∂c (vertical) or −n_z ∂f/∂c (normal).

Memory (issue 26): the vertical fit never holds its N × p Jacobian. The model and its Jacobian are
evaluated over blocks of ``CHUNK`` points, each block adding its JᵀJ and Jᵀr to the p × p normal
equations (``normal_equations``, solved by ``levenberg_marquardt_normal``); only the residual is kept
at full length (the current and the trial parameters' residuals: two columns, 16 bytes a point,
besides the part-frame points and the residual the step returns). The normal residual (probe_radius)
evaluates the whole cloud at once, its foot-point solve being warm-started from the last one.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DomainError, StepError
from ..surfaces import EvenAsphere, NominalSurface, SurfaceOfRevolution
from .lsq import levenberg_marquardt, levenberg_marquardt_normal
from .pose import Pose, rot_x, rot_y

POSE_DOF = ("alpha", "beta", "dx", "dy", "dz")
DEG = np.pi / 180.0
# A fit whose column-scaled Jacobian has a condition number above this amplifies the residual into
# its parameters by that much: the report warns and names the pairs correlated beyond 0.999.
ILL_POSED_CONDITION = 1e3
DEGENERATE_CORRELATION = 0.999
#: points per block of the vertical fit's model and Jacobian (2¹⁶: ~15 columns of 0.5 MB, in cache)
CHUNK = 1 << 16
#: a fit of more than 4× this many points starts from the fit of every k-th point (~this many): LM's
#: first iterations walk from the starting pose to the minimum, and on 10⁶ points each costs 0.2 s
PREFIT_POINTS = 50_000


def dof_names_valid(names) -> list[str]:
    bad = [n for n in names if n not in POSE_DOF and n not in ("radius", "conic")
           and not (n.startswith("A") and n[1:].isdigit() and int(n[1:]) >= 2)]
    if bad:
        raise ValueError(f"unknown degree(s) of freedom {bad}; use alpha, beta, dx, dy, dz, radius, "
                         "conic, A4, A6, …")
    if len(set(names)) != len(names):
        raise ValueError("a degree of freedom is listed twice")
    return list(names)


def with_design(surface: EvenAsphere, free, x, pose_names) -> EvenAsphere:
    """``surface`` with the design parameters among ``free`` (radius → c, conic → k, A4… by name) set
    to their values in ``x``; the names in ``pose_names`` are the pose's and left out (clouds and
    profiles share this: core/profiles/fit.py)."""
    upd = {}
    for n, v in zip(free, x):
        if n == "radius":
            upd["c"] = v
        elif n == "conic":
            upd["k"] = v
        elif n not in pose_names:
            upd[n] = v
    return surface.with_parameters(**upd)


def form_weights(part, free) -> np.ndarray | None:
    """The weights of a pose fit with DOF ``free`` whose points lie at ``part`` (N, 3) in the part
    frame: the points' areas (core.metrics.area_weights) when a design parameter (radius, conic, A_n)
    is free — the fit then takes form (power, spherical aberration) out of the residual, and the
    area's best fit is the one ISO 14999-4 and the summary's RMS over the area mean; None for a pose
    alone (rigid motions: the points' fit leaves the area RMS within ~1 % on a star scan, a review
    measured) and on even samplings. The part frame, not the measuring frame: a part tilted 2.3°
    turns its star's circles into ovals there, and weights with a cos 2θ pattern leaked astigmatism
    into the fitted radius and conic."""
    if not any(n not in POSE_DOF for n in dof_names_valid(free)):
        return None
    from ..metrics.area_weights import area_weights

    part = np.asarray(part, dtype=np.float64)
    return area_weights(part[:, 0], part[:, 1])


#: the report's ``fit_weights`` when fit_over_the_area weighted the fit
FIT_WEIGHTS_NOTE = "area: each point weighted by the area it stands for (an uneven sampling)"


def fit_over_the_area(surface, q, free, initial=None, residual="vertical", **kw):
    """(fit, weights): the fit of PosedSurfaceFit(surface, q, free, initial, residual, **kw) and, when
    it takes form out (form_weights), that fit again weighted by the points' areas in the part frame
    of the first, from its pose; weights None otherwise (the first fit stands, bit for bit)."""
    fit = PosedSurfaceFit(surface, q, free, initial, residual, **kw).fit()
    weights = form_weights(fit.part, free)
    if weights is None:
        return fit, None
    start = {**dict(initial or {}), **{nm: fit.values[nm] for nm in fit.names if nm in POSE_DOF}}
    weighted = PosedSurfaceFit(surface, q, free, start, residual, weights=weights, **kw).fit()
    if not np.isfinite(weighted.condition_number) and np.isfinite(fit.condition_number):
        # a fit degenerate to rounding (paper 002's c, k, A4 and A6 over 1300 mm: k, A4, A6 trade)
        # whose weighted normal matrix rounds to singular: the points' fit stands, with its diagnosis
        # of which parameters trade (the surface is the same to 10⁻¹⁰ mm either way)
        return fit, None
    return weighted, weights


@dataclass
class PosedFitResult:
    pose: Pose
    surface: NominalSurface
    names: list[str]
    values: dict
    uncertainty: dict
    correlation: np.ndarray
    condition_number: float
    residuals: np.ndarray
    iterations: int
    converged: bool
    part: np.ndarray  # (N, 3) the points in the part frame at the fitted pose
    warnings: list[str] = field(default_factory=list)
    foot_shift: np.ndarray | None = None  # normal residual on a surface of revolution: ρ_p − ρ_foot

    def foot_point(self):
        """(foot, n̂, d) of `part` on the fitted surface — for a surface of revolution warm-started
        from the fit's last foot radii (one Newton step that moves them by rounding only)."""
        if self.foot_shift is not None:
            return self.surface.foot_point_warm(self.part, self.foot_shift)[:3]
        return self.surface.foot_point(self.part)

    def report(self) -> dict:
        rep = {}
        for n in self.names:
            key = {"alpha": "alpha_deg", "beta": "beta_deg", "radius": "R", "conic": "k"}.get(n, n)
            rep[key] = self.values[n]
        return {**rep,
                "uncertainty": {({"alpha": "alpha_deg", "beta": "beta_deg", "radius": "R",
                                  "conic": "k"}.get(n, n)): self.uncertainty[n] for n in self.names},
                "parameters": list(self.names),
                "correlation": np.round(self.correlation, 6).tolist(),
                "condition_number": self.condition_number, "iterations": self.iterations}


def _refuse_wild_heights(q: np.ndarray) -> None:
    """StepError naming the worst height when a few points lie absurdly far from the others along z
    (beyond 10⁶ of the points' own spread): one z of 1e12 mm among a part's points made the cloud look
    like an upright plane, and the fit said "all points lie on a line" (a review)."""
    z = q[:, 2]
    med = float(np.median(z))
    spread = float(np.median(np.abs(z - med))) * 1.4826 or float(np.ptp(q[:, :2]))
    far = np.abs(z - med) > 1e6 * max(spread, 1e-300)
    if far.any():
        i = int(np.argmax(np.abs(z - med)))
        raise StepError(f"{int(far.sum())} point(s) lie absurdly far from the others in z (z = {z[i]:.6g} mm; "
                        f"the others spread ~{spread:.3g} mm about {med:.6g} mm): a corrupted value in the "
                        "file? Fix the file or remove the point(s) (manual_edit)")


class PosedSurfaceFit:
    """One job: fit pose (and chosen design parameters) of ``surface`` to points ``q`` (measuring frame).

    free:    names of the fitted degrees of freedom (alpha, beta, dx, dy, dz, radius, conic, A<n>)
    initial: starting / fixed values (alpha/beta in degrees, shifts in mm)
    residual: "vertical" or "normal"; offset: the target of the normal distance (s·ρ_ball)
    weights: per-point weights of the least squares (None: all equal) — the points' areas
             (core.metrics.area_weights) where the fit takes form out of the residual (radius, conic,
             A_n free): the best-fit sphere of ISO 14999-4 is the area's, and on a star scan the
             points' fit left spherical aberration 12 % high in the area RMS. Scaled to mean 1, so
             σ² = Σ w r² / (N − p); the returned residuals are unweighted.
    """

    def __init__(self, surface: NominalSurface, q, free, initial=None, residual="vertical",
                 offset: float = 0.0, max_iter: int = 100, check=None, weights=None):
        self.surface0 = surface
        self.q = np.asarray(q, dtype=np.float64)
        self.weights = None if weights is None else np.asarray(weights, dtype=np.float64)
        self.sw = None if weights is None else np.sqrt(self.weights / self.weights.mean())
        self._qT_full = None  # (3, N) contiguous rows, made only for a whole-cloud evaluation (model)
        self.free = dof_names_valid(free)
        self.design_free = [n for n in self.free if n not in POSE_DOF]
        if self.design_free and not isinstance(surface, EvenAsphere):
            raise StepError(f"fitting {self.design_free} needs an even-asphere nominal "
                            f"(this recipe's surface is {surface.kind})")
        self.given = dict(initial or {})  # what the user gave; the rest starts at zero / from data
        self.initial = {n: 0.0 for n in POSE_DOF} | self.given
        self.residual = residual
        self.offset = float(offset)
        self.max_iter = max_iter
        self.check = check
        # warm start of the foot-point solves (normal residual, surface of revolution): the foot shifts
        # ρ_p − ρ of the latest evaluation, and those of the lowest-cost one (LM's current iterate)
        self._shift = None
        self._best = (np.inf, None, None)

    # -- parameter vector <-> pose and surface ------------------------------------------------------
    def _design_value(self, surf: EvenAsphere, name):
        if name == "radius":
            return surf.c
        if name == "conic":
            return surf.k
        return surf.A.get(int(name[1:]), 0.0)

    def _unpack(self, x):
        vals = dict(self.initial)
        vals.update({n: v for n, v in zip(self.free, x) if n in POSE_DOF})
        surf = with_design(self.surface0, self.free, x, POSE_DOF) if self.design_free else self.surface0
        return vals, surf

    # -- the model ----------------------------------------------------------------------------------
    @property
    def _qT(self) -> np.ndarray:
        if self._qT_full is None:
            self._qT_full = np.ascontiguousarray(self.q.T)
        return self._qT_full

    @staticmethod
    def _rotation(vals):
        return rot_x(vals["alpha"] * DEG) @ rot_y(vals["beta"] * DEG)

    def _part_coords(self, vals, qT=None):
        """Part-frame coordinates as three arrays, p = Rᵀ (q − t), and the pieces the Jacobian reuses
        (of the points ``qT``, (3, m) — default all)."""
        R = self._rotation(vals)
        t = np.array([[vals["dx"]], [vals["dy"]], [vals["dz"]]])
        u = np.subtract(self._qT if qT is None else qT, t, order="C")  # (3, m) contiguous rows
        p = R.T @ u  # one BLAS call on (3, m) rows: contiguous x, y, z arrays
        return R, (u[0], u[1], u[2]), (p[0], p[1], p[2])

    def part_points(self, vals) -> np.ndarray:
        """(N, 3) points in the part frame, p = Rᵀ (q − t), computed by blocks (no (3, N) temporaries)."""
        R = self._rotation(vals)
        t = np.array([vals["dx"], vals["dy"], vals["dz"]])
        out = np.empty((len(self.q), 3))
        for s in range(0, len(self.q), CHUNK):
            np.matmul(self.q[s:s + CHUNK] - t, R, out=out[s:s + CHUNK])  # rows: (q − t)ᵀ R = (Rᵀ(q − t))ᵀ
        return out

    def normal_equations(self, x):
        """(r, JᵀJ, Jᵀr) of the vertical residual at x, the model and its Jacobian evaluated over blocks
        of CHUNK points: the only full-length array made is r."""
        vals, surf = self._unpack(x)
        n, k = len(self.q), len(self.free)
        r = np.empty(n)
        A = np.zeros((k, k))
        g = np.zeros(k)
        for s in range(0, n, CHUNK):
            rc, Jc = self._evaluate(x, vals, surf, self.q[s:s + CHUNK].T, True)
            if self.sw is not None:  # weighted least squares: rows × √w
                sw = self.sw[s:s + len(rc)]
                rc, Jc = rc * sw, Jc * sw[:, None]
            r[s:s + len(rc)] = rc
            A += Jc.T @ Jc
            g += Jc.T @ rc
        return r, A, g

    def model(self, x, want_jac: bool):
        """Residuals and Jacobian (N × p) over all points. With w = R g (g rotated to the measuring frame):
            ∂r/∂t = −w,   ∂r/∂α = −(u × w)_x,   ∂r/∂β = −(p × g)_y      (angles per radian)
        from ∂Rᵀ/∂α = Rᵀ Kxᵀ and ∂Rᵀ/∂β = Kyᵀ Rᵀ (K the generators of Rx, Ry: dRx = Rx Kx)."""
        vals, surf = self._unpack(x)
        r, J = self._evaluate(x, vals, surf, None, want_jac)
        if self.sw is not None:  # weighted least squares: rows × √w
            r = r * self.sw
            J = None if J is None else J * self.sw[:, None]
        return r, J

    def _evaluate(self, x, vals, surf, qT, want_jac: bool):
        """model() of the points qT ((3, m); None: all). The normal residual takes all points only."""
        R, (ux, uy, uz), (px, py, pz) = self._part_coords(vals, qT)
        if self.residual == "vertical":
            r2 = px * px + py * py
            G = np.empty((3, len(px)))  # g = (−f_x, −f_y, 1), as rows for the BLAS call below
            if isinstance(surf, EvenAsphere):
                f, gr = surf.sag_and_slope_over_r(r2)
                r = pz - f
                if not want_jac:
                    return r, None
                np.negative(gr, out=gr)
                np.multiply(gr, px, out=G[0])
                np.multiply(gr, py, out=G[1])
            else:
                r = pz - surf.sag(px, py)
                if not want_jac:
                    return r, None
                fx, fy = surf.gradient(px, py)
                np.negative(fx, out=G[0])
                np.negative(fy, out=G[1])
            G[2] = 1.0
            gx, gz = G[0], 1.0
            rho = np.sqrt(r2) if self.design_free else None
            dz_design = 1.0
        else:
            if isinstance(surf, SurfaceOfRevolution):
                foot, n, dist, shift = surf.foot_point_warm(np.column_stack([px, py, pz]), self._shift)
                self._shift = shift
            else:
                foot, n, dist = surf.foot_point(np.column_stack([px, py, pz]))
            r = dist - self.offset
            if isinstance(surf, SurfaceOfRevolution):
                rw = r if self.sw is None or qT is not None else r * self.sw  # LM's cost
                cost = float(rw @ rw)
                if cost <= self._best[0]:  # LM accepts a step whose cost is ≤ the current one
                    self._best = (cost, np.array(x, dtype=np.float64), shift)
            if not want_jac:
                return r, None
            G = np.ascontiguousarray(n.T)
            gx, gz = G[0], G[2]
            rho = np.sqrt(foot[:, 0] ** 2 + foot[:, 1] ** 2) if self.design_free else None
            dz_design = gz
        J = np.empty((len(r), len(self.free)), order="F")  # contiguous columns
        need_w = any(nm in self.free for nm in ("alpha", "dx", "dy", "dz"))
        if need_w:  # w = R g, one BLAS call
            wx, wy, wz = R @ G
        design = None
        if self.design_free:
            names = ["c" if m == "radius" else "k" if m == "conic" else m for m in self.design_free]
            design = dict(zip(self.design_free, surf.parameter_derivatives(rho, names).values()))
        for j, name in enumerate(self.free):
            col = J[:, j]
            if name == "alpha":
                np.multiply(uz, wy, out=col)
                col -= uy * wz
                col *= DEG
            elif name == "beta":
                np.multiply(px, gz, out=col)
                col -= pz * gx
                col *= DEG
            elif name in ("dx", "dy", "dz"):
                np.negative({"dx": wx, "dy": wy, "dz": wz}[name], out=col)
            else:
                np.multiply(design[name], -dz_design, out=col)
        return r, J

    # -- the fit ------------------------------------------------------------------------------------
    def _prefit(self, x0: np.ndarray) -> np.ndarray:
        """Where the whole fit starts: ``x0``, or for more than 4 × PREFIT_POINTS points the minimum
        of the same fit on every k-th point (an even spread of ~PREFIT_POINTS, as rows come: rasters,
        spirals and stars alike). The whole fit then runs its own iterations to its own convergence
        tests from there — the same minimum, reached in 2–3 evaluations of all points instead of 5–7
        (10⁶ raster points: probe_radius's fit 1.0 → ~0.5 s). Any trouble on the subsample (no
        convergence, a point outside the conic's domain) leaves ``x0``; a whole fit that cannot start
        from the subsample's minimum starts from ``x0`` again (fit)."""
        n = len(self.q)
        if n <= 4 * PREFIT_POINTS:
            return x0
        every = n // PREFIT_POINTS
        sub = PosedSurfaceFit(self.surface0, self.q[::every], self.free, self.initial,
                              self.residual, self.offset, self.max_iter, self.check,
                              None if self.weights is None else self.weights[::every])
        try:
            if self.residual == "vertical":
                res = levenberg_marquardt_normal(sub.normal_equations, x0, max_iter=self.max_iter,
                                                 check=self.check)
            else:
                res = levenberg_marquardt(sub.model, x0, max_iter=self.max_iter, check=self.check)
        except DomainError:
            return x0
        return res.x if res.converged and np.all(np.isfinite(res.x)) else x0

    def fit(self) -> PosedFitResult:
        n, k = len(self.q), len(self.free)
        if n <= k:
            raise StepError(f"{n} point{'' if n == 1 else 's'} for {k} parameters: need more points than "
                            "parameters")
        cov3 = _covariance3(self.q)  # 3 × 3, by blocks
        ev = np.linalg.eigvalsh(cov3[:2, :2])  # spreads² of the footprint in x, y
        w3, v3 = np.linalg.eigh(cov3)
        # a profile: narrower in x, y than 1/1000 of its length, or (a tilted profile bows sideways by
        # sag·tilt) all in one plane that stands upright — a plane section, not an areal measurement
        upright_plane = w3[0] <= 1e-9 * w3[2] and abs(v3[2, 0]) < 0.3
        if upright_plane and not (ev[1] <= 0 or ev[0] <= 1e-6 * ev[1]):
            _refuse_wild_heights(self.q)  # an areal footprint "upright" because of a wild height
        if ev[1] <= 0 or ev[0] <= 1e-6 * ev[1] or upright_plane:
            raise StepError("all points lie on a line: a profile cannot determine the tilt about its own "
                            "direction — measure a second line or an areal pattern (or fix those DOF)")
        x0 = []
        start = dict(self.initial)
        if "dz" in self.free and "dz" not in self.given:
            # start the height from the data: the median vertical gap at the initial pose
            try:  # (on ≤ 20,000 evenly spread points: a median needs no more)
                sub = slice(None, None, max(1, n // 20000))
                q = self.q[sub]
                u = q - np.array([start["dx"], start["dy"], 0.0])
                p = u @ (rot_x(start["alpha"] * DEG) @ rot_y(start["beta"] * DEG))
                gap = p[:, 2] - self.surface0.sag(p[:, 0], p[:, 1])
                start["dz"] = float(np.median(gap)) - (self.offset if self.residual == "normal" else 0.0)
                self.initial["dz"] = start["dz"]
            except DomainError:
                pass
        for name in self.free:
            x0.append(start[name] if name in POSE_DOF else self._design_value(self.surface0, name))
        x0 = np.array(x0)
        starts = [self._prefit(x0)]
        if starts[0] is not x0:
            # a point left out of the subsample may lie outside the conic's domain at the subsample's
            # pose (a review: an edge point of a decentred sphere): then the whole fit starts as before
            starts.append(x0)
        for i, x_start in enumerate(starts):
            self._shift, self._best = None, (np.inf, None, None)
            try:
                if self.residual == "vertical":  # JᵀJ, Jᵀr accumulated by blocks: no N × p Jacobian held
                    res = levenberg_marquardt_normal(self.normal_equations, np.array(x_start),
                                                     max_iter=self.max_iter, check=self.check)
                else:
                    res = levenberg_marquardt(self.model, np.array(x_start), max_iter=self.max_iter,
                                              check=self.check)
                break
            except DomainError as e:
                if i == len(starts) - 1:
                    raise StepError(f"at the starting pose: {e}") from None
        vals, surf = self._unpack(res.x)
        cov, cond = res.covariance()
        if not res.converged and cond > ILL_POSED_CONDITION:
            sig = np.sqrt(np.clip(np.diag(cov), 0, None))
            with np.errstate(divide="ignore", invalid="ignore"):
                corr = np.nan_to_num(cov / np.outer(sig, sig))
            pairs = [f"{self.free[i]}/{self.free[j]}" for i in range(k) for j in range(i + 1, k)
                     if abs(corr[i, j]) > DEGENERATE_CORRELATION]
            raise StepError(f"the fit cannot separate {', '.join(pairs) or 'its parameters'} (condition number "
                            f"{cond:.3g}; it wandered {res.iterations} iterations along a valley): on a "
                            "nearly spherical part a tilt is a decenter — fit fewer DOF, e.g. `dof: [dx, dy, "
                            "dz]` with the tilts held at `initial` values")
        if not res.converged:
            raise StepError(f"the fit did not converge ({res.message}, {res.iterations} iterations): check "
                            "the data's units (mm) and frame, the nominal surface, the probe side, or give "
                            "initial values for the pose")
        sig = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = np.nan_to_num(cov / np.outer(sig, sig))
        values = {nm: float(v) for nm, v in zip(self.free, res.x)}
        unc = {nm: float(s) for nm, s in zip(self.free, sig)}
        if "radius" in values:  # fitted as curvature c; reported as the vertex radius R = 1/c
            c = values["radius"]
            values["radius"] = 1.0 / c if c else np.inf
            unc["radius"] = unc["radius"] / (c * c) if c else np.inf
        warnings = []
        if cond > ILL_POSED_CONDITION:
            pairs = [f"{self.free[i]}/{self.free[j]} ({corr[i, j]:+.6f})" for i in range(k)
                     for j in range(i + 1, k) if abs(corr[i, j]) > DEGENERATE_CORRELATION]
            sphere = any(p.split(" ")[0] in ("alpha/dy", "beta/dx", "alpha/dx", "beta/dy") for p in pairs)
            warnings.append(
                f"ill-posed fit (condition number {cond:.3g}): {', '.join(pairs) or 'several parameters'} "
                "trade off" + (" — on a nearly spherical part a tilt looks like a decenter" if sphere else "")
                + ". These values are not separately meaningful: fix one of each pair (leave it out of "
                "`dof`, give it in `initial`) to read the others. The residual is that of the best "
                "pose along the trade-off (exactly so on a sphere); on an asphere or a freeform, form "
                "error that such a pose change reproduces is in the pose, not in the residual")
        pose = Pose(vals["alpha"], vals["beta"], vals["dx"], vals["dy"], vals["dz"])
        _, x_best, shift = self._best
        if x_best is None or not np.array_equal(x_best, res.x):
            shift = self._shift
        residuals = res.residuals if self.sw is None else res.residuals / self.sw
        return PosedFitResult(pose, surf, list(self.free), values, unc, corr, float(cond), residuals,
                              res.iterations, res.converged, self.part_points(vals), warnings, shift)


def _covariance3(q: np.ndarray) -> np.ndarray:
    """np.cov of the (N, 3) points' coordinates (ddof 1) by blocks: the mean, then the centred sums of
    products, without the (3, N) centred copy np.cov makes."""
    n = len(q)
    mean = q.sum(axis=0) / n
    c = np.zeros((3, 3))
    for s in range(0, n, CHUNK):
        d = q[s:s + CHUNK] - mean
        c += d.T @ d
    return c / max(n - 1, 1)
